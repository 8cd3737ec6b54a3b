//! Any bytes as what a networked line delivers: a Modbus TCP device's stream, or a Telnet/RFC 2217 server's.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_gateway::fuzzing::transports(data));
