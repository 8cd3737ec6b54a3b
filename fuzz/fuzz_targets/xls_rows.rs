//! Any bytes as an XLS workbook stream, its globals and sheets read row by row as
//! `mbtap profiles import` reads them.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::xls_rows(data));
