//! Integration tests, one binary by theme (each test binary links the whole crate,
//! so a few themed binaries instead of one per file): the analyzer offline: captures, the framer's accuracy, decoding, profiles and their import, the health report, the fuzz corpus.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

mod adapter_truth;
mod builtin_profiles;
mod capture_input;
mod captures;
mod cli_decode;
mod corrupt_input;
mod crc_shift;
mod framer_accuracy;
mod fuzz_corpus;
mod health;
mod learn_inverters;
mod messages;
mod mk4_examples;
mod numeric_options;
mod observer_latency;
mod profile_import;
mod profiles;
mod real_lines;
mod roundtrip;
mod tui_views;
mod two_port_replay;
