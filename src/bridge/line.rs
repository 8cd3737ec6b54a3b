//! The serial master behind the bridge, as an I/O shell: requests taken in turn from the
//! clients' queues ([`super::shared::LineShared`]), each driven through the gateway core's
//! transaction machine (`mbtap_gateway::transaction`) — the shell writes what it says, reads
//! until the time it names, and feeds back bytes and time — and the reply handed back to its
//! client alone. The port is reopened with backoff when it goes away (a USB adapter pulled);
//! meanwhile requests get exception 0x0A (Gateway Path Unavailable, MAP v1.1b3 §7). The line
//! task never exits on its own.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::AsyncReadExt;
use tokio::sync::mpsc;
use tokio::time::Instant;
use tokio_serial::{SerialPort, SerialPortBuilderExt, SerialStream};

use super::metrics::Metrics;
use super::shared::{Job, LineShared, POLL_CLIENT};
use mbtap_core::analyzer::SerialMode;
use mbtap_core::chunk::{PortId, Timestamp};
use mbtap_core::framer::LineSettings;
use mbtap_gateway::breaker::Breaker;
use mbtap_gateway::cache::{Poll, Rule};
use mbtap_gateway::rules::{GATEWAY_PATH_UNAVAILABLE, GATEWAY_TARGET_FAILED};
use mbtap_gateway::timeouts::{TimeoutMode, Timeouts};
use mbtap_gateway::transaction::{
    EchoMode, LateListener, MasterConfig, Note, Outcome, Reply, SerialMaster, Step, Transaction,
};

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
    /// `--echo`: whether the adapter hears its own transmission.
    pub echo: EchoMode,
    /// `--rs485`: transmitter direction control.
    pub rs485: crate::source::rs485::Rs485Args,
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
}

impl LineOptions {
    fn master(&self) -> SerialMaster {
        let config = MasterConfig {
            line: self.line,
            mode: self.mode,
            echo: self.echo,
            retries: self.retries,
            turnaround: self.turnaround,
            broadcast_reply: self.broadcast_reply,
            latency: self.latency,
        };
        SerialMaster::new(config, Timeouts::new(self.timeout, self.timeout_mode, self.unit_timeouts.clone()))
    }
}

/// Bytes seen on the line, for `--monitor`: port 0 carries requests, port 1 responses; the
/// flag says the bytes are exactly one frame this program wrote (stamped when its last
/// character left), not a read that may hold part of one.
pub type MonitorChunk = (PortId, Timestamp, Vec<u8>, bool);

/// The port and what is known of it between requests.
struct Port<'a> {
    opts: &'a LineOptions,
    shared: &'a LineShared,
    monitor: Option<&'a mpsc::UnboundedSender<MonitorChunk>>,
    stream: Option<SerialStream>,
    backoff: Duration,
    next_open: Instant,
    watch: crate::source::serial::DeviceWatch,
    /// Since when the port has been said missing (None: open, or not tried yet).
    missing: Option<Instant>,
}

