//! Any bytes as what a serial line delivers to the gateway core's transaction machine.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_gateway::fuzzing::transaction(data));
