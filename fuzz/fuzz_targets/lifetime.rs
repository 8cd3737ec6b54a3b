//! Any bytes as one asker's requests and answers in time, through the gateway core's lifetime rule.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_gateway::fuzzing::lifetime(data));
