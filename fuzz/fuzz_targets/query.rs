//! Any text as the items of `mbtap read`/`write`: parsed, resolved, planned and encoded.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::query(data));
