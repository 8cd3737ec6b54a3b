//! The line's port and its settings: a serial port opened by name (a by-id link or
//! `usb:VID:PID[:SERIAL]` found again wherever the adapter came back), or a serial server or
//! Modbus TCP device connected to ([`crate::io::stream`]); reopened with backoff when it goes
//! away, its absence said once a minute.

use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::Instant;
use tokio_serial::{SerialPort, SerialPortBuilderExt};

use super::shared::LineShared;
use crate::io::stream::{LineStream, Transport};
use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::chunk::{PortId, Timestamp};
use mbtap_analysis::framer::LineSettings;
use mbtap_gateway::cache::{Poll, Rule};
use mbtap_gateway::timeouts::{TimeoutMode, Timeouts};
use mbtap_gateway::transaction::{EchoMode, MasterConfig, SerialMaster};

/// Line settings of the bridge.
#[derive(Debug, Clone)]
pub struct LineOptions {
    pub port: String,
    pub line: LineSettings,
    pub mode: SerialMode,
    /// Per-request response timeout (with `--timeout auto`, the ceiling).
    pub timeout: Duration,
    /// `--timeout fixed|auto`.
    pub timeout_mode: TimeoutMode,
    /// `--unit-timeout`: units with a timeout of their own.
    pub unit_timeouts: std::collections::BTreeMap<u8, Duration>,
    /// `--unit-gap`: silence kept before each request to a unit, beyond the quiet time.
    pub unit_gaps: mbtap_gateway::line::UnitGaps,
    /// `--echo`: whether the adapter hears its own transmission.
    pub echo: EchoMode,
    /// `--rs485`: transmitter direction control.
    pub rs485: crate::io::rs485::Rs485Args,
    /// `--cache` rules for this line's units.
    pub cache: Vec<Rule>,
    /// `--poll`: ranges the bridge keeps fresh itself.
    pub polls: Vec<Poll>,
    /// Retries after a timeout or a failed check.
    pub retries: u32,
    /// Extra quiet time after t3.5 before the next request (slow slaves need it).
    pub turnaround: Duration,
    /// Answer broadcast writes at once (for SCADA that insists on a reply).
    pub broadcast_reply: bool,
    /// How late the adapter may deliver a byte (a USB adapter's latency timer): added to the
    /// silence that ends an answer of unknown length.
    pub latency: Duration,
    /// Devices emulated in this process answer instead of a port (`simulate --listen`).
    pub emulated: Option<std::sync::Arc<crate::source::simulate::emulated::Emulated>>,
}

impl LineOptions {
    /// A line to `port` with every option at its plain value: the timeout fixed at `timeout`, no
    /// per-unit timeouts, echo found by itself, no direction control, cache, polls, retries,
    /// turnaround or latency — what a command that starts a line of its own (`simulate --listen`,
    /// mbtap's master) changes from.
    #[must_use]
    pub fn plain(port: String, line: LineSettings, mode: SerialMode, timeout: Duration) -> Self {
        Self {
            port,
            line,
            mode,
            timeout,
            timeout_mode: TimeoutMode::Fixed,
            unit_timeouts: std::collections::BTreeMap::new(),
            unit_gaps: mbtap_gateway::line::UnitGaps::default(),
            echo: EchoMode::default(),
            rs485: crate::io::rs485::Rs485Args::default(),
            cache: Vec::new(),
            polls: Vec::new(),
            retries: 0,
            turnaround: Duration::ZERO,
            broadcast_reply: false,
            latency: Duration::ZERO,
            emulated: None,
        }
    }

    pub(super) fn master(&self) -> SerialMaster {
        let config = MasterConfig {
            line: self.line,
            mode: self.mode,
            echo: self.echo,
            retries: self.retries,
            turnaround: self.turnaround,
            broadcast_reply: self.broadcast_reply,
            latency: self.latency,
            monitored: false,
        };
        SerialMaster::new(config, Timeouts::new(self.timeout, self.timeout_mode, self.unit_timeouts.clone()))
    }
}

/// Bytes seen on the line, for `--monitor`: port 0 carries requests, port 1 responses; the
/// flag says the bytes are exactly one frame this program wrote (stamped when its last
/// character left), not a read that may hold part of one.
pub type MonitorChunk = (PortId, Timestamp, Vec<u8>, bool);

