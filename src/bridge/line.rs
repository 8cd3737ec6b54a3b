//! The serial master behind the bridge: one transaction at a time on the line, requests taken
//! in turn from the clients' queues ([`super::queue::FairQueue`]), each answer found by
//! [`super::response`] and handed back to its client alone. The port is reopened with backoff
//! when it goes away (a USB adapter pulled); meanwhile requests get exception 0x0A (Gateway
//! Path Unavailable, MAP v1.1b3 §7). The line task never exits on its own.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use tokio::io::AsyncReadExt;
use tokio::sync::{Notify, mpsc, oneshot};
use tokio::time::Instant;
use tokio_serial::{SerialPort, SerialPortBuilderExt, SerialStream};

use super::metrics::Metrics;
use super::queue::{ClientId, FairQueue, Full};
use mbtap_core::analyzer::SerialMode;
use mbtap_core::chunk::{PortId, Timestamp};
use mbtap_core::framer::LineSettings;
use mbtap_core::proto::answer_end::{Verdict, judge_ascii, judge_rtu};
use mbtap_core::proto::{encode_ascii, encode_rtu};

/// Exception 0x0A: the gateway has no path to the target (MAP v1.1b3 §7).
pub const GATEWAY_PATH_UNAVAILABLE: u8 = 0x0A;
/// Exception 0x0B: the target did not answer (MAP v1.1b3 §7).
pub const GATEWAY_TARGET_FAILED: u8 = 0x0B;
/// Exception 0x06: busy — the client's queue is full (MAP v1.1b3 §7).
pub const SERVER_DEVICE_BUSY: u8 = 0x06;

/// What a client gets back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// The slave's response PDU (normal or exception), unchanged.
    Pdu(Vec<u8>),
    /// An exception the gateway answers itself, with this code.
    Gateway(u8),
    /// Nothing to send (a broadcast, unless an immediate reply was asked for).
    Silence,
}

/// One request waiting for the line.
#[derive(Debug)]
pub struct Job {
    pub unit: u8,
    pub pdu: Vec<u8>,
    pub reply: oneshot::Sender<Reply>,
    pub queued: Instant,
    /// `--priority high=…` matched: goes before the round-robin (see `FairQueue::pop_prefer`).
    pub high: bool,
    /// A write's place among the writes not yet done: while it is held, the cache answers no
    /// read it may change (issue 24: a client pipelining "write h101, read h101" read the old
    /// value from the cache). Dropped with the job, however it ends.
    pub write: Option<WriteGuard>,
}

/// Writes queued or on the line, not yet done: (id, unit, request PDU).
type PendingWrites = Arc<Mutex<Vec<(u64, u8, Vec<u8>)>>>;

/// One write among [`PendingWrites`]; removed when dropped.
#[derive(Debug)]
pub struct WriteGuard {
    set: PendingWrites,
    id: u64,
}

impl Drop for WriteGuard {
    fn drop(&mut self) {
        self.set.lock().unwrap_or_else(PoisonError::into_inner).retain(|(id, ..)| *id != self.id);
    }
}

/// Line settings of the bridge.
#[derive(Debug, Clone)]
pub struct LineOptions {
    pub port: String,
    pub line: LineSettings,
    pub mode: SerialMode,
    /// Per-request response timeout (with `--timeout auto`, the ceiling).
    pub timeout: Duration,
    /// `--timeout fixed|auto`.
    pub timeout_mode: super::timing::TimeoutMode,
    /// `--unit-timeout`: units with a timeout of their own.
    pub unit_timeouts: std::collections::BTreeMap<u8, Duration>,
    /// `--echo`: whether the adapter hears its own transmission.
    pub echo: EchoMode,
    /// `--rs485`: transmitter direction control.
    pub rs485: crate::source::rs485::Rs485Args,
    /// `--cache` rules for this line's units.
    pub cache: Vec<super::cache::Rule>,
    /// `--poll`: ranges the bridge keeps fresh itself.
    pub polls: Vec<super::cache::Poll>,
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

/// Whether the adapter echoes what the bridge sends (an RS-485 transceiver whose receiver is
/// not disabled while it drives the line hears every byte it sends).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
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

/// The answer a request waits for: from whom, to which request, from when, how long.
#[derive(Debug, Clone, Copy)]
struct Awaited<'r> {
    unit: u8,
    function: u8,
    /// The request PDU: the answer must fit it ([`mbtap_core::proto::answer_fits`]).
    request: &'r [u8],
    /// When the request's last character left.
    sent: Instant,
    timeout: Duration,
}

/// What came back while the frame was expected as an echo.
enum Echo {
    /// The frame came back as sent; what followed it (the start of the answer).
    Clean(Vec<u8>),
    /// Something else came back: another driver on the line at the same time.
    Collision(Vec<u8>),
    /// Nothing (or too little) came back in time.
    Missing,
    /// `auto`, undecided: bytes that are not the frame — the adapter does not echo; they start
    /// the answer.
    Absent(Vec<u8>),
}

