//! mbtap's analysis, pure: everything between the bytes a source delivered and what a sink shows.
//!
//! No tokio, terminal, command line, serial crate or clock here — time is an input (each
//! [`chunk::Chunk`] carries its own [`chunk::Timestamp`]), so live capture, replay, the fuzzers and
//! the tests run one code path. CI checks the boundary with `cargo tree -p mbtap-core`.
//!
//! Module map (dependencies point down, never up):
//! - [`proto`] — the `mbtap-proto` crate: frames and PDUs of every function code.
//! - [`chunk`] — bytes as a read delivered them, with their timestamp and port.
//! - [`framer`] — chunks into frames and noise (RTU by structure + CRC + timing; ASCII).
//! - [`pairing`] — requests with their responses on a half-duplex bus.
//! - [`analyzer`] — framers + pairing: one path for live capture, replay and tests.
//! - [`profile`] — device register maps: format, loader with positioned errors, annotation, the
//!   built-in MK4, MKZP-0.4 and Display profiles.
//! - [`report`] — events rendered as text and JSON lines (pure formatting: strings out).
//! - [`health`] — the bus health report: findings with evidence; text, JSON and HTML.
//! - [`scan`] — which line settings give valid frames.
//! - [`capture`] — pcap/pcapng reading and writing, Wireshark export, over `io::Read`/`io::Write`.
//!   Here rather than at the edge because reading a capture is parsing (fuzzed from `fuzz/`
//!   without the edge) and its timestamps are data, not a clock.
//! - [`replay`] — a capture through the analyzer into any sink.
//! - [`query`] — what `read`/`write`/`watch` ask of a device: names resolved, requests split,
//!   writes checked and encoded, answers named and scaled.
//! - [`decode`] — frames typed as text, explained (the work of `mbtap decode`).
//! - [`duration`] — durations as typed (`250ms`, `1s`, `2min`): one parser for every option.
//! - [`line_args`] — line settings from a command line or a capture's description, merged.
//! - [`traffic`] — synthetic traffic with ground truth, observation models, scoring.
//! - [`sim`] — simulated slaves from profiles, the virtual bus with faults, the UART model.
//! - [`fuzzing`] — the bodies of the fuzz targets, also run over the seeds by `cargo test`.

pub use mbtap_proto as proto;

pub mod analyzer;
pub mod capture;
pub mod chunk;
pub mod decode;
pub mod decode_lines;
pub mod duration;
pub mod framer;
pub mod fuzzing;
pub mod health;
pub mod learn;
pub mod line_args;
pub mod pairing;
pub mod profile;
pub mod query;
pub mod replay;
pub mod report;
pub mod scan;
pub mod sim;
pub mod sparkplug;
pub mod spool;
pub mod sunspec;
pub mod traffic;
