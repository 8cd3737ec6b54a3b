//! Per unit: a dead unit must not cost every client its timeout of line time. After
//! [`BREAK_AFTER`] consecutive failures its requests are answered 0x0B (Gateway Target Device
//! Failed to Respond, MAP v1.1b3 §7) at once until the breaker's time is up; then one request
//! probes it. Time is an input.

use std::time::Duration;

/// A unit that failed to answer this many requests in a row gets its circuit breaker opened.
pub const BREAK_AFTER: u32 = 3;
/// How long an open breaker answers 0x0B at once before one probe request goes through;
/// doubled after each failed probe, up to [`BREAKER_MAX`].
pub const BREAKER_START: Duration = Duration::from_secs(2);
pub const BREAKER_MAX: Duration = Duration::from_secs(30);

/// One unit's breaker.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Breaker {
    failures: u32,
    open_until: Option<Duration>,
    backoff: Duration,
}

impl Breaker {
    /// Should a request at `now` be answered 0x0B without using the line?
    #[must_use]
    pub fn refuses(&self, now: Duration) -> bool {
        self.open_until.is_some_and(|until| now < until)
    }

    /// The outcome of a request that went to the unit, at `now`.
    pub fn record(&mut self, answered: bool, now: Duration) {
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

    /// Consecutive failures so far.
    #[must_use]
    pub fn failures(&self) -> u32 {
        self.failures
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eight clients polling a dead unit do not cost the line a timeout each (a good unit's client
    /// would get 3 answers in 8): the breaker opens after three failures, probes once per backoff
    /// (doubling to 30 s), and closes on the first answer.
    #[test]
    fn a_dead_unit_is_answered_at_once_between_probes() {
        let t0 = Duration::from_secs(100);
        let mut b = Breaker::default();
        for i in 0..BREAK_AFTER {
            assert!(!b.refuses(t0), "failure {i}: still tried");
            b.record(false, t0);
        }
        assert!(b.refuses(t0 + Duration::from_millis(1)));
        assert!(b.refuses(t0 + BREAKER_START.saturating_sub(Duration::from_millis(1))));
        // The probe goes through, fails: twice as long now.
        let probe = t0 + BREAKER_START;
        assert!(!b.refuses(probe));
        b.record(false, probe);
        assert!(b.refuses(probe + (BREAKER_START * 2).saturating_sub(Duration::from_millis(1))));
        assert!(!b.refuses(probe + BREAKER_START * 2));
        // Never longer than the cap.
        for _ in 0..10 {
            b.record(false, probe);
        }
        assert_eq!(b.backoff, BREAKER_MAX);
        // An answer closes it.
        b.record(true, probe);
        assert!(!b.refuses(probe));
        assert_eq!(b.failures(), 0);
    }
}
