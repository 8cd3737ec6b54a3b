//! Any bytes as `mbtap decode`'s standard input: the streaming line reader and the decoder.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::decode_lines(data));
