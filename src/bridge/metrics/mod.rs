//! The bridge's numbers: requests, responses, exceptions by code, timeouts, CRC errors, queue
//! depth and a latency histogram, per unit; connections and refusals for the server. Their
//! Prometheus text is written in [`exposition`].
//!
//! Beside them: [`endpoint`] (`--metrics`: the Prometheus endpoint) and [`snapshot`] (the line's
//! figures as the web view shows them).

pub(crate) mod endpoint;
mod exposition;
pub mod snapshot;

use std::collections::BTreeMap;
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

/// Latency histogram bucket bounds, seconds (request queued → answer back).
const BUCKETS: [f64; 12] = [0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0];

#[derive(Debug, Default, Clone)]
struct Unit {
    requests: u64,
    responses: u64,
    exceptions: BTreeMap<u8, u64>,
    gateway_exceptions: BTreeMap<u8, u64>,
    timeouts: u64,
    crc_errors: u64,
    /// Requests answered 0x0B at once while the unit's circuit breaker was open.
    circuit_open: u64,
    /// The timeout in force for the unit's last request (learnt with `--timeout auto`).
    timeout: Option<Duration>,
    /// Line time spent waiting for answers that never came.
    waited_in_vain: Duration,
    /// The echo of a request differed from what was sent: another driver on the line.
    collisions: u64,
    /// `--echo on` and the request did not come back.
    echo_missing: u64,
    /// Answers that did not fit the request on the line (late answers to earlier requests).
    late_answers: u64,
    /// Time the line waited before this unit's requests for its `--unit-gap`.
    gap_wait: Duration,
    /// The last latencies, ms (for p50/p99 of what happens now, not since the start).
    recent: std::collections::VecDeque<f64>,
    /// Its breaker open: the line answers 0x0B for it until its next probe.
    resting: bool,
    buckets: [u64; BUCKETS.len()],
    latency_count: u64,
    latency_sum: f64,
}

#[derive(Debug, Default)]
struct Inner {
    units: BTreeMap<u8, Unit>,
    queue_depth: usize,
    dropped: u64,
    reopened: u64,
    connections: u64,
    connections_open: i64,
    refused: BTreeMap<&'static str, u64>,
    /// Requests a client without ids gave up on (`mbtap_gateway::lifetime`): answers withheld.
    abandoned: u64,
    /// Answers withheld from a client with ids shown to ask one thing at a time, which asked
    /// again unanswered or waits no longer (`mbtap_gateway::lifetime`).
    withheld_sequential: u64,
    /// Answers the answer check dropped, by why (`mbtap_gateway::answer::Misfit::reason`).
    misfits: BTreeMap<&'static str, u64>,
    /// Bytes dropped unread: more than the longest answer.
    garbage_bytes: u64,
    last_note: Option<String>,
    /// The last answer the answer check dropped, until an in-process master takes it.
    last_misfit: Option<mbtap_gateway::answer::Misfit>,
    /// Why the port was last found missing or lost (its I/O error's kind and words), until an
    /// in-process master takes it.
    port_failure: Option<(std::io::ErrorKind, String)>,
    /// The last unit whose open breaker answered for it, until an in-process master takes it.
    last_circuit_open: Option<u8>,
    cache_hits: u64,
    cache_misses: u64,
    coalesced: u64,
    /// Line time used, by class: high (`--priority`), normal, poll (`--poll`).
    line_time: BTreeMap<&'static str, Duration>,
    /// The last transactions, newest last (the web view's list).
    last: std::collections::VecDeque<snapshot::Transaction>,
}

/// Counters shared by the line and the connections.
#[derive(Debug, Default)]
pub struct Metrics(Mutex<Inner>);

impl Metrics {
    fn with<R>(&self, f: impl FnOnce(&mut Inner) -> R) -> R {
        f(&mut self.0.lock().unwrap_or_else(PoisonError::into_inner))
    }

    pub fn request(&self, unit: u8) {
        self.with(|m| m.units.entry(unit).or_default().requests += 1);
    }

    /// A response from the slave (an exception counted by its code).
    pub fn response(&self, unit: u8, pdu: &[u8]) {
        self.with(|m| {
            let u = m.units.entry(unit).or_default();
            u.responses += 1;
            if let [fc, code, ..] = pdu
                && fc & 0x80 != 0
            {
                *u.exceptions.entry(*code).or_default() += 1;
            }
        });
    }

