//! Any bytes as a Modbus TCP stream: frames taken from the front until invalid or incomplete.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::tcp_stream(data));
