//! mbtap — a Modbus RTU/ASCII bus analyzer: the binary's edges. The analysis itself is pure and
//! lives in the workspace's libraries: `mbtap-proto` (frames and PDUs), `mbtap-device` (profiles,
//! SunSpec, queries), `mbtap-analysis` (framers, pairing, health, learn, captures), `mbtap-sim`
//! (simulated lines and devices), `mbtap-publish` (Sparkplug, the spool) and `mbtap-gateway`,
//! which import no tokio, terminal, command line or serial crate and read no clock.
//!
//! Module map (dependencies point down, never up):
//! - [`cmd`] — one file per command: its options and its `run`; `main` parses and dispatches.
//! - [`cli`] — what the commands share: the options several take ([`cli::args`]) and the one
//!   runner of the analyzing commands ([`cli::runner`]: the UI or stdout, publishers, the end).
//! - [`bridge`] — Modbus TCP ⇄ serial: server, line masters, the serial front (and reverse mode
//!   through it), metrics, its config file.
//! - [`tui`] — the terminal UI (ratatui), rendered from the model the events build.
//! - [`source`] — the analysing sources' loops (`sniff`, `tap`, `scan`, `play`, `demo`) and
//!   `simulate`'s pseudo-terminal with the devices every front serves.
//! - [`io`] — ports and transports (serial, RS-485, streams, the pty), the clock, fine waits and
//!   the one stop of every loop ([`io::signals`]).
//! - [`master`] — `read`/`write`/`watch`: requests to a device through tokio-modbus (RTU on a
//!   serial port, TCP, RTU over TCP), planned and checked by `mbtap_device::query`.
//! - [`publish`] — what the sniffer hears, served to others: a read-only Modbus TCP server of
//!   the register image (spy mode) and MQTT.
//! - [`output`] — the output sink: events as text or JSON lines, the UI feed, reports; and the
//!   progress of reading a capture file.
//! - [`config`] — the user configuration file, and device profiles by the names users give them.

pub mod bridge;
pub mod cli;
pub mod cmd;
pub mod config;
pub mod io;
pub mod master;
pub mod output;
pub mod publish;
pub mod source;
pub mod tui;

/// A single-threaded runtime for one command's I/O (at the root: the commands and the master,
/// which discovers SunSpec devices before a command runs, both need one).
///
/// # Errors
/// The runtime cannot be started.
pub(crate) fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    use anyhow::Context as _;
    tokio::runtime::Builder::new_current_thread().enable_all().build().context("starting the runtime")
}
