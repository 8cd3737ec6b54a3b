//! The link to a device: one line of the bridge's ([`crate::bridge::line`]) with mbtap's own
//! master as its one client. A request from `read`, `write`, `watch`, `probe`, the mirror or
//! `profiles import --from` takes the path every bridge client's request takes
//! ([`crate::bridge::request::admit`]: the core's admission, then the line's queue); the line
//! drives it through the gateway core — a serial port, `rtu+tcp://` or `rfc2217://` through the
//! transaction machine ([`mbtap_gateway::transaction`]: echo, answer check, retries, the
//! late-answer rule), a Modbus TCP device through [`mbtap_gateway::tcp_device`] (the same
//! answer check, its own transaction ids) — and the reply comes back typed: a PDU, or a
//! [`Failure`] saying why not.

use std::sync::Arc;
use std::time::Duration;

use mbtap_analysis::analyzer::SerialMode;
use mbtap_gateway::admit::{Policy, Role};
use mbtap_gateway::rules::{GATEWAY_PATH_UNAVAILABLE, GATEWAY_TARGET_FAILED};
use mbtap_gateway::transaction::Reply;

use crate::bridge::line::LineOptions;
use crate::bridge::request::{Admission, Client, Route, Routes, ServerOptions, admit};
use crate::bridge::shared::LineShared;
use crate::io::stream::Transport;

/// How a closed connection is said.
pub const CLOSED: &str = "the device closed the connection";

/// Why a request got no usable answer, typed where it was decided (the line's port, the core's
/// answer check and timeouts, admission), never read back from an error's words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Failure {
    /// Nothing (usable) came within the timeout, on every try.
    #[error("no answer from unit {unit} within {ms} ms")]
    Timeout { unit: u8, ms: u128 },
    /// Answers came that do not fit the request (another request's, a late one, or a damaged
    /// one: the core's answer check), and none that does within the timeout.
    #[error(
        "unit {unit}: no fitting answer within {ms} ms; an answer with the wrong {what} was dropped (a late answer to another request, or a damaged one)"
    )]
    Misfit { unit: u8, ms: u128, what: &'static str },
    /// The unit failed its last requests in a row: the line's breaker answers for it until its
    /// next probe ([`mbtap_gateway::breaker`]).
    #[error(
        "unit {unit} failed to answer its last {} requests; it is asked again within {} s (circuit breaker)",
        mbtap_gateway::breaker::BREAK_AFTER,
        mbtap_gateway::breaker::BREAKER_MAX.as_secs()
    )]
    Resting { unit: u8 },
    /// The device (or the converter in front of it) closed the connection.
    #[error("unit {unit}: {CLOSED} ({detail}); the next request opens a new one")]
    Closed { unit: u8, detail: String },
    /// The request itself cannot go (the core's admission: a malformed PDU, a broadcast read).
    #[error("unit {unit}: the request was not sent: {reason}")]
    Refused { unit: u8, reason: &'static str },
    /// The link could not be opened or failed otherwise: the I/O error's kind and words.
    #[error("{detail}")]
    Io { kind: std::io::ErrorKind, detail: String },
}

impl Failure {
    /// Whether the device closed the connection.
    #[must_use]
    pub const fn closed(&self) -> bool {
        matches!(self, Self::Closed { .. })
    }
}

/// A failure of the port, typed by its I/O error's kind: a connection the peer ended is
/// [`Failure::Closed`], anything else [`Failure::Io`].
fn port_failure(unit: u8, kind: std::io::ErrorKind, detail: String) -> Failure {
    use std::io::ErrorKind;
    match kind {
        ErrorKind::ConnectionReset
        | ErrorKind::BrokenPipe
        | ErrorKind::UnexpectedEof
        | ErrorKind::ConnectionAborted => Failure::Closed { unit, detail },
        kind => Failure::Io { kind, detail },
    }
}

/// The line and the master's seat on it, once started (inside the runtime).
struct Running {
    routes: Routes,
    server: ServerOptions,
    task: tokio::task::JoinHandle<()>,
}

impl Drop for Running {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// A device to ask, opened on first use and reopened by its line.
pub struct Link {
    target: String,
    options: LineOptions,
    running: Option<Running>,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link")
            .field("target", &self.target)
            .field("options", &self.options)
            .field("running", &self.running.is_some())
            .finish()
    }
}

/// The port a device's target names, as the bridge's `--serial` takes it: the one target parser
/// ([`Transport::of_device`]), a bare `HOST:PORT` written out as `tcp://HOST:PORT`.
fn port_of(target: &str) -> String {
    match (Transport::of(target), Transport::of_device(target)) {
        (Transport::Serial(_), Transport::ModbusTcp(a)) => format!("tcp://{a}"),
        _ => target.to_owned(),
    }
}

impl Link {
    /// A link that opens on first use: each answer waited for `timeout`, a request that got
    /// none sent again `retries` times. ASCII framing is for serial lines and serial servers
    /// (`rtu+tcp://`, `rfc2217://`); Modbus TCP has its own framing (MBAP), and refuses it.
    pub fn new(
        target: &str,
        line: &crate::cli::args::SerialLineArgs,
        timeout: Duration,
        retries: u32,
    ) -> anyhow::Result<Self> {
        let (mode, settings, _) = line.overrides().resolve();
        let port = port_of(target);
        let transport = Transport::of(&port);
        anyhow::ensure!(
            mode == SerialMode::Rtu || !matches!(transport, Transport::ModbusTcp(_)),
            "--mode ascii: {target} is Modbus TCP, framed by MBAP, not ASCII; leave --mode out, or give rtu+tcp://{} for a converter that passes ASCII frames",
            target.trim_start_matches("tcp://")
        );
        let latency = Duration::from_nanos(transport.latency_ns(None).unwrap_or(0));
        let options = LineOptions { retries, latency, ..LineOptions::plain(port, settings, mode, timeout) };
        Ok(Self { target: target.to_owned(), options, running: None })
    }

