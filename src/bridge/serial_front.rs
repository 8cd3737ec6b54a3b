//! `bridge --listen-serial PORT`: a serial port on which the bridge is the slave, for a master
//! that is already on the device's line (an inverter polling its meter) and must now share the
//! device with TCP clients. Its requests go the way every front's go ([`super::request`]: the
//! gateway core's admission, unit map and read-only rules, the line's cache, the fair queue as
//! a client of its own) and its answers come from the line or the cache; TCP clients are served
//! between them. The two masters never see each other's traffic: each hears only its own
//! port. Units no line serves get silence, as on a line where no slave has that address.
//!
//! Reverse mode (`--reverse`, an RTU master reaching Modbus TCP devices) is this front with a
//! `tcp://` or `rtu-over-tcp://` line behind it, answering as the `--answer-as` addresses: the
//! same admission, queue, timeouts, retries, breaker, cache, answer check and lifetime.

use std::collections::{BTreeSet, VecDeque};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio_serial::{SerialPortBuilderExt, SerialStream};

use super::line::MonitorChunk;

use super::request::{Client, Routes, ServerOptions, request};
use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::framer::LineSettings;
use mbtap_gateway::admit::Role;
use mbtap_gateway::lifetime::{Fate, Ids, Lifetime};
use mbtap_proto::request_frames::RequestFrame;

/// Broadcasts heard and not yet carried out, at most (a master does not wait for them, but
/// leaves the turnaround delay between them: more at once is a flood; the oldest are dropped).
const MAX_BACKLOG: usize = 16;

/// Requests just heard: the newest supersedes every request before it — those in `backlog` and
/// those heard with it (a one-at-a-time master that sent again gave up on them, Serial Line
/// v1.02 §2.4.1), counted as given up; broadcasts, which nobody waits for, are kept to be carried
/// out, at most [`MAX_BACKLOG`] of them.
fn take_newest(backlog: &mut VecDeque<RequestFrame>, heard: Vec<RequestFrame>, routes: &Routes) {
    if heard.is_empty() {
        return;
    }
    backlog.extend(heard);
    let before = backlog.len();
    let last = backlog.len() - 1;
    let mut i = 0;
    backlog.retain(|r| {
        let keep = i == last || r.unit == 0;
        i += 1;
        keep
    });
    while backlog.len() > MAX_BACKLOG {
        backlog.pop_front();
    }
    routes.server.abandoned((before - backlog.len()) as u64);
}

/// The serial port the bridge answers on, and how.
#[derive(Debug, Clone)]
pub struct SerialFront {
    pub port: String,
    pub line: LineSettings,
    pub mode: SerialMode,
    /// Time from the end of a request to the answer, at least (a slave's turnaround).
    pub turnaround: Duration,
    pub rs485: crate::io::rs485::Rs485Args,
    /// The addresses answered as (`--answer-as`); empty: every unit a line serves.
    pub answer_as: BTreeSet<u8>,
    /// The option the user gave for it, for what is said at start (`--listen-serial`,
    /// `--reverse`, `simulate --serial`).
    pub option: &'static str,
}

impl SerialFront {
    /// Whether a request to `unit` is this front's to answer (broadcasts always are).
    fn answers(&self, unit: u8) -> bool {
        unit == 0 || self.answer_as.is_empty() || self.answer_as.contains(&unit)
    }
}

/// Where the front's traffic goes for `--monitor`: what the port heard (port 0) and the answers
/// written (port 1).
type Monitor = Option<mpsc::UnboundedSender<MonitorChunk>>;

/// Bytes the port heard, stamped when the read returned.
fn observe_heard(monitor: &Monitor, bytes: &[u8]) {
    if let Some(m) = monitor.as_ref().filter(|_| !bytes.is_empty()) {
        let _ = m.send((mbtap_analysis::chunk::PortId(0), crate::io::serial::now(), bytes.to_vec(), false));
    }
}

/// An answer written: one whole frame, stamped when its last character leaves.
fn observe_answer(monitor: &Monitor, bytes: &[u8], char_ns: u64) {
    if let Some(m) = monitor {
        let on_wire = char_ns.saturating_mul(bytes.len() as u64);
        let t = mbtap_analysis::chunk::Timestamp(crate::io::serial::now().0.saturating_add(on_wire));
        let _ = m.send((mbtap_analysis::chunk::PortId(1), t, bytes.to_vec(), true));
    }
}