/// What the line task and the connections share.
#[derive(Debug)]
pub struct LineShared {
    queue: Mutex<FairQueue<Job>>,
    wake: Notify,
    pub metrics: Metrics,
    /// Answers from memory (`--cache`), filled and invalidated by the line, read by the
    /// connections before they queue.
    cache: Mutex<super::cache::Cache>,
    /// Writes not yet done: reads they may change are not answered from the cache.
    pending_writes: PendingWrites,
    next_write: std::sync::atomic::AtomicU64,
}

impl LineShared {
    #[must_use]
    pub fn new(per_client: usize, cache: Vec<super::cache::Rule>) -> Arc<Self> {
        Arc::new(Self {
            queue: Mutex::new(FairQueue::new(per_client)),
            wake: Notify::new(),
            metrics: Metrics::default(),
            cache: Mutex::new(super::cache::Cache::new(cache)),
            pending_writes: PendingWrites::default(),
            next_write: std::sync::atomic::AtomicU64::new(0),
        })
    }

    /// Registers a write to `unit` before it is queued (none for a request that writes
    /// nothing the cache holds); the job carries the guard.
    pub fn write_pending(&self, unit: u8, pdu: &[u8]) -> Option<WriteGuard> {
        super::cache::written_range(pdu)?;
        let id = self.next_write.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.pending_writes.lock().unwrap_or_else(PoisonError::into_inner).push((id, unit, pdu.to_vec()));
        Some(WriteGuard { set: Arc::clone(&self.pending_writes), id })
    }

    /// Whether a write not yet done may change what `pdu` reads from `unit`.
    fn read_behind_write(&self, unit: u8, pdu: &[u8]) -> bool {
        self.pending_writes
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .any(|(_, u, w)| super::cache::read_overlaps_write(unit, pdu, *u, w))
    }

    fn cache(&self) -> std::sync::MutexGuard<'_, super::cache::Cache> {
        self.cache.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The answer from the cache, when `--cache` covers the read and it is fresh (counted as a
    /// hit; a covered read that must go to the line as a miss).
    pub fn cached(&self, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        let cache = self.cache();
        if !cache.is_on() {
            return None;
        }
        // A read queued behind a write it overlaps waits for the write (read your own write).
        let answer =
            if self.read_behind_write(unit, pdu) { None } else { cache.lookup(unit, pdu, Instant::now().into_std()) };
        drop(cache);
        self.metrics.cache(answer.is_some());
        answer
    }

    /// Identical reads other clients have waiting at the head of their queues: they share this
    /// one's answer (coalescing; reads only — a write twice is two writes).
    fn twins(&self, client: ClientId, job: &Job) -> Vec<Job> {
        if job.unit == 0 || !matches!(job.pdu.first(), Some(0x01..=0x04)) {
            return Vec::new();
        }
        let twins: Vec<Job> = self
            .queue()
            .take_heads(client, |j| j.unit == job.unit && j.pdu == job.pdu)
            .into_iter()
            .map(|(_, j)| j)
            .collect();
        if !twins.is_empty() {
            self.metrics.coalesced(twins.len());
        }
        twins
    }

    fn queue(&self) -> std::sync::MutexGuard<'_, FairQueue<Job>> {
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Queues a request for the line.
    ///
    /// # Errors
    /// [`Full`] when the client has too many requests waiting.
    pub fn submit(&self, client: ClientId, job: Job) -> Result<(), Full> {
        let depth = {
            let mut q = self.queue();
            q.push(client, job)?;
            q.len()
        };
        self.metrics.queue_depth(depth);
        self.wake.notify_one();
        Ok(())
    }

    /// The client left: its requests that have not started are dropped.
    pub fn forget(&self, client: ClientId) -> usize {
        self.queue().remove_client(client)
    }

    fn next(&self) -> Option<(ClientId, Job)> {
        let mut q = self.queue();
        // The priority class first, unless the others were passed over three times in a row.
        let job = q.pop_prefer(|j| j.high, 4);
        self.metrics.queue_depth(q.len());
        job
    }
}

/// The queue's client id of the bridge's own polls (`--poll`): it takes its turn like any
/// client, so polling never starves the clients' requests.
pub const POLL_CLIENT: ClientId = ClientId::MAX;

/// Agent mode: reads every `--poll` range once per its interval, the requests spread evenly over
/// the interval so they leave line time between them; the answers fill the cache (the line
/// does that for every answer). Runs as long as the bridge.
pub async fn poll(polls: Vec<super::cache::Poll>, shared: Arc<LineShared>) {
    let mut jobs: Vec<(Duration, u8, Vec<u8>)> = Vec::new();
    for p in &polls {
        for &unit in &p.rule.units {
            for pdu in p.requests() {
                jobs.push((p.interval, unit, pdu));
            }
        }
    }
    if jobs.is_empty() {
        return;
    }
    let start = Instant::now();
    let n = u32::try_from(jobs.len()).unwrap_or(u32::MAX);
    let mut tasks = Vec::new();
    for (i, (interval, unit, pdu)) in jobs.into_iter().enumerate() {
        let shared = Arc::clone(&shared);
        // Job i of n starts i/n of its interval in.
        let offset = interval / n * u32::try_from(i).unwrap_or(0);
        tasks.push(tokio::spawn(async move {
            let mut tick = tokio::time::interval_at(start + offset, interval);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tick.tick().await;
                let (tx, rx) = oneshot::channel();
                let job = Job { unit, pdu: pdu.clone(), reply: tx, queued: Instant::now(), high: false, write: None };
                if shared.submit(POLL_CLIENT, job).is_ok() {
                    // Waiting keeps one poll of this range in the queue at a time.
                    let _ = rx.await;
                }
            }
        }));
    }
    for t in tasks {
        let _ = t.await;
    }
}

