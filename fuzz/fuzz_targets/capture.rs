//! Any bytes as a pcap/pcapng capture, replayed through the whole analyzer.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_analysis::fuzzing::capture(data));
