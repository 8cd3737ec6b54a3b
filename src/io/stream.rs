//! What a line is reached through: a serial port, a serial server's TCP stream carrying the
//! remote line's bytes as they are (`rtu-over-tcp://`), a remote port set over Telnet
//! (`rfc2217://`, the gateway core's [`Telnet`] codec), or — for the bridge only — a Modbus TCP
//! device (`tcp://`, one connection for every client). `sniff`, `tap` and the bridge's line
//! task read and write through [`LineStream`] whatever it is.

use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_serial::{SerialPort, SerialStream};

use mbtap_analysis::framer::LineSettings;
use mbtap_proto::rfc2217::Telnet;

/// The most bytes one [`LineStream::clear_input`] drops before it returns: sixteen of the
/// longest MBAP or RTU ADUs (260 bytes, Messaging on TCP/IP v1.0b §4.1).
const CLEAR_LIMIT: usize = 16 * 260;
/// The most a Telnet server may send before it agrees to the COM port option.
const NEGOTIATION_LIMIT: usize = 64 * 1024;
/// How long connecting to a serial server or a device may take.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(3);

/// Where a line's bytes go, by the name `--serial`/`--route` gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport<'a> {
    /// A serial port (a path, a by-id link, `usb:VID:PID`).
    Serial(&'a str),
    /// `rtu-over-tcp://HOST:PORT` (also `rtu+tcp://`): a serial server in transparent mode.
    RtuOverTcp(&'a str),
    /// `rfc2217://HOST:PORT`: a remote serial port whose settings the bridge sets.
    Rfc2217(&'a str),
    /// `tcp://HOST:PORT`: a Modbus TCP device.
    ModbusTcp(&'a str),
}

impl<'a> Transport<'a> {
    #[must_use]
    pub fn of(port: &'a str) -> Self {
        if let Some(a) = port.strip_prefix("rtu-over-tcp://").or_else(|| port.strip_prefix("rtu+tcp://")) {
            Self::RtuOverTcp(a)
        } else if let Some(a) = port.strip_prefix("rfc2217://") {
            Self::Rfc2217(a)
        } else if let Some(a) = port.strip_prefix("tcp://") {
            Self::ModbusTcp(a)
        } else {
            Self::Serial(port)
        }
    }

    /// A device's address as `read`, `write`, `watch` and `probe` take it: as [`Self::of`], and a
    /// bare `HOST:PORT` (a port number after the last colon, no path) is a Modbus TCP device —
    /// `usb:VID:PID` and `COM3` stay serial ports.
    #[must_use]
    pub fn of_device(target: &'a str) -> Self {
        match Self::of(target) {
            Self::Serial(s) if !s.contains('/') && !s.starts_with("usb:") => match s.rsplit_once(':') {
                Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok() => Self::ModbusTcp(s),
                _ => Self::Serial(s),
            },
            other => other,
        }
    }

    /// Reached over the network: no RS-485 direction control, no serial ioctls.
    #[must_use]
    pub const fn networked(self) -> bool {
        !matches!(self, Self::Serial(_))
    }

    /// How late its bytes may arrive, decided once for every command (sniff, tap, learn, the
    /// bridge): what `--latency-ms` gave (`given`, `None`: not given — never taken for 0), else
    /// for a line reached over the network [`SERIAL_SERVER_LATENCY`]; `None` for a local port
    /// whose adapter is asked ([`crate::io::serial::prepare_latency`]).
    #[must_use]
    pub const fn latency_ns(self, given: Option<u64>) -> Option<u64> {
        match (given, self.networked()) {
            (Some(ns), _) => Some(ns),
            (None, true) => Some(SERIAL_SERVER_LATENCY),
            (None, false) => None,
        }
    }
}

/// What a serial server's TCP stream is trusted to in timing (unless `--latency-ms` says): its
/// buffering and the network's split and join the line's bytes far beyond t3.5 at any baud rate,
/// so silences shorter than this are not taken as frame ends (sniffing) or as the end of an
/// answer whose length its structure does not give (the bridge). One figure for every command:
/// the line behind a serial server is the same line whoever listens to it.
pub const SERIAL_SERVER_LATENCY: u64 = 100_000_000;

/// An open line.
pub enum LineStream {
    Serial(SerialStream),
    /// A serial server's stream, or a Modbus TCP device's connection.
    Tcp(TcpStream),
    /// A remote port over Telnet: the session's state and line bytes already decoded.
    Telnet {
        tcp: TcpStream,
        telnet: Box<Telnet>,
        pending: Vec<u8>,
    },
}

impl std::fmt::Debug for LineStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Serial(_) => "LineStream::Serial",
            Self::Tcp(_) => "LineStream::Tcp",
            Self::Telnet { .. } => "LineStream::Telnet",
        })
    }
}

