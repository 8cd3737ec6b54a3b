//! The serial master behind the bridge, as an I/O shell: requests taken in turn from the
//! clients' queues ([`super::shared::LineShared`]), each driven through the gateway core's
//! transaction machine (`mbtap_gateway::transaction`) — the shell writes what it says, reads
//! until the time it names, and feeds back bytes and time — and the reply handed back to its
//! client alone. What the line decides around each request (breaker, cache fill, quiet time)
//! is the core's line's ([`mbtap_gateway::line`]), the same for a Modbus TCP device (`tcp://`,
//! [`super::device`]) and for emulated devices ([`super::emulated`]). The port is reopened with backoff when it goes away (a USB adapter pulled);
//! meanwhile requests get exception 0x0A (Gateway Path Unavailable, MAP v1.1b3 §7). The line
//! task never exits on its own.

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::Instant;

use super::metrics::Metrics;
use super::port::Port;
pub use super::port::{LineOptions, MonitorChunk};
use super::shared::{Job, LineShared};
use crate::io::pace::wait_until;
use crate::io::stream::Transport;
use mbtap_analysis::chunk::{PortId, Timestamp};
use mbtap_gateway::line::{Back, Start, class};
use mbtap_gateway::rules::GATEWAY_PATH_UNAVAILABLE;
use mbtap_gateway::transaction::{Ending, LateListener, MasterConfig, Note, Reply, SerialMaster, Step, Transaction};

