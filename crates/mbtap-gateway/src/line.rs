//! One line, whatever is behind it — a serial port or serial server (the transaction machine,
//! [`crate::transaction`]), a Modbus TCP device ([`crate::tcp_device`]) or devices emulated
//! in the process: what the line decides around each request. Whether it goes at all (a unit
//! resting behind its [`Breaker`]), what its answer may put in the cache, what its outcome
//! teaches the breaker, how long the line stays quiet after it, and under which class its line
//! time is counted. The I/O shells take a request from the queue, ask [`Line::start`], move the
//! bytes through their back, and hand the reply to [`Line::finished`]: one rule for every back.
//! A unit may ask for a pause of its own before each request to it ([`UnitGaps`], `--unit-gap`):
//! a slow device that needs silence beyond t3.5 gets it, and no other unit waits for it.

use std::collections::{BTreeMap, HashMap};
use std::time::Duration;

use crate::breaker::Breaker;
use crate::queue::ClientId;
use crate::rules::GATEWAY_TARGET_FAILED;
use crate::transaction::Reply;

/// What is behind the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Back {
    /// A serial line, local or through a serial server: after each exchange the line keeps
    /// quiet for `guard` (t3.5 and the turnaround, Serial Line v1.02 §2.5.1.1).
    Serial { guard: Duration },
    /// A Modbus TCP device: answers are matched by transaction id; no quiet time is owed.
    TcpDevice,
    /// Devices emulated in this process: answered in order, no quiet time.
    Emulated,
}

/// Whether a request taken from the queue goes to the back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Start {
    Go,
    /// Answered without the back: the unit's breaker is open (MAP v1.1b3 §7, 0x0B).
    Answer(Reply),
}

/// What the line does once a request's reply is known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Finished {
    /// The answer may fill the cache (a unit's own, not an exception, and the back says it is
    /// this request's).
    pub fill_cache: bool,
    /// How long after the exchange's last byte the line stays quiet.
    pub quiet: Duration,
}

/// Under which class a request's line time is counted (`mbtap_bridge_line_seconds{class}`).
#[must_use]
pub fn class(client: ClientId, high: bool) -> &'static str {
    match (client == crate::clients::POLL, high) {
        (true, _) => "poll",
        (false, true) => "high",
        (false, false) => "normal",
    }
}

/// `--unit-gap`: silence the line keeps before each request to a unit, beyond its quiet time
/// (t3.5 and the turnaround): for every unit, and per unit (which wins).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct UnitGaps {
    pub every: Duration,
    pub units: BTreeMap<u8, Duration>,
}

/// The longest gap a unit may ask for: a minute (a device that needs more is polled, not paced).
pub const MAX_GAP_MS: u64 = 60_000;

impl UnitGaps {
    /// `--unit-gap` values: `MS` for every unit, `UNITS=MS` for some (`1=40`, `10-12=100`).
    ///
    /// # Errors
    /// A value that is neither, or a gap outside 0–60 000 ms, named with what to give.
    pub fn parse(values: &[String]) -> Result<Self, crate::BadValue> {
        let mut gaps = Self::default();
        for v in values {
            let bad = |why: String| crate::BadValue(format!("--unit-gap {v:?}: {why}"));
            let (units, ms) = match v.split_once('=') {
                Some((units, ms)) => (Some(units), ms),
                None => (None, v.as_str()),
            };
            let ms: u64 =
                ms.trim().parse().ok().filter(|&m| m <= MAX_GAP_MS).ok_or_else(|| {
                    bad(format!("{ms:?} is not a number of ms from 0 to {MAX_GAP_MS}; e.g. 40 or 1=40"))
                })?;
            let gap = Duration::from_millis(ms);
            match units {
                None => gaps.every = gap,
                Some(units) => {
                    for unit in crate::parse::parse_units(units).map_err(|e| bad(e.to_string()))? {
                        gaps.units.insert(unit, gap);
                    }
                }
            }
        }
        Ok(gaps)
    }

    /// The gap owed before a request to `unit`; a broadcast (unit 0) reaches every unit and
    /// waits for the longest.
    #[must_use]
    pub fn of(&self, unit: u8) -> Duration {
        if unit == 0 {
            return self.units.values().copied().fold(self.every, Duration::max);
        }
        self.units.get(&unit).copied().unwrap_or(self.every)
    }
}

/// One line's decisions, per unit.
#[derive(Debug, Clone)]
pub struct Line {
    back: Back,
    breakers: HashMap<u8, Breaker>,
    gaps: UnitGaps,
}

impl Line {
    #[must_use]
    pub fn new(back: Back) -> Self {
        Self { back, breakers: HashMap::new(), gaps: UnitGaps::default() }
    }

    /// The line with `--unit-gap`s.
    #[must_use]
    pub fn with_gaps(mut self, gaps: UnitGaps) -> Self {
        self.gaps = gaps;
        self
    }

    /// When a request to `unit` may go, the line being free (its quiet time kept) from `free`:
    /// that plus the unit's own gap — and no later for a unit without one.
    #[must_use]
    pub fn ready_at(&self, unit: u8, free: Duration) -> Duration {
        free.saturating_add(self.gaps.of(unit))
    }

