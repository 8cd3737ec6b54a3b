//! Any bytes as a request PDU: parse, findings, fields, expected length.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::pdu_request(data));
