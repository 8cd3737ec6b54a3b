//! mbtap — a Modbus RTU/ASCII bus analyzer.
//!
//! Module map (dependencies point down, never up):
//!
//! Pure core (no tokio, no terminal, no clock — time is an input):
//! - [`proto`] — frames and PDUs of every function code: parse, encode, findings.
//! - [`chunk`] — bytes as a read delivered them, with their [`chunk::Timestamp`].
//! - [`framer`] — chunks into frames and noise (RTU by structure + CRC + timing; ASCII).
//! - [`pairing`] — requests with their responses on a half-duplex bus.
//! - [`analyzer`] — framers + pairing: one path for live capture, replay and tests.
//! - [`profile`] — device register maps: format, loader, annotation.
//! - [`traffic`] — synthetic traffic with ground truth and adapter observation models.
//!
//! Around it:
//! - [`capture`] — pcap/pcapng reading and writing, Wireshark export.
//! - [`report`] — text and JSON-lines rendering.
//! - [`health`] — the bus health report (findings with evidence; text, JSON, HTML) and [`scan`]
//!   line-settings detection.
//! - [`source`] — live serial ports and the clock (the edge).
//! - [`cli`], [`commands`] and the `*_cmd` modules — the commands; `hexinput`, `line_args` —
//!   what users type.
//! - [`fuzzing`] — the bodies of the fuzz targets, also run over the seeds by `cargo test`.

pub mod bridge;
pub mod bridge_cmd;
pub mod bridge_config;
pub mod cli;
pub mod commands;
pub mod config;
pub mod demo_cmd;
pub mod generate_cmd;
pub mod play_cmd;
pub mod replay_cmd;
pub mod scan_cmd;
pub mod simulate_cmd;
pub mod sniff_cmd;
pub mod source;
pub mod tap_cmd;
pub mod tui;