    /// Whether `unit` rests behind its open breaker at `now` (its requests answered 0x0B).
    #[must_use]
    pub fn resting(&self, unit: u8, now: Duration) -> bool {
        self.breakers.get(&unit).is_some_and(|b| b.refuses(now))
    }

    /// A request to `unit` is next, at `now`. Broadcasts (unit 0) always go: nobody answers
    /// them, so no breaker learns from them.
    pub fn start(&mut self, unit: u8, now: Duration) -> Start {
        if unit != 0 && self.breakers.get(&unit).is_some_and(|b| b.refuses(now)) {
            return Start::Answer(Reply::Gateway(GATEWAY_TARGET_FAILED));
        }
        Start::Go
    }

    /// The request to `unit` ended with `reply` at `now`; `cacheable`: the back vouches that
    /// the answer is this request's (a serial answer heard after a late one may not be).
    pub fn finished(&mut self, unit: u8, reply: &Reply, cacheable: bool, now: Duration) -> Finished {
        if unit != 0 {
            let answered = *reply != Reply::Gateway(GATEWAY_TARGET_FAILED);
            self.breakers.entry(unit).or_default().record(answered, now);
        }
        let own_answer =
            matches!(reply, Reply::Pdu(pdu) if pdu.first().is_some_and(|f| f & mbtap_proto::EXCEPTION_FLAG == 0));
        let quiet = match self.back {
            Back::Serial { guard } => guard,
            Back::TcpDevice | Back::Emulated => Duration::ZERO,
        };
        Finished { fill_cache: unit != 0 && own_answer && cacheable, quiet }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::breaker::BREAK_AFTER;

    /// A read's answer (03, two bytes) and an exception (83 02).
    const ANSWER: [u8; 4] = [0x03, 0x02, 0x00, 0x2A];
    const EXCEPTION: [u8; 2] = [0x83, 0x02];

    #[test]
    fn a_unit_that_fails_in_a_row_rests_whatever_the_back() {
        for back in [Back::Serial { guard: Duration::from_millis(2) }, Back::TcpDevice, Back::Emulated] {
            let mut line = Line::new(back);
            let t = Duration::from_secs(1);
            for _ in 0..BREAK_AFTER {
                assert_eq!(line.start(5, t), Start::Go);
                line.finished(5, &Reply::Gateway(GATEWAY_TARGET_FAILED), false, t);
            }
            assert_eq!(line.start(5, t), Start::Answer(Reply::Gateway(GATEWAY_TARGET_FAILED)), "{back:?}");
            assert_eq!(line.start(6, t), Start::Go, "another unit still goes");
            assert_eq!(line.start(0, t), Start::Go, "a broadcast always goes");
        }
    }

    #[test]
    fn only_a_units_own_answer_fills_the_cache_and_only_a_serial_line_keeps_quiet() {
        let guard = Duration::from_millis(2);
        let mut serial = Line::new(Back::Serial { guard });
        let t = Duration::ZERO;
        assert_eq!(
            serial.finished(1, &Reply::Pdu(ANSWER.to_vec()), true, t),
            Finished { fill_cache: true, quiet: guard }
        );
        assert!(!serial.finished(1, &Reply::Pdu(ANSWER.to_vec()), false, t).fill_cache, "not vouched for");
        assert!(!serial.finished(1, &Reply::Pdu(EXCEPTION.to_vec()), true, t).fill_cache, "an exception");
        assert!(!serial.finished(0, &Reply::Silence, true, t).fill_cache, "a broadcast");
        let mut device = Line::new(Back::TcpDevice);
        assert_eq!(device.finished(1, &Reply::Pdu(ANSWER.to_vec()), true, t).quiet, Duration::ZERO);
    }

    #[test]
    fn a_units_gap_delays_its_requests_and_no_other_units() {
        let gaps = UnitGaps::parse(&["1=40".to_owned(), "10-12=100".to_owned()]).unwrap();
        let line = Line::new(Back::Serial { guard: Duration::from_millis(2) }).with_gaps(gaps);
        let free = Duration::from_secs(5);
        assert_eq!(line.ready_at(1, free), free + Duration::from_millis(40));
        assert_eq!(line.ready_at(11, free), free + Duration::from_millis(100));
        assert_eq!(line.ready_at(2, free), free, "a unit without a gap waits for none");
        assert_eq!(line.ready_at(0, free), free + Duration::from_millis(100), "a broadcast waits for the longest");
        let every = UnitGaps::parse(&["25".to_owned(), "3=0".to_owned()]).unwrap();
        assert_eq!((every.of(7), every.of(3)), (Duration::from_millis(25), Duration::ZERO));
        for bad in ["x", "1=", "1=60001", "300=5", "-1"] {
            let e = UnitGaps::parse(&[bad.to_owned()]).unwrap_err().to_string();
            assert!(e.contains("--unit-gap"), "{bad}: {e}");
        }
    }

    #[test]
    fn line_time_is_counted_by_class() {
        assert_eq!(class(crate::clients::POLL, true), "poll");
        assert_eq!(class(7, true), "high");
        assert_eq!(class(7, false), "normal");
    }
}
