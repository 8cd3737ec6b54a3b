//! Any bytes as a SunSpec device's registers: the chain walked, every model decoded.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::sunspec(data));
