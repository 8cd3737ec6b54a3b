//! Any text through `mbtap decode`: hex input reading, mode detection, pairing, both renderers.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::decode_text(data));
