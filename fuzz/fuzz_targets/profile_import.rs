//! Any bytes as a register sheet and as Home Assistant YAML for `mbtap profiles import`: read,
//! imported, exported; every imported profile loads.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::profile_import(data));
