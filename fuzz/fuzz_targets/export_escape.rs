//! Any strings as a profile's device, name, register names and units, exported to Home
//! Assistant, ESPHome and Telegraf: each export parses back and every string comes back as written.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    mbtap_device::fuzzing::export_escape(data);
});
