//! When a stream client (TCP, TLS, RTU over TCP) has given up on its requests.
//!
//! Most Modbus masters — libmodbus, mbpoll, pymodbus' synchronous client, most SCADAs — ask one
//! thing at a time: the next request only after the answer or after their own timeout. When
//! such a client asks again while an earlier request is still unanswered, it has stopped
//! waiting for it. Its answer would now arrive while the client waits for another one: libmodbus
//! takes a foreign transaction id as an error and flushes, failing the request after it too
//! (libmodbus's `unit-test-client` through the bridge: every test after line 717 failed in
//! cascade, its 0.5 s timeout below the bridge's 0.8 s), and over RTU over TCP, with no
//! transaction id at all, the late answer would be taken for the new request's. So the
//! abandoned requests are dropped: not sent to the line if they still wait, and their answers
//! never written.
//!
//! A client that pipelines (MODBUS Messaging on TCP/IP v1.0b §4.2 lets a client have several
//! transactions outstanding) must keep every answer. It shows itself at the first request it
//! sends within [`GIVE_UP_MIN`] of an unanswered one — no client's own timeout is that short, and
//! pipelining sends requests back to back — and from then on nothing of it is dropped.
//!
//! Sans-IO: the caller numbers its requests, says how many have their answers written, and
//! gives the time.

use std::collections::VecDeque;
use std::time::Duration;

/// The shortest wait taken for a client's own timeout: a request sent sooner after an
/// unanswered one is pipelining. (libmodbus defaults to 0.5 s, mbpoll to 1 s; libmodbus's
/// own test of a too short timeout uses 0.2 s.)
pub const GIVE_UP_MIN: Duration = Duration::from_millis(100);

/// One connection's requests still without their answer, and whether it pipelines.
#[derive(Debug, Default, Clone)]
pub struct GiveUp {
    /// Sequence numbers and arrival times of requests not yet answered, oldest first.
    waiting: VecDeque<(u64, Duration)>,
    pipelines: bool,
}

impl GiveUp {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Request `seq` (numbered from 0, one more each time) arrived at `now`; every request
    /// numbered below `answered_below` has its answer written. The result: the client gave up
    /// on every request numbered below it (drop them), or `None`.
    pub fn asked(&mut self, seq: u64, now: Duration, answered_below: u64) -> Option<u64> {
        while self.waiting.front().is_some_and(|&(s, _)| s < answered_below) {
            self.waiting.pop_front();
        }
        if self.pipelines {
            return None;
        }
        let gave_up = match self.waiting.back() {
            None => None,
            Some(&(_, last)) if now.saturating_sub(last) < GIVE_UP_MIN => {
                // Back to back with an unanswered request: pipelining, never a timeout.
                self.pipelines = true;
                self.waiting.clear();
                None
            }
            Some(_) => {
                self.waiting.clear();
                Some(seq)
            }
        };
        if !self.pipelines {
            // Bounded: a sequential client has at most one request waiting once the older
            // ones are given up (the client's own queue bounds the rest).
            self.waiting.push_back((seq, now));
        }
        gave_up
    }

    /// Whether the client has shown it pipelines (nothing of it is ever dropped).
    #[must_use]
    pub fn pipelines(&self) -> bool {
        self.pipelines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// libmodbus's `unit-test-client` (line 717): a request the line cannot answer in the
    /// client's 0.5 s, then the next test's request 0.556 s later.
    #[test]
    fn a_sequential_client_asking_again_after_its_timeout_gave_up_on_the_first() {
        let mut g = GiveUp::new();
        assert_eq!(g.asked(0, ms(0), 0), None);
        assert_eq!(g.asked(1, ms(3), 1), None, "the first was answered: nothing given up");
        assert_eq!(g.asked(2, ms(559), 1), Some(2), "request 1 waited 556 ms unanswered");
        assert_eq!(g.asked(3, ms(1_060), 2), Some(3), "and request 2 likewise");
        assert!(!g.pipelines());
    }

    #[test]
    fn a_client_sending_back_to_back_pipelines_and_keeps_every_answer() {
        let mut g = GiveUp::new();
        assert_eq!(g.asked(0, ms(0), 0), None);
        assert_eq!(g.asked(1, ms(1), 0), None);
        assert!(g.pipelines());
        // Later, a long wait between its requests is not taken for a timeout.
        assert_eq!(g.asked(2, ms(900), 0), None);
        assert_eq!(g.asked(3, ms(5_000), 1), None);
    }

    #[test]
    fn answers_written_in_time_leave_nothing_to_give_up() {
        let mut g = GiveUp::new();
        for seq in 0..1_000 {
            assert_eq!(g.asked(seq, ms(seq * 200), seq), None);
        }
        assert!(g.waiting.len() <= 1, "bounded: {}", g.waiting.len());
    }
}
