//! The link to a device: a serial port (RTU or ASCII), Modbus TCP, or RTU (ASCII) over TCP,
//! opened as a tokio-modbus client context (ASCII through [`super::ascii::AsciiStream`]). Reopened after a timeout, because an answer that arrives late
//! would otherwise be taken for the answer to the next request.

use std::net::SocketAddr;
use std::time::Duration;

use anyhow::Context as _;
use mbtap_analysis::analyzer::SerialMode;
use mbtap_gateway::transaction::LateListener;
use tokio_modbus::client::Context;
use tokio_modbus::{Slave, prelude::rtu, prelude::tcp};

/// How late the master's port may deliver a byte, for the silence that ends a late answer: a USB
/// adapter's latency timer (16 ms by default) with room for the scheduler. The master does not
/// learn its adapter, so it takes a bound that holds for the common ones.
const ADAPTER_LATENCY: Duration = Duration::from_millis(40);

/// After a timeout the line is listened to, by the gateway core's rule for late answers
/// ([`LateListener`]), before the next request: what comes then is the late answer to the
/// request given up (or the tail of one), dropped — a late answer of the same shape as the next
/// request's would otherwise be taken as its answer, its values shown under the next request's
/// registers. `origin` is the timeout's instant; the result, when the first late byte came after
/// it, if any did.
async fn drain_late_answer<S: tokio::io::AsyncRead + Unpin>(
    stream: &mut S,
    mut listener: LateListener,
    origin: tokio::time::Instant,
) -> Option<Duration> {
    use tokio::io::AsyncReadExt as _;
    let mut buf = [0u8; 256];
    loop {
        let until = origin + listener.wait_until();
        if tokio::time::Instant::now() >= until || listener.garbage() {
            return listener.first();
        }
        match tokio::time::timeout_at(until, stream.read(&mut buf)).await {
            Ok(Ok(n)) if n > 0 => {
                listener.bytes(origin.elapsed(), n);
            }
            // Quiet until the listener's time, closed, or an error: done.
            _ => return listener.first(),
        }
    }
}

/// Where the device is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    Serial(String),
    Tcp(String),
    RtuOverTcp(String),
}

impl Endpoint {
    /// `rtu+tcp://H:P`, `tcp://H:P`, `H:P`, or a serial port path.
    #[must_use]
    pub fn parse(s: &str) -> Self {
        if let Some(rest) = s.strip_prefix("rtu+tcp://").or_else(|| s.strip_prefix("rtu-over-tcp://")) {
            Self::RtuOverTcp(rest.to_owned())
        } else if let Some(rest) = s.strip_prefix("tcp://") {
            Self::Tcp(rest.to_owned())
        } else if s.contains('/') || s.starts_with("COM") || !s.contains(':') {
            Self::Serial(s.to_owned())
        } else {
            Self::Tcp(s.to_owned())
        }
    }
}

async fn resolve(host_port: &str) -> anyhow::Result<SocketAddr> {
    tokio::net::lookup_host(host_port)
        .await
        .with_context(|| format!("{host_port:?}: expected HOST:PORT"))?
        .next()
        .with_context(|| format!("{host_port:?}: the host name has no address"))
}

/// A reopenable link.
pub struct Link {
    endpoint: Endpoint,
    line: mbtap_analysis::framer::LineSettings,
    mode: SerialMode,
    connect_timeout: Duration,
    context: Option<Context>,
    /// The last request timed out at this instant: listen for its late answer before the next.
    timed_out_at: Option<tokio::time::Instant>,
    /// How long after a timeout a late answer was last heard beginning: the next listening
    /// lasts at least this long (and one timeout at least), so a unit that answers later than
    /// twice the timeout is still heard out before the next request.
    late_by: Duration,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // tokio-modbus's context has no Debug; whether it is open is what matters.
        f.debug_struct("Link")
            .field("endpoint", &self.endpoint)
            .field("line", &self.line)
            .field("mode", &self.mode)
            .field("connect_timeout", &self.connect_timeout)
            .field("open", &self.context.is_some())
            .field("timed_out_at", &self.timed_out_at)
            .field("late_by", &self.late_by)
            .finish()
    }
}

