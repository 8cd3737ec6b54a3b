//! Arbitrary chunks through the analyzer into the bus health report and its renderings, and
//! through the stored-bytes scan.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::health(data));
