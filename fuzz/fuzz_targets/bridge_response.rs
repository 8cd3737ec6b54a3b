//! Any bytes read by the bridge's serial master: judged without panicking, an answer never
//! longer than what was read.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::bridge_response(data));
