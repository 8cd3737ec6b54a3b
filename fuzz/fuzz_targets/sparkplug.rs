//! Any bytes as a Sparkplug command from the broker, a held update, and a published value.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap_publish::fuzzing::sparkplug(data));
