//! One line, whatever is behind it — a serial port or serial server (the transaction machine,
//! [`crate::transaction`]), a Modbus TCP device ([`crate::tcp_device`]) or devices emulated
//! in the process: what the line decides around each request. Whether it goes at all (a unit
//! resting behind its [`Breaker`]), what its answer may put in the cache, what its outcome
//! teaches the breaker, how long the line stays quiet after it, and under which class its line
//! time is counted. The I/O shells take a request from the queue, ask [`Line::start`], move the
//! bytes through their back, and hand the reply to [`Line::finished`]: one rule for every back.

use std::collections::HashMap;
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

/// One line's decisions, per unit.
#[derive(Debug, Clone)]
pub struct Line {
    back: Back,
    breakers: HashMap<u8, Breaker>,
}

impl Line {
    #[must_use]
    pub fn new(back: Back) -> Self {
        Self { back, breakers: HashMap::new() }
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
    fn line_time_is_counted_by_class() {
        assert_eq!(class(crate::clients::POLL, true), "poll");
        assert_eq!(class(7, true), "high");
        assert_eq!(class(7, false), "normal");
    }
}
