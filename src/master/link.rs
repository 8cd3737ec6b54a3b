//! The link to a device: a serial port (RTU or ASCII), Modbus TCP, or RTU (ASCII) over TCP,
//! opened as a tokio-modbus client context (ASCII through [`super::ascii::AsciiStream`]). Reopened after a timeout, because an answer that arrives late
//! would otherwise be taken for the answer to the next request.

use std::net::SocketAddr;
use std::time::Duration;

use anyhow::Context as _;
use mbtap_analysis::analyzer::SerialMode;
use tokio_modbus::client::Context;
use tokio_modbus::{Slave, prelude::rtu, prelude::tcp};

/// After a timeout, the line is listened to for one more timeout before the next request:
/// what comes then is the late answer to the request given up (or the tail of one), dropped —
/// a late answer of the same shape as the next request's would otherwise be taken as its answer,
/// its values shown under the next request's registers (issue 39, hostile round 3
/// `watch_swap.sh`: 16 of 20 values under the wrong register). Listening stops early once
/// bytes came and the line has been quiet for [`QUIET`].
async fn drain_late_answer<S: tokio::io::AsyncRead + Unpin>(stream: &mut S, window: Duration) {
    use tokio::io::AsyncReadExt as _;
    /// Quiet after the late bytes that ends the listening: longer than any pause inside an
    /// answer at 1200 baud (t3.5 is 32 ms there, Serial Line v1.02 §2.5.1.1).
    const QUIET: Duration = Duration::from_millis(50);
    let end = tokio::time::Instant::now() + window;
    let mut buf = [0u8; 256];
    let mut heard = false;
    loop {
        let now = tokio::time::Instant::now();
        if now >= end {
            return;
        }
        let wait = if heard { QUIET.min(end - now) } else { end - now };
        match tokio::time::timeout(wait, stream.read(&mut buf)).await {
            Ok(Ok(n)) if n > 0 => heard = true,
            // Quiet after the late bytes, closed, an error, or the window over: done.
            _ => return,
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
    /// The last request timed out: listen for its late answer before the next one.
    after_timeout: bool,
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
            .field("after_timeout", &self.after_timeout)
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
        let endpoint = Endpoint::parse(target);
        anyhow::ensure!(
            mode == SerialMode::Rtu || !matches!(endpoint, Endpoint::Tcp(_)),
            "--mode ascii: {target} is Modbus TCP, framed by MBAP, not ASCII; leave --mode out, or give rtu+tcp://{} for a converter that passes ASCII frames",
            target.trim_start_matches("tcp://")
        );
        Ok(Self { endpoint, line: settings, mode, connect_timeout, context: None, after_timeout: false })
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
                    if std::mem::take(&mut self.after_timeout) {
                        drain_late_answer(&mut port, self.connect_timeout).await;
                    }
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
                    if std::mem::take(&mut self.after_timeout) {
                        drain_late_answer(&mut stream, self.connect_timeout).await;
                    }
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

    /// Drops the connection; the next request opens a new one.
    pub fn reset(&mut self) {
        self.context = None;
        self.after_timeout = true;
    }
}