/// Runs the line forever.
pub async fn run(opts: LineOptions, shared: Arc<LineShared>, monitor: Option<mpsc::UnboundedSender<MonitorChunk>>) {
    let mut port = Port {
        opts: &opts,
        shared: &shared,
        monitor: monitor.as_ref(),
        stream: None,
        backoff: Duration::from_millis(100),
        next_open: Instant::now(),
        watch: crate::io::serial::DeviceWatch::default(),
        missing: None,
        opened_once: false,
        // Transaction ids toward the device start where nobody can guess (counted from 0, an
        // unsolicited answer under the next id would be taken).
        device: mbtap_gateway::tcp_device::TcpDevice::seeded(super::device::random_seed()),
    };
    let device = matches!(Transport::of(&opts.port), Transport::ModbusTcp(_));
    let mut master = opts.master();
    master.config.monitored = monitor.is_some();
    // The line is free for the next request from this time on (t3.5 + turnaround after the
    // last byte, Serial Line v1.02 §2.5.1.1).
    let mut free_at = Instant::now();
    let mut decide = mbtap_gateway::line::Line::new(if device {
        Back::TcpDevice
    } else {
        Back::Serial { guard: master.config.line_guard() }
    })
    .with_gaps(opts.unit_gaps.clone());
    loop {
        let Some((client, job)) = shared.next() else {
            // Wake on a new request, or now and then to retry opening the port.
            let _ = tokio::time::timeout(Duration::from_millis(500), shared.wake.notified()).await;
            // With backoff: a server streaming an endless negotiation, reconnected every half
            // second, costs a core (each attempt reads at full speed).
            if port.stream.is_none() && Instant::now() >= port.next_open {
                port.reopen().await;
            }
            continue;
        };
        if job.reply.is_closed() {
            // The client left while this request waited: no line time for it.
            shared.metrics.dropped();
            let mut job = job;
            job.audited("not sent: the client left before the line took it");
            continue;
        }
        if port.stream.is_none() && Instant::now() >= port.next_open {
            port.reopen().await;
        }
        if port.stream.is_none() {
            answer(&shared, job, Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
            continue;
        }
        if let Start::Answer(reply) = decide.start(job.unit, shared.now()) {
            shared.metrics.circuit_open(job.unit);
            answer(&shared, job, reply);
            continue;
        }
        // The unit's own gap, on top of the line's quiet time: the core says when it may go.
        let ready = shared.instant(decide.ready_at(job.unit, shared.since_start(free_at)));
        let gap_waited = ready.saturating_duration_since(free_at.max(Instant::now()));
        if !gap_waited.is_zero() {
            shared.metrics.unit_gap_wait(job.unit, gap_waited);
        }
        wait_until(ready.max(free_at)).await;
        let on_line_from = Instant::now();
        let twins = shared.twins(client, &job);
        // A write may change what the cache holds, whatever its outcome.
        shared.cache().invalidate(job.unit, &job.pdu);
        let done =
            if device { port.transact_tcp(&mut master, &job).await } else { port.transact(&mut master, &job).await };
        let Ok(outcome) = done else {
            // The port failed under us: answer 0x0A and reopen with backoff.
            for twin in twins {
                let _ = twin.reply.send(Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
            }
            answer(&shared, job, Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
            continue;
        };
        let Ending { reply, last, cacheable, flush } = outcome;
        let last = shared.instant(last);
        let finished = decide.finished(job.unit, &reply, cacheable, shared.now());
        shared.metrics.resting(job.unit, decide.resting(job.unit, shared.now()));
        if let Reply::Pdu(pdu) = &reply
            && job.unit != 0
        {
            shared.metrics.response(job.unit, pdu);
            if finished.fill_cache {
                shared.cache().fill(job.unit, &job.pdu, pdu, shared.now());
            }
        }
        shared.metrics.line_time(class(client, job.high), last.saturating_duration_since(on_line_from));
        for twin in twins {
            shared.metrics.latency(twin.unit, twin.queued.elapsed());
            let _ = twin.reply.send(reply.clone());
        }
        let guard = finished.quiet;
        free_at = last + guard;
        shared.metrics.latency(job.unit, job.queued.elapsed());
        let unit = job.unit;
        answer(&shared, job, reply);
        // The client has its answer (or 0x0B); now what a slow unit says late is heard and
        // dropped before the next request goes out — but only where that request could take
        // it for its own: the same unit's. Another unit's request goes at once (a
        // dead unit cost every queued request two timeouts); a late answer carries its unit's
        // address and the answer check drops it.
        if let Some(window) = flush
            && shared.may_take_late_answer(unit)
            && let Some(last) = port.flush_late(unit, window, &master.config).await
        {
            free_at = free_at.max(last + guard);
        }
    }
}

/// Hands `reply` to the job's client, counting a gateway exception (every line task's ending).
pub(super) fn answer(shared: &LineShared, mut job: Job, reply: Reply) {
    if let Reply::Gateway(code) = reply {
        shared.metrics.gateway_exception(job.unit, code);
    }
    let outcome = mbtap_gateway::audit::outcome(&reply);
    job.audited(&outcome);
    shared.metrics.transaction(job.unit, &job.pdu, outcome, job.queued.elapsed());
    let _ = job.reply.send(reply);
}

impl Port<'_> {
    /// Drives one request through the gateway core's transaction machine.
    async fn transact(&mut self, master: &mut SerialMaster, job: &Job) -> std::io::Result<Ending> {
        let (mut t, mut step) = master.transaction(job.unit, &job.pdu);
        let result = self.drive(&mut t, &mut step, job.unit).await;
        self.notes(&mut t, job.unit);
        if let Err(e) = &result {
            self.lost(e);
        }
        result?;
        t.outcome().cloned().ok_or_else(|| std::io::Error::other("the transaction ended without an outcome"))
    }

    async fn drive(&mut self, t: &mut Transaction<'_>, step: &mut Step, unit: u8) -> std::io::Result<()> {
        let shared = self.shared;
        let mut chunk = [0u8; 512];
        loop {
            self.notes(t, unit);
            let Some(port) = self.stream.as_mut() else {
                return Err(std::io::Error::new(std::io::ErrorKind::NotConnected, "no port"));
            };
            *step = match std::mem::replace(step, Step::Done) {
                Step::Send(adu) => {
                    // Stale bytes (a late answer to an earlier request, noise) must not be taken
                    // for this request's answer.
                    let dropped = port.clear_input();
                    shared.metrics.garbage(dropped);
                    port.send(&self.opts.rs485, &adu).await?;
                    self.observe_sent(&adu);
                    // With --rs485 rts the send returned when the last character left (tcdrain).
                    let drained = self.opts.rs485.rs485 == crate::io::rs485::Rs485Mode::Rts;
                    t.sent(shared.now(), drained)
                }
                Step::WaitUntil(until) => {
                    match tokio::time::timeout_at(shared.instant(until), port.read(&mut chunk)).await {
                        Ok(Ok(0)) => {
                            return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the port closed"));
                        }
                        Ok(Ok(n)) => t.bytes(shared.now(), chunk.get(..n).unwrap_or_default()),
                        Ok(Err(e)) if e.kind() == std::io::ErrorKind::TimedOut => t.tick(shared.now()),
                        Ok(Err(e)) => return Err(e),
                        Err(_) => t.tick(shared.now()),
                    }
                }
                Step::PauseUntil(until) => {
                    wait_until(shared.instant(until)).await;
                    t.tick(shared.now())
                }
                Step::Done => return Ok(()),
            };
        }
    }

    /// What the transaction noted, to the metrics and the monitor.
    fn notes(&self, t: &mut Transaction<'_>, unit: u8) {
        let m: &Metrics = &self.shared.metrics;
        for note in t.take_notes() {
            match note {
                Note::Request => m.request(unit),
                Note::UnitTimeout(d) => m.unit_timeout(unit, d),
                Note::EchoFound => {
                    m.note(&format!("{}: the adapter echoes what is sent (--echo auto)", self.opts.port));
                }
                Note::EchoMissing => m.echo_missing(unit),
                Note::Collision => m.collision(unit),
                Note::CrcError => m.crc_error(unit),
                Note::Timeout => m.timeout(unit),
                Note::WaitedInVain(d) => m.waited_in_vain(unit, d),
                Note::LateAnswer(why) => m.misfit(unit, why),
                Note::Garbage(bytes) => m.garbage(bytes),
                Note::Heard { port, bytes } => self.observe(port, &bytes),
            }
        }
    }

    /// After a timeout: listens for what the unit says late and drops it; when the line was
    /// last busy (None: the port was lost meanwhile).
    async fn flush_late(&mut self, unit: u8, window: Duration, config: &MasterConfig) -> Option<Instant> {
        let shared = self.shared;
        // At most 1 s: a slow unit's late words cost the other clients' requests little.
        let mut listener = LateListener::new(config, window.min(Duration::from_secs(1)), shared.now());
        let mut chunk = [0u8; 512];
        loop {
            let port = self.stream.as_mut()?;
            let until = shared.instant(listener.wait_until());
            let read = tokio::select! {
                r = tokio::time::timeout_at(until, port.read(&mut chunk)) => r,
                // A request arrived meanwhile: if it is another unit's, it goes now.
                () = shared.wake.notified() => {
                    if shared.may_take_late_answer(unit) {
                        continue;
                    }
                    // The permit taken here is the line loop's: give it back.
                    shared.wake.notify_one();
                    break;
                }
            };
            match read {
                Ok(Ok(0)) => {
                    self.lost(&std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the port closed"));
                    return None;
                }
                Ok(Ok(n)) => {
                    self.observe(1, chunk.get(..n).unwrap_or_default());
                    if listener.bytes(shared.now(), n) {
                        shared.metrics.late_answer(unit);
                    }
                    if listener.garbage() {
                        shared.metrics.garbage(n);
                        break;
                    }
                }
                Ok(Err(e)) if e.kind() == std::io::ErrorKind::TimedOut => break,
                Ok(Err(e)) => {
                    self.lost(&e);
                    return None;
                }
                Err(_) => break,
            }
        }
        Some(shared.instant(listener.last()))
    }

    /// Bytes read from the line, stamped when the read returned.
    pub(super) fn observe(&self, port: u8, bytes: &[u8]) {
        if let Some(m) = self.monitor {
            let _ = m.send((PortId(port), crate::io::serial::now(), bytes.to_vec(), false));
        }
    }

    /// A frame this program wrote, stamped when its last character leaves the wire (the write
    /// returns as soon as the bytes are queued; stamping them then back-dated the request by
    /// its own transmission time, and the monitor saw a gap shorter than the line's).
    pub(super) fn observe_sent(&self, bytes: &[u8]) {
        if let Some(m) = self.monitor {
            let on_wire = self.opts.line.char_ns().saturating_mul(bytes.len() as u64);
            let t = Timestamp(crate::io::serial::now().0.saturating_add(on_wire));
            let _ = m.send((PortId(0), t, bytes.to_vec(), true));
        }
    }
}
