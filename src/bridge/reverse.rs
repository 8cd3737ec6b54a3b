//! Reverse mode: the bridge answers as slave addresses on the serial bus and forwards each
//! request to a Modbus TCP server (or an RTU-over-TCP server: `--target-rtu`), so an RTU (or
//! ASCII) master can reach TCP devices.
//!
//! Requests are framed from the serial bytes the way a slave's UART sees them (structure and
//! CRC, the silence for functions of unknown length: [`mbtap_sim::RequestAssembler`]). The TCP
//! side is a plain MBAP client kept open and reconnected on failure; PDUs pass through
//! unchanged in both directions, vendor codes included — which is why it is not tokio-modbus's
//! client, whose typed responses would have to be re-encoded. A TCP server that cannot be
//! reached gives exception 0x0A, one that does not answer in time 0x0B (MAP v1.1b3 §7).

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio_serial::{SerialPortBuilderExt, SerialStream};

use super::line::MonitorChunk;
use super::metrics::Metrics;
use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::chunk::PortId;
use mbtap_analysis::framer::LineSettings;
use mbtap_gateway::admit::{Asked, Policy, Role};
use mbtap_gateway::answer::check;
use mbtap_gateway::rules::{GATEWAY_PATH_UNAVAILABLE, GATEWAY_TARGET_FAILED, exception_pdu};
use mbtap_gateway::tcp_device::{Heard, TcpDevice};
use mbtap_proto::ExceptionCode;
use mbtap_proto::answer_end::Verdict;
use mbtap_proto::encode_rtu;

/// Reverse-mode settings.
#[derive(Debug, Clone)]
pub struct ReverseOptions {
    pub port: String,
    pub line: LineSettings,
    pub mode: SerialMode,
    /// Serial addresses to answer as (empty: every address 1–247).
    pub units: BTreeSet<u8>,
    /// The Modbus TCP server (`HOST:PORT`).
    pub target: String,
    /// The target speaks RTU over TCP (frames with CRC, no MBAP header) instead of Modbus TCP.
    pub target_rtu: bool,
    pub timeout: Duration,
    /// Time from the end of a request to the answer (a slave's turnaround).
    pub turnaround: Duration,
    /// The forward bridge's admission policy, built once from the same options (read-only,
    /// allowed functions, broadcasts, unit map), with one route for every unit answered.
    pub policy: Policy,
    /// `--rs485`: transmitter direction control for the answers.
    pub rs485: crate::source::rs485::Rs485Args,
}

/// Runs until the future is dropped; the serial port is reopened when it goes away. With
/// `monitor`, the bytes heard (port 0) and answered (port 1) go there for `--monitor`.
pub async fn run(opts: ReverseOptions, metrics: Arc<Metrics>, monitor: Option<mpsc::UnboundedSender<MonitorChunk>>) {
    let mut tcp: Option<TcpStream> = None;
    let mut device = TcpDevice::seeded(super::device::random_seed());
    let metrics = &*metrics;
    loop {
        let prepared = opts.rs485.prepare(&opts.port);
        let Ok(mut port) =
            prepared.and_then(|()| Ok(crate::source::serial::builder(&opts.port, opts.line).open_native_async()?))
        else {
            metrics.note(&format!("cannot open {}; retrying", opts.port));
            tokio::time::sleep(Duration::from_secs(1)).await;
            continue;
        };
        let mut side = Side { tcp: &mut tcp, device: &mut device, metrics, monitor: monitor.as_ref() };
        if let Err(e) = serve_port(&opts, &mut port, &mut side).await {
            metrics.note(&format!("serial port {} lost: {e}; reopening", opts.port));
            metrics.reopened();
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
}

/// What serving a port works with besides the port.
struct Side<'a> {
    tcp: &'a mut Option<TcpStream>,
    device: &'a mut TcpDevice,
    metrics: &'a Metrics,
    monitor: Option<&'a mpsc::UnboundedSender<MonitorChunk>>,
}

impl Side<'_> {
    /// Bytes read from the line (the master's requests), stamped when the read returned.
    fn monitor(&self, port: PortId, bytes: &[u8]) {
        if let Some(m) = self.monitor {
            let _ = m.send((port, crate::source::serial::now(), bytes.to_vec(), false));
        }
    }

    /// An answer this program wrote: one whole frame, stamped when its last character leaves.
    fn monitor_sent(&self, port: PortId, bytes: &[u8], char_ns: u64) {
        if let Some(m) = self.monitor {
            let on_wire = char_ns.saturating_mul(bytes.len() as u64);
            let t = mbtap_analysis::chunk::Timestamp(crate::source::serial::now().0.saturating_add(on_wire));
            let _ = m.send((port, t, bytes.to_vec(), true));
        }
    }
}

