//! Any bytes as a file `mbtap profiles import` is given — CSV, XLSX, XLS, ODS or Home Assistant
//! YAML, by the first byte — imported whole, as the command runs it
//! (`mbtap::cmd::profiles::fuzzing::import_file`). No crash, and no input may make it produce
//! past its budgets: `.ci/run` runs this under `-rss_limit_mb=256`, so memory an input makes the
//! import hold (not what the file claims) is what fails it.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mbtap::cmd::profiles::fuzzing::import_file(data));