/// Bytes seen on the line, for `--monitor`: port 0 carries requests, port 1 responses; the
/// flag says the bytes are exactly one frame this program wrote (stamped when its last
/// character left), not a read that may hold part of one.
pub type MonitorChunk = (PortId, Timestamp, Vec<u8>, bool);

/// A unit that failed to answer this many requests in a row gets its circuit breaker opened.
const BREAK_AFTER: u32 = 3;
/// How long an open breaker answers 0x0B at once before one probe request goes through;
/// doubled after each failed probe, up to [`BREAKER_MAX`].
const BREAKER_START: Duration = Duration::from_secs(2);
const BREAKER_MAX: Duration = Duration::from_secs(30);

/// Per unit: a dead unit must not cost every client its timeout of line time. After
/// [`BREAK_AFTER`] consecutive failures its requests are answered 0x0B (Gateway Target Device
/// Failed to Respond, MAP v1.1b3 §7) at once until `open_until`; then one request probes it.
#[derive(Debug, Default)]
struct Breaker {
    failures: u32,
    open_until: Option<Instant>,
    backoff: Duration,
}

impl Breaker {
    /// Should this request be answered 0x0B without using the line?
    fn refuses(&self, now: Instant) -> bool {
        self.open_until.is_some_and(|until| now < until)
    }

    /// The outcome of a request that went to the unit.
    fn record(&mut self, answered: bool, now: Instant) {
        if answered {
            *self = Self::default();
            return;
        }
        self.failures = self.failures.saturating_add(1);
        if self.failures >= BREAK_AFTER {
            // A failed probe doubles the wait; the first opening starts it.
            self.backoff = if self.open_until.is_some() { (self.backoff * 2).min(BREAKER_MAX) } else { BREAKER_START };
            self.open_until = Some(now + self.backoff);
        }
    }
}

