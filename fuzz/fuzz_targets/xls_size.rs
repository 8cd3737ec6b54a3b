//! Any bytes as an XLS workbook's `Workbook` stream, its laid-out size counted before
//! `mbtap profiles import` opens the workbook.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::xls_size(data));
