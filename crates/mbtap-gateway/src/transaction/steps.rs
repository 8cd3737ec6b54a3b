//! What the transaction machine is configured with and says: the master's configuration, the
//! steps the shell carries out, the notes it counts and the outcome a client gets.

use crate::answer::Misfit;
use mbtap_proto::ExceptionCode;
use mbtap_proto::serial_line::LineSettings;
use mbtap_proto::serial_line::SerialMode;
use std::time::Duration;

/// What a client gets back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// The slave's response PDU (normal or exception), unchanged.
    Pdu(Vec<u8>),
    /// An exception the gateway answers itself, with this code.
    Gateway(ExceptionCode),
    /// Nothing to send (a broadcast, unless an immediate reply was asked for).
    Silence,
}

/// Whether the adapter echoes what the bridge sends (an RS-485 transceiver whose receiver is
/// not disabled while it drives the line hears every byte it sends).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EchoMode {
    /// Detect it from the first request whose answer cannot look like the request itself
    /// (not 05, 06 or 08, whose normal answers echo the request).
    #[default]
    Auto,
    /// The adapter echoes: consume exactly the frame sent before reading the answer; a
    /// difference is a collision (another driver on the line).
    On,
    /// No echo.
    Off,
}

/// The line and how the master treats it.
#[derive(Debug, Clone)]
pub struct MasterConfig {
    pub line: LineSettings,
    pub mode: SerialMode,
    pub echo: EchoMode,
    /// Retries after a timeout or a failed check.
    pub retries: u32,
    /// Extra quiet time after t3.5 before the next request (slow slaves need it).
    pub turnaround: Duration,
    /// Answer broadcast writes at once (for SCADA that insists on a reply).
    pub broadcast_reply: bool,
    /// How late the adapter may deliver a byte (a USB adapter's latency timer): added to the
    /// silence that ends an answer of unknown length.
    pub latency: Duration,
    /// Someone watches the line (`--monitor`): the bytes heard come back as [`Note::Heard`].
    /// Without it they are not copied (one allocation per read on the bridge's hot path).
    pub monitored: bool,
}

/// The longest ADU a mode carries: RTU 256 bytes (Serial Line v1.02 §2.5.1.1), ASCII 513
/// characters (§2.5.2.1).
#[must_use]
pub const fn max_adu(mode: SerialMode) -> usize {
    match mode {
        SerialMode::Rtu => 256,
        SerialMode::Ascii => 513,
    }
}

impl MasterConfig {
    /// Quiet time after the last byte before the next request: t3.5 plus the turnaround
    /// (Serial Line v1.02 §2.5.1.1).
    #[must_use]
    pub fn line_guard(&self) -> Duration {
        Duration::from_nanos(self.line.t35_ns()) + self.turnaround
    }

    /// The longest ADU its mode carries ([`max_adu`]).
    #[must_use]
    pub fn max_adu(&self) -> usize {
        max_adu(self.mode)
    }

    /// The silence that ends an answer: RTU t3.5, plus one timer tick (reads come in 1 ms
    /// steps) and the adapter's latency; ASCII the 1 s inter-character timeout (Serial Line
    /// v1.02 §2.5.2.1).
    pub(super) fn silence(&self) -> Duration {
        match self.mode {
            SerialMode::Rtu => Duration::from_nanos(self.line.t35_ns()) + Duration::from_millis(1) + self.latency,
            SerialMode::Ascii => Duration::from_secs(1),
        }
    }
}

/// What the machine wants done next.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// Drop stale input, write these bytes, then call [`Transaction::sent`].
    Send(Vec<u8>),
    /// Read until this time: call [`Transaction::bytes`] with what arrives, or
    /// [`Transaction::tick`] when the time is reached (or a read times out early).
    WaitUntil(Duration),
    /// Keep the line quiet until this time, then call [`Transaction::tick`].
    PauseUntil(Duration),
    /// Finished: see [`Transaction::outcome`].
    Done,
}

/// What happened on the way, for the metrics and the monitor, in order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Note {
    /// A request (or a retry) goes out.
    Request,
    /// The timeout this attempt waits.
    UnitTimeout(Duration),
    /// `--echo auto` found that the adapter echoes.
    EchoFound,
    /// The adapter was expected to echo and did not.
    EchoMissing,
    /// Something other than the frame came back while it was sent.
    Collision,
    /// A whole frame with a bad check (or bytes left at the timeout).
    CrcError,
    /// No answer within the timeout.
    Timeout,
    /// A whole timeout waited in vain.
    WaitedInVain(Duration),
    /// An answer to another request (late, or not fitting this one: [`crate::answer::check`]),
    /// dropped.
    LateAnswer(Misfit),
    /// Bytes dropped unread because no answer can be that long: garbage.
    Garbage(usize),
    /// Bytes the monitor should see: port 0 requests (what was heard in place of the
    /// request on a collision), port 1 answers.
    Heard { port: u8, bytes: Vec<u8> },
}

/// How a transaction ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ending {
    pub reply: Reply,
    /// When the line last carried a byte (or the wait ended).
    pub last: Duration,
    /// The answer may fill the cache: neither this unit's previous request nor this one timed
    /// out (an answer after a timeout may be a late one whose shape matched).
    pub cacheable: bool,
    /// After a timeout: listen this long for the unit's late answer, once the client is
    /// answered ([`LateListener`]).
    pub flush: Option<Duration>,
}
