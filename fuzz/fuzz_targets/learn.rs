//! Any bytes as answered transactions for `mbtap learn`: guessed and drafted, the draft loading.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::learn(data));
