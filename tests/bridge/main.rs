//! Integration tests, one binary by theme (each test binary links the whole crate,
//! so a few themed binaries instead of one per file): the bridge: serial lines, configuration, TLS, agent polling, RS-485 hardware emulation, serial servers.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

#[path = "../common/mod.rs"]
mod common;

mod agent;
mod config;
mod hardware;
mod lifetime;
mod listen_serial;
mod one_path;
mod operate;
mod serial;
mod serial_server;
mod tls;
