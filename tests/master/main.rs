//! Integration tests, one binary by theme (each test binary links the whole crate,
//! so a few themed binaries instead of one per file): mbtap as a master: read, write, watch, probe, SunSpec, against simulate and third-party peers.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

#[path = "../common/mod.rs"]
mod common;

mod ascii_master;
mod emulate;
mod interop_emulate;
mod interop_master;
mod interop_mbpoll;
mod interop_pymodbus;
mod late_answer;
mod learn_confirm;
mod probe;
mod read_write;
mod sunspec;
