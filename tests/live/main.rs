//! Integration tests, one binary by theme (each test binary links the whole crate,
//! so a few themed binaries instead of one per file): live lines and what shows them: pseudo-terminals, tap, spy, simulate --poll, the demo, the terminal UI in tmux, the report in a browser, Wireshark's tshark.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

#[path = "../common/mod.rs"]
mod common;

mod demo;
mod interop_tshark;
mod live_pty;
mod report_browser;
mod simulate_poll;
mod spy;
mod tap_pty;
mod tui_tmux;