    pub fn gateway_exception(&self, unit: u8, code: mbtap_proto::ExceptionCode) {
        self.with(|m| *m.units.entry(unit).or_default().gateway_exceptions.entry(code.value()).or_default() += 1);
    }

    pub fn timeout(&self, unit: u8) {
        self.with(|m| m.units.entry(unit).or_default().timeouts += 1);
    }

    /// A request answered at once because the unit's circuit breaker is open.
    pub fn circuit_open(&self, unit: u8) {
        self.with(|m| {
            m.units.entry(unit).or_default().circuit_open += 1;
            m.last_circuit_open = Some(unit);
        });
    }

    /// A covered read answered from the cache (`hit`) or sent to the line.
    pub fn cache(&self, hit: bool) {
        self.with(|m| if hit { m.cache_hits += 1 } else { m.cache_misses += 1 });
    }

    /// Line time one transaction of `class` used.
    pub fn line_time(&self, class: &'static str, d: Duration) {
        self.with(|m| {
            let t = m.line_time.entry(class).or_default();
            *t = t.saturating_add(d);
        });
    }

    /// `n` requests answered with another client's identical read.
    pub fn coalesced(&self, n: usize) {
        self.with(|m| m.coalesced += n as u64);
    }

    /// The timeout used for `unit`'s request.
    pub fn unit_timeout(&self, unit: u8, d: Duration) {
        self.with(|m| m.units.entry(unit).or_default().timeout = Some(d));
    }

    /// The echo of a request to `unit` was not what was sent.
    pub fn collision(&self, unit: u8) {
        self.with(|m| m.units.entry(unit).or_default().collisions += 1);
        self.note(&format!(
            "collision: the echo of a request to unit {unit} differed from what was sent (another driver on the line?)"
        ));
    }

    /// A request to `unit` did not come back from an echoing adapter.
    /// The line kept silent `waited` before a request to `unit` for its `--unit-gap`.
    pub fn unit_gap_wait(&self, unit: u8, waited: Duration) {
        self.with(|m| {
            let u = m.units.entry(unit).or_default();
            u.gap_wait = u.gap_wait.saturating_add(waited);
        });
    }

    /// An answer from `unit` that fits another request than the one on the line: dropped.
    pub fn late_answer(&self, unit: u8) {
        self.with(|m| m.units.entry(unit).or_default().late_answers += 1);
    }

    /// An answer the answer check dropped (it does not fit the request awaited).
    pub fn misfit(&self, unit: u8, why: mbtap_gateway::answer::Misfit) {
        self.with(|m| {
            m.units.entry(unit).or_default().late_answers += 1;
            *m.misfits.entry(why.reason()).or_default() += 1;
            m.last_misfit = Some(why);
        });
    }

    /// What a Modbus TCP device's stream held besides the answer awaited: answers under other
    /// transaction ids (late) and answers that do not fit, each counted.
    pub fn answers_dropped(&self, unit: u8, dropped: &mbtap_gateway::tcp_device::Dropped) {
        for _ in 0..dropped.late {
            self.late_answer(unit);
        }
        for &why in &dropped.misfits {
            self.misfit(unit, why);
        }
    }

    /// Bytes dropped unread: a stream longer than any answer (garbage).
    pub fn garbage(&self, bytes: usize) {
        self.with(|m| m.garbage_bytes = m.garbage_bytes.saturating_add(bytes as u64));
    }

    pub fn echo_missing(&self, unit: u8) {
        self.with(|m| m.units.entry(unit).or_default().echo_missing += 1);
    }

    /// Line time lost waiting `d` for an answer from `unit` that never came.
    pub fn waited_in_vain(&self, unit: u8, d: Duration) {
        self.with(|m| {
            let u = m.units.entry(unit).or_default();
            u.waited_in_vain = u.waited_in_vain.saturating_add(d);
        });
    }

    pub fn crc_error(&self, unit: u8) {
        self.with(|m| m.units.entry(unit).or_default().crc_errors += 1);
    }