async fn connect(addr: &str) -> Result<TcpStream, String> {
    let tcp = tokio::time::timeout(CONNECT_TIMEOUT, TcpStream::connect(addr))
        .await
        .map_err(|_| format!("no connection to {addr} within {} s", CONNECT_TIMEOUT.as_secs()))?
        .map_err(|e| format!("connecting to {addr}: {e}"))?;
    // A request is one small write that must leave at once.
    let _ = tcp.set_nodelay(true);
    Ok(tcp)
}

impl LineStream {
    /// Connects to a networked transport; a Telnet server must agree to the COM port option
    /// (and is given the line's settings) before the line is taken as open.
    pub async fn connect(transport: Transport<'_>, line: LineSettings) -> Result<Self, String> {
        match transport {
            Transport::Serial(_) => Err("a serial port is opened by the port's own path".into()),
            Transport::RtuOverTcp(addr) | Transport::ModbusTcp(addr) => Ok(Self::Tcp(connect(addr).await?)),
            Transport::Rfc2217(addr) => {
                let mut tcp = connect(addr).await?;
                let mut telnet = Box::new(Telnet::new(line));
                tcp.write_all(&Telnet::greeting()).await.map_err(|e| format!("{addr}: {e}"))?;
                let (mut pending, mut reply, mut buf) = (Vec::new(), Vec::new(), [0u8; 256]);
                let deadline = tokio::time::Instant::now() + CONNECT_TIMEOUT;
                let mut received = 0usize;
                while !telnet.configured {
                    // A server that talks without end before agreeing (an endless
                    // subnegotiation) is no RFC 2217 server: given up at once, not read at full
                    // speed until the timeout (97 % CPU).
                    if received > NEGOTIATION_LIMIT {
                        return Err(format!(
                            "{addr} sent {received} bytes without agreeing to the COM port option (RFC 2217); not a serial server the bridge can set"
                        ));
                    }
                    let n = match tokio::time::timeout_at(deadline, tcp.read(&mut buf)).await {
                        Ok(Ok(n)) if n > 0 => n,
                        Ok(Ok(_)) => return Err(format!("{addr} closed the connection while negotiating")),
                        Ok(Err(e)) => return Err(format!("{addr}: {e}")),
                        Err(_) => {
                            return Err(format!(
                                "{addr} does not offer RFC 2217 (no DO COM-PORT-OPTION within {} s); for a raw TCP serial server use rtu-over-tcp://",
                                CONNECT_TIMEOUT.as_secs()
                            ));
                        }
                    };
                    received = received.saturating_add(n);
                    telnet.feed(buf.get(..n).unwrap_or_default(), &mut pending, &mut reply);
                    // Line bytes before the settings were heard at other settings: not kept.
                    pending.clear();
                    if !reply.is_empty() {
                        tcp.write_all(&reply).await.map_err(|e| format!("{addr}: {e}"))?;
                        reply.clear();
                    }
                }
                // Bytes before the settings took effect were heard at other settings.
                pending.clear();
                Ok(Self::Telnet { tcp, telnet, pending })
            }
        }
    }

