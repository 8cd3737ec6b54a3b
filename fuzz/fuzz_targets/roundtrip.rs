//! Whatever parses re-encodes to exactly the bytes it came from (asserted).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::roundtrip(data));
