//! Any bytes as an OpenDocument spreadsheet's `content.xml`, its expanded size counted before
//! `mbtap profiles import` opens the workbook.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::ods_size(data));