    /// The endpoint, for messages.
    #[must_use]
    pub fn describe(&self) -> String {
        let mode = match self.options.mode {
            SerialMode::Rtu => "RTU",
            SerialMode::Ascii => "ASCII",
        };
        match Transport::of(&self.options.port) {
            Transport::Serial(p) => format!("{p} ({mode}, {})", self.options.line),
            Transport::ModbusTcp(a) => format!("{a} (Modbus TCP)"),
            Transport::RtuOverTcp(a) => format!("{a} ({mode} over TCP)"),
            Transport::Rfc2217(a) => format!("{a} ({mode}, {}, RFC 2217)", self.options.line),
        }
    }

    /// How long each answer is waited for.
    #[must_use]
    pub const fn timeout(&self) -> Duration {
        self.options.timeout
    }

    /// Starts the line (inside the runtime) on first use.
    fn running(&mut self) -> &Running {
        self.running.get_or_insert_with(|| {
            // One asker, one request at a time: a queue of one each way is enough.
            let shared = LineShared::new(1, 1, Vec::new());
            let task = tokio::spawn(crate::bridge::line::run(self.options.clone(), Arc::clone(&shared), None));
            // Every unit, and broadcasts (`write --unit 0`): the master is the line's owner.
            let server = ServerOptions {
                rtu_over_tcp: false,
                policy: Policy { routes: vec![0..=u8::MAX], broadcast: true, ..Policy::default() },
                allow_ips: Vec::new(),
                max_connections: 1,
                idle_timeout: Duration::MAX,
                rate_limit: None,
            };
            let routes = Routes { lines: vec![Route { units: 0..=u8::MAX, line: shared }], ..Routes::default() };
            Running { routes, server, task }
        })
    }

    /// Sends `pdu` to `unit` and waits for its answer: the answer's PDU (an exception answer
    /// too; empty for a broadcast, which nobody answers), or why none came.
    ///
    /// # Errors
    /// The [`Failure`].
    pub async fn ask(&mut self, unit: u8, pdu: Vec<u8>) -> Result<Vec<u8>, Failure> {
        let ms = self.options.timeout.as_millis();
        let running = self.running();
        let Some(line) = running.routes.lines.first().map(|r| Arc::clone(&r.line)) else {
            return Err(Failure::Io { kind: std::io::ErrorKind::NotConnected, detail: "no line".into() });
        };
        // What an earlier request left said is no part of this one's story.
        let _ = (line.metrics.take_misfit(), line.metrics.take_port_failure(), line.metrics.take_circuit_open());
        let mut client = Client::local(mbtap_gateway::clients::MASTER, Role::Plain, &running.routes, &running.server)
            .known_as("mbtap", None);
        let reply = match admit(&mut client, unit, pdu, &running.routes, &running.server) {
            Admission::Refused(why) => return Err(Failure::Refused { unit, reason: why.reason() }),
            Admission::Now(reply) => reply,
            Admission::Later(rx) => rx.await.unwrap_or(Reply::Gateway(GATEWAY_TARGET_FAILED)),
        };
        match reply {
            Reply::Pdu(pdu) => Ok(pdu),
            Reply::Silence => Ok(Vec::new()),
            Reply::Gateway(GATEWAY_PATH_UNAVAILABLE) => Err(match line.metrics.take_port_failure() {
                Some((kind, why)) => port_failure(unit, kind, format!("{}: {why}", self.target)),
                None => Failure::Io {
                    kind: std::io::ErrorKind::NotConnected,
                    detail: format!("{}: not open; trying again shortly", self.target),
                },
            }),
            Reply::Gateway(_) => Err(if line.metrics.take_circuit_open() == Some(unit) {
                Failure::Resting { unit }
            } else if let Some(why) = line.metrics.take_misfit() {
                Failure::Misfit { unit, ms, what: why.reason() }
            } else {
                Failure::Timeout { unit, ms }
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bare_host_and_port_is_modbus_tcp_and_a_serial_name_stays_a_port() {
        assert_eq!(port_of("192.0.2.7:502"), "tcp://192.0.2.7:502");
        assert_eq!(port_of("tcp://h:502"), "tcp://h:502");
        assert_eq!(port_of("rtu+tcp://h:4001"), "rtu+tcp://h:4001");
        assert_eq!(port_of("rfc2217://h:2217"), "rfc2217://h:2217");
        assert_eq!(port_of("/dev/ttyUSB0"), "/dev/ttyUSB0");
        assert_eq!(port_of("usb:0403:6001"), "usb:0403:6001");
        assert_eq!(port_of("COM3"), "COM3");
    }

    /// Classified by type, not by words: a reset is a closed connection whatever its text; a
    /// text that merely says "Broken pipe" under another kind is not.
    #[test]
    fn a_failure_is_classified_by_its_kind_not_its_words() {
        use std::io::ErrorKind;
        assert!(port_failure(1, ErrorKind::ConnectionReset, "x".into()).closed());
        assert!(port_failure(1, ErrorKind::UnexpectedEof, "the port closed".into()).closed());
        assert!(!port_failure(1, ErrorKind::NotConnected, "Broken pipe".into()).closed());
        assert!(matches!(
            port_failure(1, ErrorKind::TimedOut, "t".into()),
            Failure::Io { kind: ErrorKind::TimedOut, .. }
        ));
    }
}
