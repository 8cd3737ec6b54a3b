//! Arbitrary chunk sequences through the RTU and ASCII framers; no byte lost or duplicated.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::framer(data));
