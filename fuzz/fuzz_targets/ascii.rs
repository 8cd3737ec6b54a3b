//! Any bytes as one ASCII frame: characters, LRC, PDU.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::ascii(data));