/// Serves the port until the process ends; a port that goes away is reopened every second,
/// said once per spell.
pub async fn serve(front: SerialFront, routes: Arc<Routes>, opts: Arc<ServerOptions>, monitor: Monitor) {
    let mut said = false;
    loop {
        let opened = front
            .rs485
            .prepare(&front.port)
            .and_then(|()| Ok(crate::io::serial::builder(&front.port, front.line).open_native_async()?));
        let mut port = match opened {
            Ok(p) => p,
            Err(e) => {
                if !said {
                    note(
                        &routes,
                        &format!("{} {}: cannot open it ({e:#}); retrying every second", front.option, front.port),
                    );
                    said = true;
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
        };
        said = false;
        if let Err(e) = serve_port(&front, &mut port, &routes, &opts, &monitor).await {
            note(&routes, &format!("{} {}: lost ({e}); reopening", front.option, front.port));
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
}

/// A message for the operator, said with the first line's (the bridge prints those).
fn note(routes: &Routes, text: &str) {
    if let Some(r) = routes.first() {
        r.line.metrics.note(text);
    }
}

async fn serve_port(
    front: &SerialFront,
    port: &mut SerialStream,
    routes: &Routes,
    opts: &ServerOptions,
    monitor: &Monitor,
) -> std::io::Result<()> {
    // A serial master has no address: the priority class by address never holds for it.
    let peer = SocketAddr::from(([0, 0, 0, 0], 0));
    let mut client =
        Client::new(mbtap_gateway::clients::SERIAL_FRONT, Role::Plain, peer, routes, opts).known_as("serial", None);
    let mut heard = super::slave_port::Requests::new(front.mode, front.line);
    // A serial master asks one thing at a time and has no ids (`mbtap_gateway::lifetime`): its
    // next request — to any unit — means it gave up on the last; an answer that would reach it
    // after its own timeout (learnt from when it asks again) is never written.
    let mut lifetime = Lifetime::new(Ids::None);
    let born = tokio::time::Instant::now();
    let mut next_seq = 0u64;
    let mut backlog: VecDeque<RequestFrame> = VecDeque::new();
    loop {
        let Some(r) = backlog.pop_front() else {
            let (requests, bytes) = heard.next(port).await?;
            observe_heard(monitor, &bytes);
            take_newest(&mut backlog, requests, routes);
            continue;
        };
        let seq = next_seq;
        next_seq += 1;
        lifetime.asked(seq, born.elapsed());
        if !front.answers(r.unit) || !opts.policy.serves(r.unit) {
            // Another slave's request on a shared line: not ours to answer.
            continue;
        }
        let broadcast = r.unit == 0;
        let pending = request(&mut client, 0, r.unit, r.pdu, routes, opts);
        // The answer of the line, the cache or the gateway (0A, 0B, a refusal's code) — while
        // the port is listened to: a request heard meanwhile means the master stopped waiting.
        let answer = pending.answer_pdu();
        tokio::pin!(answer);
        let pdu = loop {
            tokio::select! {
                pdu = &mut answer => break Some(pdu),
                more = heard.next(port) => {
                    let (requests, bytes) = more?;
                    observe_heard(monitor, &bytes);
                    if !requests.is_empty() {
                        take_newest(&mut backlog, requests, routes);
                        break None;
                    }
                }
            }
        };
        let Some(pdu) = pdu else {
            // Given up: dropping the answer's receiver keeps it off the line if it has not
            // started; an answer already coming is never written.
            routes.server.abandoned(1);
            continue;
        };
        let Some(pdu) = pdu else {
            lifetime.unanswered(seq);
            continue;
        };
        if broadcast {
            // Broadcasts are never answered (Serial Line v1.02 §2.1).
            lifetime.unanswered(seq);
            continue;
        }
        // When the answer's last character reaches the master: after the turnaround and its
        // own time on the wire (RTU: one byte a character; ASCII: two characters a byte + 5).
        let chars = match front.mode {
            SerialMode::Rtu => pdu.len() + 3,
            SerialMode::Ascii => pdu.len() * 2 + 9,
        };
        let on_wire = Duration::from_nanos(front.line.char_ns().saturating_mul(chars as u64));
        if lifetime.answer(seq, born.elapsed() + front.turnaround + on_wire) == Fate::Withhold {
            routes.server.abandoned(1);
            continue;
        }
        let written = super::slave_port::answer(port, &front.rs485, front.mode, front.turnaround, r.unit, &pdu).await?;
        observe_answer(monitor, &written, front.line.char_ns());
    }
}