impl Link {
    /// A link that opens on first use. ASCII framing is for serial lines and raw TCP to a
    /// converter (`rtu+tcp://`); Modbus TCP has its own framing (MBAP), and refuses it.
    pub fn new(
        target: &str,
        line: &crate::cli::args::SerialLineArgs,
        connect_timeout: Duration,
    ) -> anyhow::Result<Self> {
        let (mode, settings, _) = line.overrides().resolve();
        // RFC 2217 negotiates the remote port's settings around the bytes; the master speaks
        // through tokio-modbus's transports, which carry none of that. Refused, never taken for
        // a serial path named `rfc2217:`.
        anyhow::ensure!(
            !target.starts_with("rfc2217://"),
            "{target}: RFC 2217 is read by `sniff` and served by `bridge --serial`; for read, write, watch and probe give the serial server's raw TCP port as rtu+tcp://HOST:PORT, or put `mbtap bridge --serial {target} --listen 127.0.0.1:1502` in front and read 127.0.0.1:1502"
        );
        let endpoint = Endpoint::parse(target);
        anyhow::ensure!(
            mode == SerialMode::Rtu || !matches!(endpoint, Endpoint::Tcp(_)),
            "--mode ascii: {target} is Modbus TCP, framed by MBAP, not ASCII; leave --mode out, or give rtu+tcp://{} for a converter that passes ASCII frames",
            target.trim_start_matches("tcp://")
        );
        Ok(Self {
            endpoint,
            line: settings,
            mode,
            connect_timeout,
            context: None,
            timed_out_at: None,
            late_by: Duration::ZERO,
        })
    }

    /// The endpoint, for messages.
    #[must_use]
    pub fn describe(&self) -> String {
        match &self.endpoint {
            Endpoint::Serial(p) => format!("{p} ({}, {})", self.mode_name(), self.line),
            Endpoint::Tcp(a) => format!("{a} (Modbus TCP)"),
            Endpoint::RtuOverTcp(a) => format!("{a} ({} over TCP)", self.mode_name()),
        }
    }

    const fn mode_name(&self) -> &'static str {
        match self.mode {
            SerialMode::Rtu => "RTU",
            SerialMode::Ascii => "ASCII",
        }
    }

    /// The open context, opening it when needed.
    pub async fn context(&mut self, unit: u8) -> anyhow::Result<&mut Context> {
        use tokio_modbus::prelude::SlaveContext as _;
        if self.context.is_none() {
            let slave = Slave(unit);
            let ctx = match &self.endpoint {
                Endpoint::Serial(path) => {
                    let mut port = tokio_serial::SerialStream::open(&crate::source::serial::builder(path, self.line))
                        .with_context(|| format!("opening serial port {path}"))?;
                    // Bytes the port holds from before (a late answer to another process's request)
                    // are not an answer to ours: the input buffer is emptied at every open.
                    let _ = tokio_serial::SerialPort::clear(&port, tokio_serial::ClearBuffer::Input);
                    self.hear_out_late_answer(&mut port).await;
                    match self.mode {
                        SerialMode::Rtu => rtu::attach_slave(port, slave),
                        SerialMode::Ascii => rtu::attach_slave(super::ascii::AsciiStream::new(port), slave),
                    }
                }
                Endpoint::Tcp(a) => {
                    let addr = resolve(a).await?;
                    tokio::time::timeout(self.connect_timeout, tcp::connect_slave(addr, slave))
                        .await
                        .with_context(|| format!("connecting to {addr}: no answer within {:?}", self.connect_timeout))?
                        .with_context(|| format!("connecting to {addr}"))?
                }
                Endpoint::RtuOverTcp(a) => {
                    let addr = resolve(a).await?;
                    let mut stream = tokio::time::timeout(self.connect_timeout, tokio::net::TcpStream::connect(addr))
                        .await
                        .with_context(|| format!("connecting to {addr}: no answer within {:?}", self.connect_timeout))?
                        .with_context(|| format!("connecting to {addr}"))?;
                    self.hear_out_late_answer(&mut stream).await;
                    match self.mode {
                        SerialMode::Rtu => rtu::attach_slave(stream, slave),
                        SerialMode::Ascii => rtu::attach_slave(super::ascii::AsciiStream::new(stream), slave),
                    }
                }
            };
            self.context = Some(ctx);
        }
        let ctx = self.context.as_mut().context("link not open")?;
        ctx.set_slave(Slave(unit));
        Ok(ctx)
    }

    /// Drops the connection; the next request opens a new one, once a late answer to the
    /// request given up has been heard out.
    pub fn reset(&mut self) {
        self.context = None;
        self.timed_out_at = Some(tokio::time::Instant::now());
    }

    /// After a timeout: listens for one timeout after it (or, when the unit was heard later than
    /// that before, that long and a little more), dropping what comes; learns how late the unit
    /// was.
    async fn hear_out_late_answer<S: tokio::io::AsyncRead + Unpin>(&mut self, stream: &mut S) {
        let Some(origin) = self.timed_out_at.take() else { return };
        let window = self.connect_timeout.max(self.late_by + self.late_by / 4);
        let listener = LateListener::on_line(self.line, self.mode, ADAPTER_LATENCY, window, Duration::ZERO);
        if let Some(first) = drain_late_answer(stream, listener, origin).await {
            self.late_by = first;
        }
    }
}
