//! mbtap's analysis, pure: everything between the bytes a source delivered and what a sink shows.
//!
//! No tokio, terminal, command line, serial crate or clock here — time is an input (each
//! [`chunk::Chunk`] carries its own [`chunk::Timestamp`]), so live capture, replay, the fuzzers and
//! the tests run one code path. CI checks the boundary with `cargo tree -p mbtap-analysis`.
//!
//! Below it: `mbtap-proto` (frames and PDUs, the serial line's timing) and `mbtap-device` (the
//! profiles frames are annotated with). Above it: `mbtap-sim` (simulated lines, the traffic
//! generator) and `mbtap-gateway`. Module map (dependencies point down, never up):
//! - [`chunk`] — bytes as a read delivered them, with their timestamp and port.
//! - [`framer`] — chunks into frames and noise (RTU by structure + CRC + timing; ASCII).
//! - [`pairing`] — requests with their responses on a half-duplex bus.
//! - [`analyzer`] — framers + pairing: one path for live capture, replay and tests.
//! - [`report`] — events rendered as text and JSON lines (pure formatting: strings out).
//! - [`health`] — the bus health report: findings with evidence; text, JSON and HTML.
//! - [`learn`] — a draft profile from what the line says; `diff` of two recordings.
//! - [`scan`] — which line settings give valid frames.
//! - [`capture`] — pcap/pcapng reading and writing, Wireshark export, over `io::Read`/`io::Write`.
//!   Here rather than at the edge because reading a capture is parsing (fuzzed from `fuzz/`
//!   without the edge) and its timestamps are data, not a clock.
//! - [`replay`] — a capture through the analyzer into any sink.
//! - [`decode`] — frames typed as text, explained (the work of `mbtap decode`); [`decode_lines`]
//!   splits what was pasted.
//! - [`duration`] — durations as typed (`250ms`, `1s`, `2min`): one parser for every option.
//! - [`line_args`] — line settings from a command line or a capture's description, merged.
//! - [`fuzzing`] — the bodies of this crate's fuzz targets, also run over the seeds by `cargo test`.

pub mod analyzer;
pub mod capture;
pub mod chunk;
pub mod decode;
pub mod decode_lines;
/// Durations as typed (`250ms`, `2min`): the protocol crate's parser, one for every crate.
pub use mbtap_proto::duration;
pub mod framer;
pub mod fuzzing;
pub mod health;
pub mod learn;
pub mod line_args;
pub mod pairing;
pub mod replay;
pub mod report;
pub mod scan;
