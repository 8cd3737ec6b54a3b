//! Any text as a device profile: loaded (errors, never panics) and used to annotate values.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::profile(data));