/// Runs the line forever.
pub async fn run(opts: LineOptions, shared: Arc<LineShared>, monitor: Option<mpsc::UnboundedSender<MonitorChunk>>) {
    let mut port = Port {
        opts: &opts,
        shared: &shared,
        monitor: monitor.as_ref(),
        stream: None,
        backoff: Duration::from_millis(100),
        next_open: Instant::now(),
        watch: crate::source::serial::DeviceWatch::default(),
        missing: None,
    };
    let mut master = opts.master();
    // The line is free for the next request from this time on (t3.5 + turnaround after the
    // last byte, Serial Line v1.02 §2.5.1.1).
    let mut free_at = Instant::now();
    let mut breakers: HashMap<u8, Breaker> = HashMap::new();
    loop {
        let Some((client, job)) = shared.next() else {
            // Wake on a new request, or now and then to retry opening the port.
            let _ = tokio::time::timeout(Duration::from_millis(500), shared.wake.notified()).await;
            if port.stream.is_none() && Instant::now() >= port.next_open {
                port.open();
            }
            continue;
        };
        if job.reply.is_closed() {
            // The client left while this request waited: no line time for it.
            shared.metrics.dropped();
            continue;
        }
        if port.stream.is_none() && Instant::now() >= port.next_open {
            port.reopen();
        }
        if port.stream.is_none() {
            answer(&shared, job, Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
            continue;
        }
        let breaker = breakers.entry(job.unit).or_default();
        if job.unit != 0 && breaker.refuses(shared.now()) {
            shared.metrics.circuit_open(job.unit);
            answer(&shared, job, Reply::Gateway(GATEWAY_TARGET_FAILED));
            continue;
        }
        wait_until(free_at).await;
        let on_line_from = Instant::now();
        let twins = shared.twins(client, &job);
        // A write may change what the cache holds, whatever its outcome.
        shared.cache().invalidate(job.unit, &job.pdu);
        let done = port.transact(&mut master, &job).await;
        let Ok(outcome) = done else {
            // The port failed under us: answer 0x0A and reopen with backoff.
            for twin in twins {
                let _ = twin.reply.send(Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
            }
            answer(&shared, job, Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
            continue;
        };
        let Outcome { reply, last, cacheable, flush } = outcome;
        let last = shared.instant(last);
        if let Reply::Pdu(pdu) = &reply
            && job.unit != 0
        {
            shared.metrics.response(job.unit, pdu);
            if cacheable {
                shared.cache().fill(job.unit, &job.pdu, pdu, shared.now());
            }
        }
        let class = match (client == POLL_CLIENT, job.high) {
            (true, _) => "poll",
            (false, true) => "high",
            (false, false) => "normal",
        };
        shared.metrics.line_time(class, last.saturating_duration_since(on_line_from));
        for twin in twins {
            shared.metrics.latency(twin.unit, twin.queued.elapsed());
            let _ = twin.reply.send(reply.clone());
        }
        if job.unit != 0 {
            let answered = reply != Reply::Gateway(GATEWAY_TARGET_FAILED);
            breakers.entry(job.unit).or_default().record(answered, shared.now());
        }
        let guard = master.config.line_guard();
        free_at = last + guard;
        shared.metrics.latency(job.unit, job.queued.elapsed());
        let unit = job.unit;
        answer(&shared, job, reply);
        // The client has its answer (or 0x0B); now what a slow unit says late is heard and
        // dropped before the next request goes out.
        if let Some(window) = flush
            && let Some(last) = port.flush_late(unit, window, &master.config).await
        {
            free_at = free_at.max(last + guard);
        }
    }
}

/// Hands `reply` to the job's client, counting a gateway exception.
fn answer(shared: &LineShared, job: Job, reply: Reply) {
    if let Reply::Gateway(code) = reply {
        shared.metrics.gateway_exception(job.unit, code);
    }
    let _ = job.reply.send(reply);
}

impl Port<'_> {
    /// Opens the port when due; backoff doubles while it stays away.
    fn reopen(&mut self) {
        self.open();
        if self.stream.is_some() {
            self.backoff = Duration::from_millis(100);
            self.shared.metrics.reopened();
        } else {
            self.next_open = Instant::now() + self.backoff;
            self.backoff = (self.backoff * 2).min(Duration::from_secs(5));
        }
    }

    /// The port failed under us: reopened later, with backoff.
    fn lost(&mut self, e: &std::io::Error) {
        self.shared.metrics.note(&format!("serial port lost: {e}; reopening"));
        self.stream = None;
        self.next_open = Instant::now() + self.backoff;
    }

    /// Opens the line's port (a by-id link or `usb:VID:PID[:SERIAL]` found again wherever the
    /// adapter came back), telling when the device behind the name changed.
    fn open(&mut self) {
        let opts = self.opts;
        let opened = (|| -> Result<SerialStream, String> {
            let path = crate::source::serial::resolve_port(&opts.port).map_err(|e| format!("{e:#}"))?;
            // Checked at start-up; a port that comes back must take the mode again.
            opts.rs485.prepare(&path).map_err(|e| format!("{e:#}"))?;
            let port =
                crate::source::serial::builder(&path, opts.line).open_native_async().map_err(|e| e.to_string())?;
            let _ = port.clear(tokio_serial::ClearBuffer::All);
            if let Some(said) = self.watch.opened(&opts.port, &path) {
                self.shared.metrics.note(&said);
            }
            Ok(port)
        })();
        match opened {
            Ok(port) => {
                if self.missing.take().is_some() {
                    self.shared.metrics.note(&format!("serial port {}: open; forwarding requests again", opts.port));
                }
                self.stream = Some(port);
            }
            Err(why) => {
                // Said at once and then once a minute while it lasts (issue 31: the bridge said
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

    /// Drives one request through the gateway core's transaction machine.
    async fn transact(&mut self, master: &mut SerialMaster, job: &Job) -> std::io::Result<Outcome> {
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
                    let _ = port.clear(tokio_serial::ClearBuffer::Input);
                    self.opts.rs485.send(port, &adu).await?;
                    self.observe_sent(&adu);
                    // With --rs485 rts the send returned when the last character left (tcdrain).
                    let drained = self.opts.rs485.rs485 == crate::source::rs485::Rs485Mode::Rts;
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
                Note::LateAnswer => m.late_answer(unit),
                Note::Heard { port, bytes } => self.observe(port, &bytes),
            }
        }
    }

    /// After a timeout: listens for what the unit says late and drops it; when the line was
    /// last busy (None: the port was lost meanwhile).
    async fn flush_late(&mut self, unit: u8, window: Duration, config: &MasterConfig) -> Option<Instant> {
        let shared = self.shared;
        let mut listener = LateListener::new(config, window, shared.now());
        let mut chunk = [0u8; 512];
        loop {
            let port = self.stream.as_mut()?;
            let read = tokio::time::timeout_at(shared.instant(listener.wait_until()), port.read(&mut chunk)).await;
            match read {
                Ok(Ok(0)) => {
                    self.lost(&std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the port closed"));
                    return None;
                }
                Ok(Ok(n)) => {
                    self.observe(1, chunk.get(..n).unwrap_or_default());
                    if listener.bytes(shared.now()) {
                        shared.metrics.late_answer(unit);
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
    fn observe(&self, port: u8, bytes: &[u8]) {
        if let Some(m) = self.monitor {
            let _ = m.send((PortId(port), crate::source::serial::now(), bytes.to_vec(), false));
        }
    }

    /// A frame this program wrote, stamped when its last character leaves the wire (the write
    /// returns as soon as the bytes are queued; stamping them then back-dated the request by
    /// its own transmission time, and the monitor saw a gap shorter than the line's).
    fn observe_sent(&self, bytes: &[u8]) {
        if let Some(m) = self.monitor {
            let on_wire = self.opts.line.char_ns().saturating_mul(bytes.len() as u64);
            let t = Timestamp(crate::source::serial::now().0.saturating_add(on_wire));
            let _ = m.send((PortId(0), t, bytes.to_vec(), true));
        }
    }
}

/// How often a port that stays missing is said again.
const MISSING_PORT_REMINDER: Duration = Duration::from_mins(1);

/// Sleeps until `at`: the timer for all but the last millisecond (its granularity), then
/// yields until the moment, so the line's quiet time is t3.5, not t3.5 rounded up to a tick.
async fn wait_until(at: Instant) {
    let coarse = at.checked_sub(Duration::from_millis(1)).unwrap_or(at);
    if Instant::now() < coarse {
        tokio::time::sleep_until(coarse).await;
    }
    while Instant::now() < at {
        tokio::task::yield_now().await;
    }
}
