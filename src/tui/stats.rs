//! Per-device and whole-bus statistics for the devices view: counts by outcome, exceptions by
//! code, latency percentiles over a bounded window, the polling period, and the bus load (share
//! of line time carrying characters).

use std::collections::{BTreeMap, HashMap, VecDeque};

use mbtap_analysis::framer::LineSettings;
use mbtap_analysis::pairing::{Outcome, Transaction};

/// Latencies kept per device for percentiles: enough for a stable p99, bounded on an endless bus.
const LATENCY_WINDOW: usize = 4096;
/// Distinct requests remembered per device to measure how often each is repeated.
const POLL_KINDS: usize = 256;

/// One unit's numbers.
#[derive(Debug, Clone, Default)]
pub struct DeviceStats {
    pub requests: u64,
    pub ok: u64,
    /// Exception responses by exception code.
    pub exceptions: BTreeMap<u8, u64>,
    pub bad_responses: u64,
    pub timeouts: u64,
    pub other: u64,
    latencies: VecDeque<u64>,
    pub max_latency_ns: u64,
    /// When each distinct request was last sent: its repetition interval is the poll period.
    last_request: HashMap<Box<[u8]>, u64>,
    /// Smoothed poll period (exponential average of repetition intervals).
    pub poll_period_ns: Option<u64>,
    pub last_seen_ns: u64,
}

impl DeviceStats {
    pub fn transaction(&mut self, t: &Transaction<'_>) {
        let at = t.t_start.0;
        self.last_seen_ns = self.last_seen_ns.max(at);
        if t.request.is_some() {
            self.requests += 1;
        }
        match t.outcome {
            Outcome::Ok => self.ok += 1,
            Outcome::Exception(code) => *self.exceptions.entry(code).or_default() += 1,
            Outcome::BadResponse => self.bad_responses += 1,
            Outcome::NoResponse => self.timeouts += 1,
            Outcome::Broadcast | Outcome::Orphan | Outcome::WrongUnit(_) => self.other += 1,
        }
        if let Some(l) = t.latency_ns {
            if self.latencies.len() == LATENCY_WINDOW {
                self.latencies.pop_front();
            }
            self.latencies.push_back(l);
            self.max_latency_ns = self.max_latency_ns.max(l);
        }
        if let Some(req) = t.request {
            if let Some(prev) = self.last_request.get(req).copied() {
                let interval = at.saturating_sub(prev);
                // An average that follows changes within a few polls.
                self.poll_period_ns = Some(self.poll_period_ns.map_or(interval, |p| (p * 7 + interval) / 8));
            }
            if self.last_request.len() < POLL_KINDS || self.last_request.contains_key(req) {
                self.last_request.insert(req.into(), at);
            }
        }
    }

    pub fn exceptions_total(&self) -> u64 {
        self.exceptions.values().sum()
    }

    /// The latency below which `p` (0–100) percent of the recent answers came.
    #[must_use]
    pub fn latency_percentile(&self, p: u32) -> Option<u64> {
        if self.latencies.is_empty() {
            return None;
        }
        let mut v: Vec<u64> = self.latencies.iter().copied().collect();
        v.sort_unstable();
        let i = (v.len() - 1) * usize::try_from(p.min(100)).unwrap_or(100) / 100;
        v.get(i).copied()
    }
}

/// The whole bus.
#[derive(Debug, Clone, Default)]
pub struct BusStats {
    pub frames: u64,
    pub bad_frames: u64,
    pub noise_events: u64,
    pub transactions: u64,
    pub errors: u64,
    /// Line time that carried characters (frames and noise), ns.
    busy_ns: u64,
    first_ns: Option<u64>,
    last_ns: u64,
}

impl BusStats {
    fn carried(&mut self, bytes: usize, t_end: u64, line: LineSettings) {
        let chars = u64::try_from(bytes).unwrap_or(u64::MAX);
        let busy = line.char_ns().saturating_mul(chars);
        self.busy_ns = self.busy_ns.saturating_add(busy);
        self.first_ns.get_or_insert(t_end.saturating_sub(busy));
        self.last_ns = self.last_ns.max(t_end);
    }

