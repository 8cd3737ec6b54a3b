//! Any bytes as one RTU frame: split, check, decode the PDU both ways, render.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::rtu(data));
