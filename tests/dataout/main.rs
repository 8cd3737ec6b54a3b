//! Integration tests, one binary by theme (each test binary links the whole crate,
//! so a few themed binaries instead of one per file): data out: MQTT and Sparkplug B against a real Mosquitto.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

#[path = "../common/mod.rs"]
mod common;

mod mqtt;
mod sparkplug;
