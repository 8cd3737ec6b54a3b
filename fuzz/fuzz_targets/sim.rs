//! Any request to the simulated built-in devices: answered well-formed or not at all.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_sim::fuzzing::sim(data));
