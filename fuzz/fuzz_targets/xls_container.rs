//! Any bytes as an XLS file's compound-file container, read the way the workbook reader reads
//! it before `mbtap profiles import` lets the reader open it.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_device::fuzzing::xls_container(data));