/// The port and what is known of it between requests.
pub(super) struct Port<'a> {
    pub(super) opts: &'a LineOptions,
    pub(super) shared: &'a LineShared,
    pub(super) monitor: Option<&'a mpsc::UnboundedSender<MonitorChunk>>,
    pub(super) stream: Option<LineStream>,
    /// `tcp://`: the bridge's side of the one connection to a Modbus TCP device.
    pub(super) device: mbtap_gateway::tcp_device::TcpDevice,
    pub(super) backoff: Duration,
    pub(super) next_open: Instant,
    pub(super) watch: crate::io::serial::DeviceWatch,
    /// The port was open once: each later opening is a reopening.
    pub(super) opened_once: bool,
    /// Since when the port has been said missing (None: open, or not tried yet).
    pub(super) missing: Option<Instant>,
}

impl Port<'_> {
    /// Opens the port when due; backoff doubles while it stays away.
    pub(super) async fn reopen(&mut self) {
        self.open().await;
        if self.stream.is_some() {
            self.backoff = Duration::from_millis(100);
        } else {
            self.next_open = Instant::now() + self.backoff;
            self.backoff = (self.backoff * 2).min(Duration::from_secs(5));
        }
    }

    /// The port failed under us: reopened later, with backoff.
    pub(super) fn lost(&mut self, e: &std::io::Error) {
        self.shared.metrics.note(&format!("serial port lost: {e}; reopening"));
        // `EINPROGRESS` (Linux: 115) is what a write on a socket closed underneath gives: its
        // text ("Operation now in progress") says nothing true of what happened.
        if e.raw_os_error() == Some(115) {
            self.shared
                .metrics
                .port_failure(std::io::ErrorKind::ConnectionAborted, "the socket was closed under the request");
        } else {
            self.shared.metrics.port_failure(e.kind(), &e.to_string());
        }
        self.stream = None;
        self.next_open = Instant::now() + self.backoff;
    }

    /// Opens the line's port (a by-id link or `usb:VID:PID[:SERIAL]` found again wherever the
    /// adapter came back), telling when the device behind the name changed.
    pub(super) async fn open(&mut self) {
        let opts = self.opts;
        let transport = Transport::of(&opts.port);
        let opened = if transport.networked() {
            self.device.reset();
            LineStream::connect(transport, opts.line).await
        } else {
            self.open_serial()
        };
        self.opened(opened);
    }

    /// Opens a serial port.
    fn open_serial(&mut self) -> Result<LineStream, String> {
        let opts = self.opts;
        (|| -> Result<LineStream, String> {
            let path = crate::io::serial::resolve_port(&opts.port).map_err(|e| format!("{e:#}"))?;
            // Checked at start-up; a port that comes back must take the mode again.
            opts.rs485.prepare(&path).map_err(|e| format!("{e:#}"))?;
            let port = crate::io::serial::builder(&path, opts.line).open_native_async().map_err(|e| e.to_string())?;
            let _ = port.clear(tokio_serial::ClearBuffer::All);
            if let Some(said) = self.watch.opened(&opts.port, &path) {
                self.shared.metrics.note(&said);
            }
            Ok(LineStream::Serial(port))
        })()
    }

    /// What opening gave: the stream, or why not (said at once, then once a minute).
    fn opened(&mut self, opened: Result<LineStream, String>) {
        let opts = self.opts;
        match opened {
            Ok(port) => {
                // Counted however it came back, idle or at a request's turn (21
                // reconnections to a tcp:// device left port_reopened_total at 0).
                if self.opened_once {
                    self.shared.metrics.reopened();
                }
                self.opened_once = true;
                if let Some(w) = port.warning(&opts.port) {
                    self.shared.metrics.note(&w);
                }
                if self.missing.take().is_some() {
                    self.shared.metrics.note(&format!("serial port {}: open; forwarding requests again", opts.port));
                }
                self.stream = Some(port);
            }
            Err(why) => {
                self.shared.metrics.port_failure(std::io::ErrorKind::NotConnected, &why);
                // Said at once and then once a minute while it lasts (the bridge said
                // only "listening" and every client got 0x0A with no word why).
                if self.missing.is_none_or(|said| said.elapsed() >= MISSING_PORT_REMINDER) {
                    self.missing = Some(Instant::now());
                    self.shared.metrics.note(&format!(
                        "serial port {}: cannot open it ({why}); clients get exception 0x0A (gateway path unavailable) until it opens; trying again every few seconds",
                        opts.port
                    ));
                }
                self.stream = None;
            }
        }
    }
}

/// How often a port that stays missing is said again.
const MISSING_PORT_REMINDER: Duration = Duration::from_mins(1);
