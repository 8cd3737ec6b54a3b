//! Any bytes as a store-and-forward buffer file and as a record's body.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_publish::fuzzing::spool(data));