async fn serve_port(opts: &ReverseOptions, port: &mut SerialStream, side: &mut Side<'_>) -> std::io::Result<()> {
    let metrics = side.metrics;
    let policy = &opts.policy;
    let mut heard = super::slave_port::Requests::default();
    loop {
        let (requests, got) = heard.next(port, opts.mode, opts.line).await?;
        if !got.is_empty() {
            side.monitor(PortId(0), &got);
        }
        for r in requests {
            let broadcast = r.unit == 0;
            let ours = opts.units.contains(&r.unit) || opts.units.is_empty() && r.unit <= 247;
            if !(broadcast || ours) {
                continue;
            }
            metrics.request(r.unit);
            let fc = r.pdu.first().copied().unwrap_or(0);
            // The gateway core's admission: length, read-only and function rules, broadcasts
            // carry writes only (Serial Line v1.02 §2.1); every unit of ours has a route.
            let asked = Asked { unit: r.unit, pdu: &r.pdu, role: Role::Plain, peer_high: false };
            let refused = policy.admit(asked, None, Duration::ZERO).err();
            let pdu = if let Some(why) = refused {
                // Refused here: never forwarded, answered 01 (MAP v1.1b3 §7: Illegal Function)
                // or 03 for a request of the wrong length.
                metrics.refused(why.reason());
                exception_pdu(fc, why.exception())
            } else {
                match forward(opts, side.tcp, side.device, metrics, r.unit, &r.pdu).await {
                    Ok(pdu) => {
                        metrics.response(r.unit, &pdu);
                        pdu
                    }
                    Err(code) => {
                        metrics.gateway_exception(r.unit, code);
                        exception_pdu(fc, code)
                    }
                }
            };
            if broadcast {
                // Broadcasts are never answered (Serial Line v1.02 §2.1).
                continue;
            }
            let out = super::slave_port::answer(port, &opts.rs485, opts.mode, opts.turnaround, r.unit, &pdu).await?;
            side.monitor_sent(PortId(1), &out, opts.line.char_ns());
        }
    }
}

/// One request to the TCP server; its response PDU, or the gateway exception to answer.
async fn forward(
    opts: &ReverseOptions,
    tcp: &mut Option<TcpStream>,
    device: &mut TcpDevice,
    metrics: &Metrics,
    unit: u8,
    pdu: &[u8],
) -> Result<Vec<u8>, ExceptionCode> {
    // One reconnect per request: a server that restarted is found again at once.
    for _ in 0..2 {
        if tcp.is_none() {
            let connect = tokio::time::timeout(opts.timeout, TcpStream::connect(&opts.target)).await;
            match connect {
                Ok(Ok(s)) => {
                    let _ = s.set_nodelay(true);
                    device.reset();
                    *tcp = Some(s);
                }
                _ => return Err(GATEWAY_PATH_UNAVAILABLE),
            }
        }
        let Some(s) = tcp.as_mut() else { return Err(GATEWAY_PATH_UNAVAILABLE) };
        if opts.target_rtu {
            match forward_rtu(opts, s, unit, pdu).await {
                Ok(answer) => return Ok(answer),
                Err(RtuFailure::Lost) => {
                    *tcp = None;
                    continue;
                }
                Err(RtuFailure::NoAnswer) => {
                    // A late answer would be taken for the next request's: start clean.
                    *tcp = None;
                    return Err(GATEWAY_TARGET_FAILED);
                }
            }
        }
        let frame = device.request(unit, pdu);
        if s.write_all(&frame).await.is_err() {
            *tcp = None;
            continue;
        }
        match tokio::time::timeout(opts.timeout, read_answer(s, device, metrics, unit)).await {
            Ok(Ok(pdu)) => return Ok(pdu),
            Ok(Err(_)) => *tcp = None,
            Err(_) => {
                // A late answer would arrive with this transaction id: start clean.
                *tcp = None;
                return Err(GATEWAY_TARGET_FAILED);
            }
        }
    }
    Err(GATEWAY_PATH_UNAVAILABLE)
}