    pub fn latency(&self, unit: u8, d: Duration) {
        self.with(|m| {
            let u = m.units.entry(unit).or_default();
            let s = d.as_secs_f64();
            if u.recent.len() == snapshot::RECENT_LATENCIES {
                u.recent.pop_front();
            }
            u.recent.push_back(s * 1000.0);
            for (b, bound) in u.buckets.iter_mut().zip(BUCKETS) {
                if s <= bound {
                    *b += 1;
                }
            }
            u.latency_count += 1;
            u.latency_sum += s;
        });
    }

    pub fn queue_depth(&self, depth: usize) {
        self.with(|m| m.queue_depth = depth);
    }

    /// A queued request dropped because its client left or gave up on it.
    pub fn dropped(&self) {
        self.with(|m| m.dropped += 1);
    }

    pub fn reopened(&self) {
        self.with(|m| m.reopened += 1);
    }

    pub fn connection_opened(&self) {
        self.with(|m| {
            m.connections += 1;
            m.connections_open += 1;
        });
    }

    pub fn connection_closed(&self) {
        self.with(|m| m.connections_open -= 1);
    }

    /// Something refused: `reason` is a stable snake_case label.
    pub fn refused(&self, reason: &'static str) {
        self.with(|m| *m.refused.entry(reason).or_default() += 1);
    }

    /// `n` requests their clients without ids gave up on: their answers withheld.
    pub fn abandoned(&self, n: u64) {
        self.with(|m| m.abandoned += n);
    }

    /// An answer withheld from a client with ids that asks one thing at a time and no longer
    /// waits for it.
    pub fn withheld_sequential(&self) {
        self.with(|m| m.withheld_sequential += 1);
    }

    /// Keeps the latest event worth telling (a port lost).
    pub fn note(&self, text: &str) {
        self.with(|m| m.last_note = Some(text.to_owned()));
    }

    /// Open connections now.
    #[must_use]
    pub fn open_connections(&self) -> i64 {
        self.with(|m| m.connections_open)
    }

    /// The port could not be opened, or failed under a request: kept, typed, for an in-process
    /// master to say why its request got exception 0x0A.
    pub fn port_failure(&self, kind: std::io::ErrorKind, why: &str) {
        self.with(|m| m.port_failure = Some((kind, why.to_owned())));
    }

    /// Why the port was last missing or lost, taken.
    pub fn take_port_failure(&self) -> Option<(std::io::ErrorKind, String)> {
        self.with(|m| m.port_failure.take())
    }

    /// The last unit whose open breaker answered a request without the line, taken.
    pub fn take_circuit_open(&self) -> Option<u8> {
        self.with(|m| m.last_circuit_open.take())
    }

    /// The last answer the answer check dropped, taken.
    pub fn take_misfit(&self) -> Option<mbtap_gateway::answer::Misfit> {
        self.with(|m| m.last_misfit.take())
    }

    /// The latest note, taken.
    pub fn take_note(&self) -> Option<String> {
        self.with(|m| m.last_note.take())
    }

    /// Requests sent and responses received on the line, all units.
    #[must_use]
    pub fn totals(&self) -> (u64, u64) {
        self.with(|m| (m.units.values().map(|u| u.requests).sum(), m.units.values().map(|u| u.responses).sum()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exposition_carries_every_family_with_labels() {
        let m = Metrics::default();
        m.request(1);
        m.response(1, &[0x83, 0x02]);
        m.gateway_exception(5, mbtap_gateway::rules::GATEWAY_TARGET_FAILED);
        m.timeout(5);
        m.crc_error(5);
        m.latency(1, Duration::from_millis(3));
        m.refused("read_only");
        let text = m.render();
        for line in [
            "mbtap_bridge_requests_total{unit=\"1\"} 1",
            "mbtap_bridge_exceptions_total{unit=\"1\",code=\"2\"} 1",
            "mbtap_bridge_gateway_exceptions_total{unit=\"5\",code=\"11\"} 1",
            "mbtap_bridge_timeouts_total{unit=\"5\"} 1",
            "mbtap_bridge_crc_errors_total{unit=\"5\"} 1",
            "mbtap_bridge_latency_seconds_bucket{unit=\"1\",le=\"0.002\"} 0",
            "mbtap_bridge_latency_seconds_bucket{unit=\"1\",le=\"0.005\"} 1",
            "mbtap_bridge_latency_seconds_count{unit=\"1\"} 1",
            "mbtap_bridge_refused_total{reason=\"read_only\"} 1",
            "mbtap_bridge_queue_depth 0",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing in\n{text}");
        }
    }
}