    pub fn frame(&mut self, bytes: usize, check_ok: bool, t_end: u64, line: LineSettings) {
        self.frames += 1;
        if !check_ok {
            self.bad_frames += 1;
        }
        self.carried(bytes, t_end, line);
    }

    pub fn noise(&mut self, bytes: usize, t_end: u64, line: LineSettings) {
        self.noise_events += 1;
        self.carried(bytes, t_end, line);
    }

    pub fn transaction(&mut self, outcome: Outcome) {
        self.transactions += 1;
        if !matches!(outcome, Outcome::Ok | Outcome::Broadcast) {
            self.errors += 1;
        }
    }

    /// Share of line time that carried characters since the first one, in percent.
    #[must_use]
    pub fn load_percent(&self) -> Option<f64> {
        let span = self.last_ns.saturating_sub(self.first_ns?);
        (span > 0).then(|| ratio(self.busy_ns, span) * 100.0)
    }

    /// Transactions that did not end well, in percent.
    #[must_use]
    pub fn error_percent(&self) -> Option<f64> {
        (self.transactions > 0).then(|| ratio(self.errors, self.transactions) * 100.0)
    }
}

/// a / b as a float; both stay far below 2^52 in practice, and precision beyond that would not
/// change a percentage on screen.
#[allow(clippy::cast_precision_loss)]
fn ratio(a: u64, b: u64) -> f64 {
    a as f64 / b as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use mbtap_analysis::chunk::Timestamp;

    fn t(outcome: Outcome, at_ms: u64, latency_ms: Option<u64>, req: &'static [u8]) -> Transaction<'static> {
        Transaction {
            outcome,
            unit: 1,
            function: 3,
            request: Some(req),
            response: None,
            request_pdu: None,
            response_pdu: None,
            t_start: Timestamp(at_ms * 1_000_000),
            latency_ns: latency_ms.map(|l| l * 1_000_000),
            latency_resolution_ns: 0,
            input_ended: false,
        }
    }

    #[test]
    fn counts_percentiles_and_the_poll_period() {
        let mut d = DeviceStats::default();
        for i in 0..100 {
            d.transaction(&t(Outcome::Ok, i * 500, Some(i + 1), b"A"));
            d.transaction(&t(Outcome::Ok, i * 500 + 100, Some(2), b"B"));
        }
        d.transaction(&t(Outcome::Exception(2), 50_000, Some(3), b"C"));
        d.transaction(&t(Outcome::NoResponse, 50_100, None, b"C"));
        assert_eq!((d.requests, d.ok, d.timeouts, d.exceptions_total()), (202, 200, 1, 1));
        assert_eq!(d.exceptions.get(&2), Some(&1));
        assert_eq!(d.max_latency_ns, 100_000_000);
        assert_eq!(d.latency_percentile(50), Some(2_000_000), "half the answers took 2 ms");
        assert_eq!(d.latency_percentile(100), Some(100_000_000));
        // "A" and "B" each repeat every 500 ms; "C" once 100 ms apart pulls the average a little.
        let p = d.poll_period_ns.unwrap();
        assert!((400_000_000..=500_000_000).contains(&p), "{p}");
    }

    #[test]
    fn bus_load_is_the_share_of_line_time_carrying_characters() {
        let line = LineSettings::default();
        let mut b = BusStats::default();
        // 10 characters, then 10 more ending 100 characters' time after the first began.
        b.frame(10, true, 10 * line.char_ns(), line);
        b.frame(10, true, 100 * line.char_ns(), line);
        let load = b.load_percent().unwrap();
        assert!((load - 20.0).abs() < 0.01, "{load}");
        b.transaction(Outcome::Ok);
        b.transaction(Outcome::NoResponse);
        assert_eq!(b.error_percent(), Some(50.0));
    }
}