/// Why an RTU-over-TCP request got no answer.
enum RtuFailure {
    /// The connection failed: reconnect and try once more.
    Lost,
    /// No valid answer in time (or a failed check).
    NoAnswer,
}

/// One request to an RTU-over-TCP server: the RTU frame as on a serial line, the answer found
/// by its structure and CRC (what the forward bridge does on a real line); a function of
/// unknown length ends after 20 ms without bytes — a TCP segment carries no character timing.
async fn forward_rtu(opts: &ReverseOptions, s: &mut TcpStream, unit: u8, pdu: &[u8]) -> Result<Vec<u8>, RtuFailure> {
    const QUIET: Duration = Duration::from_millis(20);
    let mut frame = Vec::with_capacity(pdu.len() + 3);
    encode_rtu(unit, pdu, &mut frame);
    s.write_all(&frame).await.map_err(|_| RtuFailure::Lost)?;
    let function = pdu.first().copied().unwrap_or(0);
    let deadline = tokio::time::Instant::now() + opts.timeout;
    let mut buf: Vec<u8> = Vec::with_capacity(300);
    let mut chunk = [0u8; 300];
    loop {
        let wait = if buf.is_empty() { deadline } else { (tokio::time::Instant::now() + QUIET).min(deadline) };
        let silent = match tokio::time::timeout_at(wait, s.read(&mut chunk)).await {
            Ok(Ok(0) | Err(_)) => return Err(RtuFailure::Lost),
            Ok(Ok(n)) => {
                buf.extend_from_slice(chunk.get(..n).unwrap_or_default());
                // Bounded: an RTU frame is at most 256 bytes (Serial Line v1.02 §2.5.1).
                if buf.len() > 1024 {
                    return Err(RtuFailure::NoAnswer);
                }
                false
            }
            Err(_) if buf.is_empty() || tokio::time::Instant::now() >= deadline => return Err(RtuFailure::NoAnswer),
            Err(_) => true,
        };
        match mbtap_proto::answer_end::judge_rtu(&buf, unit, function, silent) {
            Verdict::Pending => {}
            Verdict::Answer { len } => {
                let answer = buf.get(1..len.saturating_sub(2)).map(<[u8]>::to_vec).ok_or(RtuFailure::NoAnswer)?;
                // The core's one answer check, as for every back.
                match check(unit, pdu, unit, &answer) {
                    Ok(()) => return Ok(answer),
                    Err(_) => {
                        buf.drain(..len);
                    }
                }
            }
            Verdict::BadCheck => return Err(RtuFailure::NoAnswer),
            Verdict::Foreign => buf.clear(),
        }
    }
}

/// Reads MBAP frames until the answer to the request `device` awaits — matched by its
/// transaction id and put through the core's answer check, as on the forward bridge's
/// `tcp://` lines; what does not fit is dropped and counted.
async fn read_answer(
    s: &mut TcpStream,
    device: &mut TcpDevice,
    metrics: &Metrics,
    unit: u8,
) -> std::io::Result<Vec<u8>> {
    let mut chunk = [0u8; 300];
    loop {
        let n = s.read(&mut chunk).await?;
        if n == 0 {
            return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the server closed"));
        }
        let (heard, dropped) = device.bytes(chunk.get(..n).unwrap_or_default());
        metrics.answers_dropped(unit, &dropped);
        match heard {
            Heard::More => {}
            Heard::Answer { pdu, .. } => return Ok(pdu),
            Heard::Broken => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    "the server's stream is not Modbus TCP",
                ));
            }
        }
    }
}
