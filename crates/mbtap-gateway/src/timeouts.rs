//! How long the line waits for each unit's answer: a fixed `--timeout-ms`, a per-unit
//! `--unit-timeout UNITS=MS` (a slow unit beside fast ones), or `--timeout auto`: each unit's
//! timeout learnt from its own answers, so a dead unit costs little line time and a slow one is
//! not cut off. Pure: latencies and timeouts are inputs, no clock here.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

/// Answers remembered per unit for `auto`.
const WINDOW: usize = 32;
/// Answers needed before `auto` trusts what it learnt (until then: the ceiling).
const MIN_SAMPLES: usize = 5;
/// `auto`: this many times the slowest recent answer (the p99 of 32 is their maximum)…
const FACTOR: u32 = 3;
/// …plus this, for the adapter's latency timer and the scheduler.
const MARGIN: Duration = Duration::from_millis(10);
/// `auto` never goes below this (a 1 ms timer and a USB adapter's batching).
const FLOOR: Duration = Duration::from_millis(20);

/// How timeouts are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TimeoutMode {
    /// `--timeout-ms` for every unit (and `--unit-timeout` where given).
    #[default]
    Fixed,
    /// Learnt per unit from its answers: 3 × its slowest of the last 32 + 10 ms, within 20 ms
    /// and `--timeout-ms`; doubled after each timeout.
    Auto,
}

#[derive(Debug, Default, Clone)]
struct Learnt {
    latencies: VecDeque<Duration>,
    /// After timeouts: the learnt value doubled this many times (reset by an answer).
    backoff: u32,
}

/// Per-unit timeouts.
#[derive(Debug, Clone)]
pub struct Timeouts {
    ceiling: Duration,
    mode: TimeoutMode,
    fixed: BTreeMap<u8, Duration>,
    learnt: BTreeMap<u8, Learnt>,
}

impl Timeouts {
    #[must_use]
    pub fn new(ceiling: Duration, mode: TimeoutMode, fixed: BTreeMap<u8, Duration>) -> Self {
        Self { ceiling, mode, fixed, learnt: BTreeMap::new() }
    }

    /// The timeout for `unit`'s next request.
    #[must_use]
    pub fn get(&self, unit: u8) -> Duration {
        if let Some(&d) = self.fixed.get(&unit) {
            return d;
        }
        if self.mode == TimeoutMode::Fixed {
            return self.ceiling;
        }
        let Some(l) = self.learnt.get(&unit).filter(|l| l.latencies.len() >= MIN_SAMPLES) else { return self.ceiling };
        let slowest = l.latencies.iter().max().copied().unwrap_or(self.ceiling);
        let base = slowest.saturating_mul(FACTOR).saturating_add(MARGIN).max(FLOOR);
        base.saturating_mul(1u32 << l.backoff.min(16)).min(self.ceiling)
    }

    /// `unit` answered `latency` after its request left.
    pub fn answered(&mut self, unit: u8, latency: Duration) {
        let l = self.learnt.entry(unit).or_default();
        if l.latencies.len() == WINDOW {
            l.latencies.pop_front();
        }
        l.latencies.push_back(latency);
        l.backoff = 0;
    }

    /// `unit` did not answer in time.
    pub fn timed_out(&mut self, unit: u8) {
        let l = self.learnt.entry(unit).or_default();
        l.backoff = l.backoff.saturating_add(1);
    }
}

/// `--unit-timeout UNITS=MS` values (`5=2000`, `10-12,14=50`) into one map.
///
/// # Errors
/// Which value is malformed and why.
pub fn parse_unit_timeouts(values: &[String]) -> Result<BTreeMap<u8, Duration>, crate::BadValue> {
    let mut out = BTreeMap::new();
    for v in values {
        let (units, ms) = v.split_once('=').ok_or_else(|| {
            crate::BadValue(format!("--unit-timeout {v:?}: expected UNITS=MS, e.g. 5=2000 or 10-12=50"))
        })?;
        let ms: u64 = ms.trim().parse().ok().filter(|&m| (1..=60_000).contains(&m)).ok_or_else(|| {
            crate::BadValue(format!("--unit-timeout {v:?}: {ms:?} is not a number of ms from 1 to 60000"))
        })?;
        for unit in
            crate::parse::parse_units(units).map_err(|e| crate::BadValue(format!("--unit-timeout {v:?}: {e}")))?
        {
            out.insert(unit, Duration::from_millis(ms));
        }
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const CEILING: Duration = Duration::from_secs(1);

    #[test]
    fn auto_learns_each_unit_and_backs_off_after_timeouts() {
        let mut t = Timeouts::new(CEILING, TimeoutMode::Auto, BTreeMap::new());
        assert_eq!(t.get(1), CEILING, "nothing learnt yet: the ceiling");
        for ms in [4, 5, 6, 5, 4] {
            t.answered(1, Duration::from_millis(ms));
        }
        // 3 × 6 ms + 10 ms.
        assert_eq!(t.get(1), Duration::from_millis(28));
        t.timed_out(1);
        assert_eq!(t.get(1), Duration::from_millis(56));
        for _ in 0..10 {
            t.timed_out(1);
        }
        assert_eq!(t.get(1), CEILING, "never above the ceiling");
        t.answered(1, Duration::from_millis(5));
        assert_eq!(t.get(1), Duration::from_millis(28), "an answer resets the backoff");
        // A slow unit learns a long one; a fast one is floored.
        for _ in 0..5 {
            t.answered(2, Duration::from_millis(200));
            t.answered(3, Duration::from_micros(100));
        }
        assert_eq!(t.get(2), Duration::from_millis(610));
        assert_eq!(t.get(3), FLOOR);
    }

    #[test]
    fn fixed_units_win_and_fixed_mode_ignores_learning() {
        let fixed = parse_unit_timeouts(&["5=2000".into(), "10-11=50".into()]).unwrap();
        let mut t = Timeouts::new(CEILING, TimeoutMode::Fixed, fixed);
        for _ in 0..5 {
            t.answered(1, Duration::from_millis(1));
        }
        assert_eq!(t.get(1), CEILING);
        assert_eq!(t.get(5), Duration::from_secs(2));
        assert_eq!(t.get(11), Duration::from_millis(50));
        assert!(parse_unit_timeouts(&["5".into()]).is_err());
        assert!(parse_unit_timeouts(&["5=0".into()]).is_err());
        assert!(parse_unit_timeouts(&["300=5".into()]).is_err());
    }
}
