//! Any bytes as an OpenDocument spreadsheet's `content.xml`, its first sheet's rows streamed as
//! `mbtap profiles import` reads them.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::ods_rows(data));