    /// Drops what was received and not read (a late answer, noise): it must not be taken for
    /// the next request's answer. Bounded (a server streaming garbage would keep an unbounded
    /// loop reading, never yielding, and stall every route): at most [`CLEAR_LIMIT`] bytes a call;
    /// what is left is the answer check's to drop. Returns the bytes dropped.
    pub fn clear_input(&mut self) -> usize {
        let mut buf = [0u8; 512];
        let mut dropped = 0;
        match self {
            Self::Serial(port) => {
                let _ = port.clear(tokio_serial::ClearBuffer::Input);
            }
            Self::Tcp(tcp) => {
                while dropped < CLEAR_LIMIT
                    && let Ok(n @ 1..) = tcp.try_read(&mut buf)
                {
                    dropped += n;
                }
            }
            Self::Telnet { tcp, telnet, pending } => {
                let mut reply = Vec::new();
                dropped += pending.len();
                pending.clear();
                while dropped < CLEAR_LIMIT
                    && let Ok(n @ 1..) = tcp.try_read(&mut buf)
                {
                    telnet.feed(buf.get(..n).unwrap_or_default(), pending, &mut reply);
                    dropped += pending.len();
                    pending.clear();
                    // A server may make Telnet answers without end: one read's worth kept.
                    reply.truncate(1024);
                }
                // Telnet's answers go out with the next write.
                if !reply.is_empty() {
                    let _ = tcp.try_write(&reply);
                }
            }
        }
        dropped
    }

    /// What the remote end agreed to that the user should hear of (a Telnet server refusing
    /// binary mode: its CR NUL is undone, but a server that does so may alter other bytes).
    #[must_use]
    pub fn warning(&self, name: &str) -> Option<String> {
        match self {
            Self::Telnet { telnet, .. } if telnet.binary_refused() => Some(format!(
                "{name}: the Telnet server refuses binary mode (RFC 856); the line's bytes travel as NVT text, a CR as CR NUL, undone by the bridge — set the server's port to binary (ser2net: telnet(rfc2217) with no 'nobinary') if answers fail"
            )),
            _ => None,
        }
    }

    /// Sends one frame.
    pub async fn send(&mut self, rs485: &crate::io::rs485::Rs485Args, frame: &[u8]) -> std::io::Result<()> {
        match self {
            Self::Serial(port) => rs485.send(port, frame).await,
            Self::Tcp(tcp) => tcp.write_all(frame).await,
            Self::Telnet { tcp, telnet, .. } => tcp.write_all(&telnet.escape_out(frame)).await,
        }
    }

    /// Reads the line's next bytes (0: the other end closed).
    pub async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            Self::Serial(port) => port.read(buf).await,
            Self::Tcp(tcp) => tcp.read(buf).await,
            Self::Telnet { tcp, telnet, pending } => loop {
                if !pending.is_empty() {
                    let n = pending.len().min(buf.len());
                    buf.get_mut(..n).unwrap_or_default().copy_from_slice(pending.get(..n).unwrap_or_default());
                    pending.drain(..n);
                    return Ok(n);
                }
                let mut raw = [0u8; 512];
                let n = tcp.read(&mut raw).await?;
                if n == 0 {
                    return Ok(0);
                }
                let mut reply = Vec::new();
                telnet.feed(raw.get(..n).unwrap_or_default(), pending, &mut reply);
                if !reply.is_empty() {
                    tcp.write_all(&reply).await?;
                }
            },
        }
    }
}

impl LineStream {
    /// Opens a line to listen to or to tap (`sniff`, `tap`): a serial port by name (a by-id
    /// link, `usb:VID:PID`), or a serial server. A Modbus TCP device is not a line.
    ///
    /// # Errors
    /// The port cannot be opened, the server not reached, or `port` names a Modbus TCP device.
    pub async fn open_line(
        port: &str,
        line: LineSettings,
        watch: &mut crate::io::serial::DeviceWatch,
        err: &mut dyn std::io::Write,
    ) -> anyhow::Result<Self> {
        use anyhow::Context as _;
        match Transport::of(port) {
            Transport::Serial(name) => Ok(Self::Serial(
                crate::io::serial::open_named(name, line, watch, err)
                    .with_context(|| format!("opening serial port {name} ({line})"))?,
            )),
            Transport::ModbusTcp(addr) => anyhow::bail!(
                "{port}: tcp:// names a Modbus TCP device, not a line; a serial server's line is rtu-over-tcp://{addr} (raw) or rfc2217://{addr} (Telnet)"
            ),
            networked => Self::connect(networked, line).await.map_err(|e| anyhow::anyhow!("{e}")),
        }
    }
}
