//! Any bytes heard through the UART model at any settings: ends, in order, exact when matched.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_sim::fuzzing::uart(data));
