//! What the line task and the client connections share for one serial line: the fair queue
//! (`mbtap_gateway::queue`), the cache (`mbtap_gateway::cache`), the writes not yet done and
//! the metrics, behind locks; and the bridge's own polls (agent mode). The decisions are the
//! gateway core's; this holds them for tasks that run at once.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use tokio::sync::{Notify, oneshot};
use tokio::time::Instant;

use super::metrics::Metrics;
use mbtap_gateway::cache::{Cache, Poll, Rule, WriteId};
use mbtap_gateway::queue::{ClientId, FairQueue, Full};
use mbtap_gateway::transaction::Reply;

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
    /// read it may change (a client pipelining "write h101, read h101" read the old
    /// value from the cache). Dropped with the job, however it ends.
    pub write: Option<WriteGuard>,
    /// `--audit`: the record of a request that may change a device, written when it ends.
    pub audit: Option<Ticket>,
}

/// What the audit writes of a job when it ends: who asked, what it changes.
#[derive(Debug)]
pub struct Ticket {
    pub audit: Arc<crate::output::audit::Audit>,
    pub who: crate::output::audit::Who,
    pub change: mbtap_gateway::audit::Change,
}

impl Job {
    /// Records the job's ending in the audit, if it is one the audit keeps.
    pub fn audited(&mut self, outcome: &str) {
        if let Some(t) = self.audit.take() {
            t.audit.record(&t.who, self.unit, &t.change, outcome);
        }
    }
}

/// A write's place among the cache's writes not yet done; ended when dropped, however the
/// job ends (answered, failed, dropped unsent).
#[derive(Debug)]
pub struct WriteGuard {
    line: std::sync::Weak<LineShared>,
    id: WriteId,
}

impl Drop for WriteGuard {
    fn drop(&mut self) {
        if let Some(line) = self.line.upgrade() {
            line.cache().write_ends(self.id);
        }
    }
}

/// What the line task and the connections share.
#[derive(Debug)]
pub struct LineShared {
    queue: Mutex<FairQueue<Job>>,
    pub(super) wake: Notify,
    pub metrics: Metrics,
    /// Answers from memory (`--cache`), filled and invalidated by the line, read by the
    /// connections before they queue; it keeps the writes not yet done.
    cache: Mutex<Cache>,
    /// The gateway core's time zero: its clock is the time since.
    origin: Instant,
}

impl LineShared {
    /// `per_client` requests may wait per client, `total` for all clients together.
    #[must_use]
    pub fn new(per_client: usize, total: usize, cache: Vec<Rule>) -> Arc<Self> {
        Arc::new(Self {
            queue: Mutex::new(FairQueue::bounded(per_client, total)),
            wake: Notify::new(),
            metrics: Metrics::default(),
            cache: Mutex::new(Cache::new(cache)),
            origin: Instant::now(),
        })
    }

    /// The gateway core's clock: time since this line was set up.
    pub fn now(&self) -> Duration {
        self.origin.elapsed()
    }

    /// The instant of a time on the gateway core's clock.
    pub fn instant(&self, at: Duration) -> Instant {
        self.origin + at
    }

    /// An instant as a time on the gateway core's clock (0 for one before its origin).
    pub fn since_start(&self, at: Instant) -> Duration {
        at.saturating_duration_since(self.origin)
    }

    /// Registers a write to `unit` before it is queued (none for a request that writes
    /// nothing the cache holds, or without a cache); the job carries the guard.
    pub fn write_pending(self: &Arc<Self>, unit: u8, pdu: &[u8]) -> Option<WriteGuard> {
        let id = self.cache().write_begins(unit, pdu)?;
        Some(WriteGuard { line: Arc::downgrade(self), id })
    }

    pub(super) fn cache(&self) -> std::sync::MutexGuard<'_, Cache> {
        self.cache.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The answer from the cache, when `--cache` covers the read and it is fresh (counted as a
    /// hit; a covered read that must go to the line as a miss).
    pub fn cached(&self, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        let cache = self.cache();
        if !cache.is_on() {
            return None;
        }
        let answer = cache.lookup(unit, pdu, self.now());
        drop(cache);
        self.metrics.cache(answer.is_some());
        answer
    }

    /// Identical reads other clients have waiting at the head of their queues: they share this
    /// one's answer (coalescing; reads only — a write twice is two writes).
    pub(super) fn twins(&self, client: ClientId, job: &Job) -> Vec<Job> {
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
    /// [`Full`] when the client, or the line, has too many requests waiting.
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

    /// Whether the next request could take `unit`'s late answer for its own: one of `unit`'s
    /// own is waiting, or nothing is (then the next to arrive decides).
    pub(super) fn may_take_late_answer(&self, unit: u8) -> bool {
        let q = self.queue();
        // A request its client gave up on (its reply closed) never reaches the line: not counted.
        let live = |j: &Job| !j.reply.is_closed();
        !q.any(live) || q.any(|j| j.unit == unit && live(j))
    }

    /// The client left: its requests that have not started are dropped.
    pub fn forget(&self, client: ClientId) -> usize {
        self.queue().remove_client(client)
    }

    pub(super) fn next(&self) -> Option<(ClientId, Job)> {
        let mut q = self.queue();
        // The priority class first, unless the others were passed over three times in a row.
        let job = q.pop_prefer(|j| j.high, 4);
        self.metrics.queue_depth(q.len());
        job
    }
}

/// Agent mode: reads every `--poll` range once per its interval, the requests spread evenly over
/// the interval so they leave line time between them; the answers fill the cache (the line
/// does that for every answer). Runs as long as the bridge.
pub async fn poll(polls: Vec<Poll>, shared: Arc<LineShared>) {
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
                let job = Job {
                    unit,
                    pdu: pdu.clone(),
                    reply: tx,
                    queued: Instant::now(),
                    high: false,
                    write: None,
                    audit: None,
                };
                if shared.submit(mbtap_gateway::clients::POLL, job).is_ok() {
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