/// Runs the line forever.
pub async fn run(opts: LineOptions, shared: Arc<LineShared>, monitor: Option<mpsc::UnboundedSender<MonitorChunk>>) {
    let mut port: Option<SerialStream> = None;
    let mut backoff = Duration::from_millis(100);
    let mut next_open = Instant::now();
    // The line is free for the next request from this time on (t3.5 + turnaround after the
    // last byte, Serial Line v1.02 §2.5.1.1).
    let mut free_at = Instant::now();
    let timeouts = super::timing::Timeouts::new(opts.timeout, opts.timeout_mode, opts.unit_timeouts.clone());
    let mut master = Master {
        opts: &opts,
        shared: &shared,
        monitor: monitor.as_ref(),
        buf: Vec::with_capacity(600),
        timeouts,
        echo_found: None,
        suspect: std::collections::HashSet::new(),
        flush_after: None,
    };
    let mut breakers: std::collections::HashMap<u8, Breaker> = std::collections::HashMap::new();
    let mut watch = crate::source::serial::DeviceWatch::default();
    // Since when the port has been said missing (None: open, or not tried yet).
    let mut missing: Option<Instant> = None;
    loop {
        let Some((client, job)) = shared.next() else {
            // Wake on a new request, or now and then to retry opening the port.
            let _ = tokio::time::timeout(Duration::from_millis(500), shared.wake.notified()).await;
            if port.is_none() && Instant::now() >= next_open {
                port = open(&opts, &shared, &mut watch, &mut missing);
            }
            continue;
        };
        if job.reply.is_closed() {
            // The client left while this request waited: no line time for it.
            shared.metrics.dropped();
            continue;
        }
        if port.is_none() && Instant::now() >= next_open {
            port = open(&opts, &shared, &mut watch, &mut missing);
            if port.is_some() {
                backoff = Duration::from_millis(100);
                shared.metrics.reopened();
            } else {
                next_open = Instant::now() + backoff;
                backoff = (backoff * 2).min(Duration::from_secs(5));
            }
        }
        let Some(p) = port.as_mut() else {
            shared.metrics.gateway_exception(job.unit, GATEWAY_PATH_UNAVAILABLE);
            let _ = job.reply.send(Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
            continue;
        };
        let breaker = breakers.entry(job.unit).or_default();
        if job.unit != 0 && breaker.refuses(Instant::now()) {
            shared.metrics.circuit_open(job.unit);
            shared.metrics.gateway_exception(job.unit, GATEWAY_TARGET_FAILED);
            let _ = job.reply.send(Reply::Gateway(GATEWAY_TARGET_FAILED));
            continue;
        }
        wait_until(free_at).await;
        let on_line_from = Instant::now();
        let twins = shared.twins(client, &job);
        // A write may change what the cache holds, whatever its outcome.
        shared.cache().invalidate(job.unit, &job.pdu);
        let was_suspect = master.suspect.remove(&job.unit);
        match master.transact(p, &job).await {
            Ok((reply, last_byte)) => {
                if let Reply::Pdu(answer) = &reply
                    && !was_suspect
                    && !master.suspect.contains(&job.unit)
                {
                    shared.cache().fill(job.unit, &job.pdu, answer, Instant::now().into_std());
                }
                let class = if client == POLL_CLIENT {
                    "poll"
                } else if job.high {
                    "high"
                } else {
                    "normal"
                };
                shared.metrics.line_time(class, last_byte.saturating_duration_since(on_line_from));
                for twin in twins {
                    shared.metrics.latency(twin.unit, twin.queued.elapsed());
                    let _ = twin.reply.send(reply.clone());
                }
                if job.unit != 0 {
                    let answered = !matches!(reply, Reply::Gateway(GATEWAY_TARGET_FAILED));
                    breakers.entry(job.unit).or_default().record(answered, Instant::now());
                }
                free_at = last_byte + opts.line_guard();
                shared.metrics.latency(job.unit, job.queued.elapsed());
                let _ = job.reply.send(reply);
                // The client has its answer (or 0x0B); now what a slow unit says late is heard
                // and dropped before the next request goes out.
                if let Some((unit, window)) = master.flush_after.take() {
                    match master.flush_late(p, unit, window).await {
                        Ok(last) => free_at = free_at.max(last + opts.line_guard()),
                        Err(lost) => {
                            shared.metrics.port_lost(&lost);
                            port = None;
                            next_open = Instant::now() + backoff;
                        }
                    }
                }
            }
            Err(lost) => {
                for twin in twins {
                    let _ = twin.reply.send(Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
                }
                // The port failed under us: answer 0x0A and reopen with backoff.
                shared.metrics.port_lost(&lost);
                shared.metrics.gateway_exception(job.unit, GATEWAY_PATH_UNAVAILABLE);
                let _ = job.reply.send(Reply::Gateway(GATEWAY_PATH_UNAVAILABLE));
                port = None;
                next_open = Instant::now() + backoff;
            }
        }
    }
}

impl LineOptions {
    /// Quiet time after the last byte before the next request: t3.5 plus the turnaround.
    fn line_guard(&self) -> Duration {
        Duration::from_nanos(self.line.t35_ns()) + self.turnaround
    }

    fn char_time(&self) -> Duration {
        Duration::from_nanos(self.line.char_ns())
    }
}

/// Opens the line's port (a by-id link or `usb:VID:PID[:SERIAL]` found again wherever the
/// adapter came back), telling when the device behind the name changed.
fn open(
    opts: &LineOptions,
    shared: &LineShared,
    watch: &mut crate::source::serial::DeviceWatch,
    missing: &mut Option<Instant>,
) -> Option<SerialStream> {
    let opened = (|| -> Result<SerialStream, String> {
        let path = crate::source::serial::resolve_port(&opts.port).map_err(|e| format!("{e:#}"))?;
        // Checked at start-up; a port that comes back must take the mode again.
        opts.rs485.prepare(&path).map_err(|e| format!("{e:#}"))?;
        let port = crate::source::serial::builder(&path, opts.line).open_native_async().map_err(|e| e.to_string())?;
        let _ = port.clear(tokio_serial::ClearBuffer::All);
        if let Some(said) = watch.opened(&opts.port, &path) {
            shared.metrics.note(&said);
        }
        Ok(port)
    })();
    match opened {
        Ok(port) => {
            if missing.take().is_some() {
                shared.metrics.note(&format!("serial port {}: open; forwarding requests again", opts.port));
            }
            Some(port)
        }
        Err(why) => {
            // Said at once and then once a minute while it lasts (issue 31: the bridge said only
            // "listening" and every client got 0x0A with no word why).
            if missing.is_none_or(|said| said.elapsed() >= MISSING_PORT_REMINDER) {
                *missing = Some(Instant::now());
                shared.metrics.note(&format!(
                    "serial port {}: cannot open it ({why}); clients get exception 0x0A (gateway path unavailable) until it opens; trying again every few seconds",
                    opts.port
                ));
            }
            None
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

struct Master<'a> {
    opts: &'a LineOptions,
    shared: &'a LineShared,
    monitor: Option<&'a mpsc::UnboundedSender<MonitorChunk>>,
    buf: Vec<u8>,
    timeouts: super::timing::Timeouts,
    /// With `--echo auto`: what the first telling request found.
    echo_found: Option<bool>,
    /// Units that timed out: their next answer is passed on but not cached (it may still be a
    /// late one whose shape matched).
    suspect: std::collections::HashSet<u8>,
    /// After a timeout: the unit, and how long to listen for its late answer once the client
    /// has been answered.
    flush_after: Option<(u8, Duration)>,
}

impl Master<'_> {
    /// Bytes read from the line, stamped when the read returned.
    fn observe(&self, port: u8, bytes: &[u8]) {
        if let Some(m) = self.monitor {
            let _ = m.send((PortId(port), crate::source::serial::now(), bytes.to_vec(), false));
        }
    }

    /// A frame this program wrote, stamped when its last character leaves the wire (the write
    /// returns as soon as the bytes are queued; stamping them then back-dated the request by
    /// its own transmission time, and the monitor saw a gap shorter than the line's).
    fn observe_sent(&self, port: u8, bytes: &[u8]) {
        if let Some(m) = self.monitor {
            let on_wire = self.opts.line.char_ns().saturating_mul(bytes.len() as u64);
            let t = Timestamp(crate::source::serial::now().0.saturating_add(on_wire));
            let _ = m.send((PortId(port), t, bytes.to_vec(), true));
        }
    }

    /// One request with its retries; the reply and when the line last carried a byte.
    async fn transact(&mut self, port: &mut SerialStream, job: &Job) -> std::io::Result<(Reply, Instant)> {
        let mut adu = Vec::with_capacity(job.pdu.len() * 2 + 5);
        match self.opts.mode {
            SerialMode::Rtu => encode_rtu(job.unit, &job.pdu, &mut adu),
            SerialMode::Ascii => encode_ascii(job.unit, &job.pdu, &mut adu),
        }
        let function = job.pdu.first().copied().unwrap_or(0);
        let mut attempt = 0;
        loop {
            attempt += 1;
            self.shared.metrics.request(job.unit);
            // Stale bytes (a late answer to an earlier request, noise) must not be taken for
            // this request's answer.
            let _ = port.clear(tokio_serial::ClearBuffer::Input);
            self.opts.rs485.send(port, &adu).await?;
            self.observe_sent(0, &adu);
            // The request is on the wire when its last character has left (with --rs485 rts
            // the send returned then: tcdrain).
            let sent = if self.opts.rs485.rs485 == crate::source::rs485::Rs485Mode::Rts {
                Instant::now()
            } else {
                Instant::now() + self.opts.char_time() * u32::try_from(adu.len()).unwrap_or(u32::MAX)
            };
            if job.unit == 0 {
                // Broadcast (Serial Line v1.02 §2.1): no answer; the turnaround delay follows.
                let reply = if self.opts.broadcast_reply { echo_reply(&job.pdu) } else { Reply::Silence };
                return Ok((reply, sent + self.opts.turnaround));
            }
            let timeout = self.timeouts.get(job.unit);
            self.shared.metrics.unit_timeout(job.unit, timeout);
            let awaited = Awaited { unit: job.unit, function, sent, timeout, request: &job.pdu };
            let initial = match self.echo_expected(function) {
                None => Vec::new(),
                Some(decided) => match self.consume_echo(port, &adu, sent + timeout, decided).await? {
                    Echo::Clean(rest) => {
                        if self.echo_found.is_none() && self.opts.echo == EchoMode::Auto {
                            self.echo_found = Some(true);
                            self.shared
                                .metrics
                                .note(&format!("{}: the adapter echoes what is sent (--echo auto)", self.opts.port));
                        }
                        rest
                    }
                    Echo::Absent(bytes) => {
                        self.echo_found = Some(false);
                        bytes
                    }
                    Echo::Collision(heard) => {
                        // Not the frame: either no echo at all and this is the answer (the
                        // adapter does not echo: counted, the answer used), or a collision.
                        let (answer, last) = self.read_answer(port, awaited, heard.clone(), true).await?;
                        if let Some(pdu) = answer {
                            self.shared.metrics.echo_missing(job.unit);
                            self.timeouts.answered(job.unit, last.saturating_duration_since(sent));
                            self.shared.metrics.response(job.unit, &pdu);
                            return Ok((Reply::Pdu(pdu), last));
                        }
                        // The monitor sees what was really on the line in place of the request.
                        self.observe(0, &heard);
                        self.shared.metrics.collision(job.unit);
                        if attempt <= self.opts.retries {
                            wait_until(last + self.opts.line_guard()).await;
                            continue;
                        }
                        self.shared.metrics.gateway_exception(job.unit, GATEWAY_TARGET_FAILED);
                        return Ok((Reply::Gateway(GATEWAY_TARGET_FAILED), last));
                    }
                    Echo::Missing => {
                        self.shared.metrics.echo_missing(job.unit);
                        self.timeouts.timed_out(job.unit);
                        self.shared.metrics.waited_in_vain(job.unit, timeout);
                        let last = Instant::now();
                        if attempt <= self.opts.retries {
                            wait_until(last + self.opts.line_guard()).await;
                            continue;
                        }
                        self.shared.metrics.gateway_exception(job.unit, GATEWAY_TARGET_FAILED);
                        return Ok((Reply::Gateway(GATEWAY_TARGET_FAILED), last));
                    }
                },
            };
            let outcome = self.read_answer(port, awaited, initial, false).await?;
            match &outcome {
                (Some(_), last) => self.timeouts.answered(job.unit, last.saturating_duration_since(sent)),
                (None, last) if last.saturating_duration_since(sent) >= timeout => {
                    self.timeouts.timed_out(job.unit);
                    self.shared.metrics.waited_in_vain(job.unit, timeout);
                    // A unit slower than the timeout answers later: that answer must reach no
                    // one (issue 24: the answer to h150 went to the client asking h160). The
                    // line is listened to once this client has its 0x0B (a retry of the same
                    // request may take the late answer: it is that request's).
                    self.suspect.insert(job.unit);
                    self.flush_after = Some((job.unit, timeout));
                }
                (None, _) => {}
            }
            let retry = attempt <= self.opts.retries;
            match outcome {
                (Some(pdu), last) => {
                    self.shared.metrics.response(job.unit, &pdu);
                    return Ok((Reply::Pdu(pdu), last));
                }
                (None, last) if !retry => {
                    self.shared.metrics.gateway_exception(job.unit, GATEWAY_TARGET_FAILED);
                    return Ok((Reply::Gateway(GATEWAY_TARGET_FAILED), last));
                }
                (None, last) => wait_until(last + self.opts.line_guard()).await,
            }
        }
    }

    /// After a timeout: listens up to `window` (at most 1 s) for what the unit says late and
    /// drops it, ending at the silence after the last late byte; when the line was last busy.
    async fn flush_late(&mut self, port: &mut SerialStream, unit: u8, window: Duration) -> std::io::Result<Instant> {
        let start = Instant::now();
        let until = start + window.min(Duration::from_secs(1));
        // Noise that never stops cannot hold the line longer than twice the window.
        let hard_stop = until + window.min(Duration::from_secs(1));
        let silence = Duration::from_nanos(self.opts.line.t35_ns()) + Duration::from_millis(1) + self.opts.latency;
        let mut last = None;
        let mut chunk = [0u8; 512];
        loop {
            let quiet_until = last.map_or(until, |t: Instant| (t + silence).min(hard_stop));
            match tokio::time::timeout_at(quiet_until, port.read(&mut chunk)).await {
                Ok(Ok(0)) => return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the port closed")),
                Ok(Ok(n)) => {
                    self.observe(1, chunk.get(..n).unwrap_or_default());
                    if last.is_none() {
                        self.shared.metrics.late_answer(unit);
                    }
                    last = Some(Instant::now());
                }
                Ok(Err(e)) if e.kind() == std::io::ErrorKind::TimedOut => break,
                Ok(Err(e)) => return Err(e),
                Err(_) => break,
            }
        }
        Ok(last.unwrap_or(start))
    }

    /// Whether to read the frame back before the answer: `Some(true)` when the adapter is known
    /// to echo, `Some(false)` to find out (`auto`, first telling request), `None` not to.
    fn echo_expected(&self, function: u8) -> Option<bool> {
        match (self.opts.echo, self.echo_found) {
            (EchoMode::Off, _) | (EchoMode::Auto, Some(false)) => None,
            (EchoMode::On, _) | (EchoMode::Auto, Some(true)) => Some(true),
            // 05, 06 and 08 answer with the request itself: an echo and an answer look alike.
            (EchoMode::Auto, None) if matches!(function, 0x05 | 0x06 | 0x08) => None,
            (EchoMode::Auto, None) => Some(false),
        }
    }

    /// Reads back the frame just sent. `decided`: the adapter is known to echo (a difference is
    /// a collision); otherwise bytes that differ from the frame mean there is no echo.
    async fn consume_echo(
        &mut self,
        port: &mut SerialStream,
        adu: &[u8],
        deadline: Instant,
        decided: bool,
    ) -> std::io::Result<Echo> {
        let mut heard: Vec<u8> = Vec::with_capacity(adu.len() + 64);
        let mut chunk = [0u8; 512];
        while heard.len() < adu.len() {
            match tokio::time::timeout_at(deadline, port.read(&mut chunk)).await {
                Ok(Ok(0)) => return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the port closed")),
                Ok(Ok(n)) => heard.extend_from_slice(chunk.get(..n).unwrap_or_default()),
                Ok(Err(e)) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Ok(Err(e)) => return Err(e),
                Err(_) => break,
            }
            let n = heard.len().min(adu.len());
            if !decided && heard.get(..n) != adu.get(..n) {
                return Ok(Echo::Absent(heard));
            }
        }
        if heard.len() < adu.len() {
            // An echoing adapter gives the frame back whether or not the unit answers: undecided,
            // silence means no echo.
            return Ok(match (decided, heard.is_empty()) {
                (true, true) => Echo::Missing,
                (true, false) => Echo::Collision(heard),
                (false, _) => Echo::Absent(heard),
            });
        }
        // Everything heard goes on: after a clean echo, what followed it; else all of it.
        Ok(if heard.get(..adu.len()) == Some(adu) {
            Echo::Clean(heard.split_off(adu.len()))
        } else {
            Echo::Collision(heard)
        })
    }

    /// Reads until an answer, a failed check or the timeout; the answer's PDU (or none) and
    /// the time of the last byte. `initial`: bytes already read that start the answer.
    async fn read_answer(
        &mut self,
        port: &mut SerialStream,
        wait: Awaited<'_>,
        initial: Vec<u8>,
        strict_start: bool,
    ) -> std::io::Result<(Option<Vec<u8>>, Instant)> {
        let Awaited { unit, function, sent, timeout, request } = wait;
        let deadline = sent + timeout;
        // RTU: t3.5 of silence ends a frame; ASCII: the 1 s inter-character timeout (Serial
        // Line v1.02 §2.5.2.1). Plus one timer tick, as reads come in 1 ms steps.
        let silence = match self.opts.mode {
            SerialMode::Rtu => {
                Duration::from_nanos(self.opts.line.t35_ns()) + Duration::from_millis(1) + self.opts.latency
            }
            SerialMode::Ascii => Duration::from_secs(1),
        };
        self.buf.clear();
        let mut last = sent;
        if !initial.is_empty() {
            self.observe(1, &initial);
            self.buf.extend_from_slice(&initial);
            last = Instant::now();
        }
        let mut chunk = [0u8; 512];
        // Bytes already in hand are judged before waiting for more: the answer may be whole
        // (issue 25: an ASCII answer that came in place of an echo waited for the 1 s silence).
        let mut judge_now = !self.buf.is_empty();
        loop {
            let silent = if std::mem::take(&mut judge_now) {
                false
            } else {
                let now = Instant::now();
                if now >= deadline {
                    if !self.buf.is_empty() {
                        self.shared.metrics.crc_error(unit);
                    }
                    self.shared.metrics.timeout(unit);
                    return Ok((None, last.max(now)));
                }
                let quiet_until = if self.buf.is_empty() { deadline } else { (last + silence).min(deadline) };
                match tokio::time::timeout_at(quiet_until, port.read(&mut chunk)).await {
                    Ok(Ok(0)) => {
                        return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the port closed"));
                    }
                    Ok(Ok(n)) => {
                        let got = chunk.get(..n).unwrap_or_default();
                        self.observe(1, got);
                        self.buf.extend_from_slice(got);
                        last = Instant::now();
                        false
                    }
                    Ok(Err(e)) if e.kind() == std::io::ErrorKind::TimedOut => !self.buf.is_empty(),
                    Ok(Err(e)) => return Err(e),
                    Err(_) => !self.buf.is_empty(),
                }
            };
            if self.opts.mode == SerialMode::Rtu && turnaround_glitch(&self.buf, unit) {
                // A transceiver's turnaround glitch before the answer (00, FE or FF): dropped,
                // as `read` and the sniffer do (issue 24: the bridge answered 0x0B).
                self.buf.remove(0);
            }
            let verdict = match self.opts.mode {
                SerialMode::Rtu => judge_rtu(&self.buf, unit, function, silent),
                SerialMode::Ascii => judge_ascii(&self.buf, unit, silent),
            };
            match verdict {
                Verdict::Pending => {}
                Verdict::Answer { len } => {
                    let frame = self.buf.get(..len).unwrap_or_default();
                    let pdu = match self.opts.mode {
                        SerialMode::Rtu => frame.get(1..len.saturating_sub(2)).map(<[u8]>::to_vec),
                        SerialMode::Ascii => {
                            let start = frame.iter().position(|&b| b == b':').unwrap_or(0);
                            mbtap_core::proto::parse_ascii(frame.get(start..).unwrap_or_default())
                                .ok()
                                .map(|f| f.pdu().to_vec())
                        }
                    };
                    if let Some(p) = &pdu
                        && !mbtap_core::proto::answer_fits(request, p)
                    {
                        // Another request's answer (a late one after a timeout: another
                        // quantity, address or function): never this client's. Dropped, counted;
                        // the real answer may follow it.
                        self.shared.metrics.late_answer(unit);
                        self.buf.drain(..len);
                        judge_now = !self.buf.is_empty();
                        continue;
                    }
                    return Ok((pdu, last));
                }
                Verdict::BadCheck => {
                    self.shared.metrics.crc_error(unit);
                    return Ok((None, last));
                }
                // `strict_start`: the answer must begin with the first byte (what came in place
                // of an echo is judged whole: anything else is a collision).
                Verdict::Foreign if strict_start => return Ok((None, last)),
                Verdict::Foreign => self.buf.clear(),
            }
        }
    }
}

/// Whether `buf` starts with a turnaround glitch before the awaited unit's answer: a byte a
/// transceiver leaves when it switches (00, FE, FF), not the unit's address, followed by it.
fn turnaround_glitch(buf: &[u8], unit: u8) -> bool {
    matches!(buf, [g @ (0x00 | 0xFE | 0xFF), u, ..] if *g != unit && *u == unit)
}

/// The normal response a write would get, for `--broadcast-reply`: 05/06 echo the request,
/// 0F/10 answer address and quantity (MAP v1.1b3 §6.5, §6.6, §6.11, §6.12).
fn echo_reply(pdu: &[u8]) -> Reply {
    match pdu.first() {
        Some(0x05 | 0x06 | 0x0F | 0x10) if pdu.len() >= 5 => Reply::Pdu(pdu.get(..5).unwrap_or_default().to_vec()),
        _ => Reply::Silence,
    }
}

impl Metrics {
    fn port_lost(&self, e: &std::io::Error) {
        self.note(&format!("serial port lost: {e}; reopening"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 24: an answer preceded by a transceiver's turnaround glitch (FE) was judged
    /// foreign and the client got 0x0B, where `read` tolerated it.
    #[test]
    fn a_turnaround_glitch_before_the_answer_is_set_aside() {
        // FE glitch, then unit 1's answer: 01 03 02 00 2A + CRC.
        let answer = [0xFE, 0x01, 0x03, 0x02, 0x00, 0x2A, 0x39, 0x9B];
        assert!(turnaround_glitch(&answer, 1));
        assert!(turnaround_glitch(&[0x00, 0x11, 0x03], 0x11));
        assert!(turnaround_glitch(&[0xFF, 0x05], 5));
        assert!(!turnaround_glitch(&answer[1..], 1), "no glitch: the answer itself");
        assert!(!turnaround_glitch(&[0xFE, 0x02, 0x03], 1), "another unit's frame is no glitch of ours");
        assert!(!turnaround_glitch(&[0xFE, 0xFE, 0x03], 0xFE), "unit 254's own address");
        assert!(!turnaround_glitch(&[0x07, 0x01], 1), "not a value a driver leaves");
    }

    /// Issue 15: eight clients polling a dead unit cost the line a timeout each; a good unit's
    /// client got 3 answers in 8. The breaker opens after three failures, probes once per
    /// backoff (doubling to 30 s), and closes on the first answer.
    #[test]
    fn a_dead_unit_is_answered_at_once_between_probes() {
        let t0 = Instant::now();
        let mut b = Breaker::default();
        for i in 0..BREAK_AFTER {
            assert!(!b.refuses(t0), "failure {i}: still tried");
            b.record(false, t0);
        }
        assert!(b.refuses(t0 + Duration::from_millis(1)));
        assert!(b.refuses(t0 + BREAKER_START - Duration::from_millis(1)));
        // The probe goes through, fails: twice as long now.
        let probe = t0 + BREAKER_START;
        assert!(!b.refuses(probe));
        b.record(false, probe);
        assert!(b.refuses(probe + BREAKER_START * 2 - Duration::from_millis(1)));
        assert!(!b.refuses(probe + BREAKER_START * 2));
        // Never longer than the cap.
        for _ in 0..10 {
            b.record(false, probe);
        }
        assert_eq!(b.backoff, BREAKER_MAX);
        // An answer closes it.
        b.record(true, probe);
        assert!(!b.refuses(probe));
        assert_eq!(b.failures, 0);
    }
}
