//! A request's lifetime as its asker sees it: whether the asker still waits for it, and what
//! its answer becomes when it comes — decided here, once, for every front.
//!
//! Two kinds of asker:
//! - **With ids** (MBAP over TCP, TLS, UDP: MODBUS Messaging on TCP/IP v1.0b §4.2 lets a client
//!   have several transactions outstanding, each answered under its own transaction id). A
//!   later request is no sign that an earlier one was given up: every request gets its answer —
//!   the device's, its exception, or the gateway's 0x0B — whatever the spacing. The one
//!   exception rests on evidence, not spacing: a client that has *shown* it asks one thing at
//!   a time — [`PROOF`] requests in a row each sent within [`REACTION`] of the answer before
//!   it, and never a second request while one was unanswered — and then asks while one is
//!   unanswered has given up on it (its own timeout ran out: libmodbus, mbpoll, most SCADAs).
//!   That answer would meet its next request; a sequential client takes it for the next
//!   request's, fails it, and stays one answer behind from then on.
//! - **Without ids** (RTU over TCP, a serial master on `--listen-serial`, the emulator's serial
//!   fronts): one transaction at a time (MODBUS over Serial Line v1.02 §2.4.1: the master waits
//!   for the reply or its response timeout before the next request). Its next request means it
//!   gave up on every earlier one; those answers, late or not, never reach it.
//!
//! For a one-at-a-time asker (without ids, or shown sequential) the wait after which it asked
//! again is learnt: its own response timeout is no longer than that. Once two give-ups were
//! seen, an answer that would reach it later after its request than the longer of the last two
//! such waits (less a guard, [`GUARD`]) is withheld too — it would sit in the asker's input and
//! meet the next request. One
//! odd give-up (a master that moved on early once) withholds nothing.
//!
//! Sans-IO: the caller numbers requests (from 0, one more each time), gives the time on one
//! clock of its choice, and says when an answer is ready to go out.

use std::collections::VecDeque;
use std::time::Duration;

/// Requests in a row, each sent right after the answer before it, that show a client with ids
/// asks one thing at a time.
pub const PROOF: u32 = 3;

/// How soon after an answer the next request must come to count as caused by it: a client
/// that asks again this soon waited for the answer (a program's loop, not a poll timer). Far
/// above a loop's turn on loopback (tens of µs), far below poll periods (100 ms and up).
pub const REACTION: Duration = Duration::from_millis(10);

/// The shortest wait taken for a master's response timeout: less than a request and its answer
/// take on the wire at 9600 baud (8 + 7 characters, 17 ms), which no master sets.
pub const SHORTEST_TIMEOUT: Duration = Duration::from_millis(20);

/// How close to a one-at-a-time asker's learnt timeout an answer may arrive, at least (an eighth
/// of the timeout when that is more): the master may already have moved on, and an answer it
/// reads then is taken for its next request's. Silence is the safe side.
pub const GUARD: Duration = Duration::from_millis(5);

/// Requests kept for the give-up decision, at most: the queue per client bounds what is
/// outstanding (`--queue-per-client`, at most 1024); the oldest are forgotten beyond this.
const TRACKED: usize = 4096;

/// Whether an asker numbers its requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ids {
    /// MBAP: each answer carries its request's transaction id.
    Has,
    /// RTU framing: nothing ties an answer to its request but the order.
    None,
}

/// What a client with ids has shown of how it asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Conduct {
    /// Not yet shown: `reactions` requests in a row came right after the previous answer.
    Unknown { reactions: u32 },
    /// One thing at a time: a request while another waits means it gave up on that one.
    Sequential,
    /// Several outstanding: nothing of it is ever given up.
    Pipelines,
}

/// What becomes of an answer that is ready.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fate {
    /// Its asker waits for it: write it.
    Deliver,
    /// Its asker gave up on it (asked again, or waited longer than it ever waits): never
    /// written.
    Withhold,
}

/// One asker's requests still without their answer, and what it has shown.
#[derive(Debug, Clone)]
pub struct Lifetime {
    ids: Ids,
    conduct: Conduct,
    /// Sequence numbers and arrival times of requests not yet answered, oldest first.
    waiting: VecDeque<(u64, Duration)>,
    /// Requests numbered below this were given up by the asker.
    given_up_below: u64,
    /// When the last answer was written.
    last_answer: Option<Duration>,
    /// The last two waits after which this asker asked again with a request unanswered,
    /// newest first: its response timeout is no longer than either.
    gave_up_after: [Option<Duration>; 2],
}

impl Lifetime {
    /// A new asker.
    #[must_use]
    pub fn new(ids: Ids) -> Self {
        Self {
            ids,
            conduct: Conduct::Unknown { reactions: 0 },
            waiting: VecDeque::new(),
            given_up_below: 0,
            last_answer: None,
            gave_up_after: [None, None],
        }
    }

    /// Request `seq` arrived at `now`. The result: the asker gave up on every request numbered
    /// below it (each not yet on the line never goes there; no answer of them is written), or
    /// `None`.
    pub fn asked(&mut self, seq: u64, now: Duration) -> Option<u64> {
        let outstanding = self.waiting.front().copied();
        let gives_up = match (self.ids, self.conduct) {
            (Ids::None, _) | (Ids::Has, Conduct::Sequential) => outstanding.is_some(),
            (Ids::Has, Conduct::Pipelines) => false,
            (Ids::Has, Conduct::Unknown { reactions }) => {
                self.conduct = if outstanding.is_some() {
                    Conduct::Pipelines
                } else if self.last_answer.is_some_and(|t| now.saturating_sub(t) <= REACTION) {
                    if reactions + 1 >= PROOF {
                        Conduct::Sequential
                    } else {
                        Conduct::Unknown { reactions: reactions + 1 }
                    }
                } else {
                    Conduct::Unknown { reactions: 0 }
                };
                false
            }
        };
        let result = if gives_up {
            // The newest unanswered request waited this long before the asker moved on: its
            // timeout is no longer than that. A request superseded sooner than any master waits
            // is a burst, not a timeout, and teaches nothing.
            if let Some(&(_, at)) = self.waiting.back()
                && now.saturating_sub(at) >= SHORTEST_TIMEOUT
            {
                self.gave_up_after = [Some(now.saturating_sub(at)), self.gave_up_after[0]];
            }
            self.waiting.clear();
            self.given_up_below = self.given_up_below.max(seq);
            Some(seq)
        } else {
            None
        };
        if self.waiting.len() >= TRACKED {
            self.waiting.pop_front();
        }
        self.waiting.push_back((seq, now));
        result
    }

    /// The answer to request `seq` would reach its asker at `arrives` (when it is written, plus
    /// a serial front's turnaround and the frame's time on the wire). Whether it goes out;
    /// either way the request is no longer waiting.
    pub fn answer(&mut self, seq: u64, arrives: Duration) -> Fate {
        let asked = self.take(seq);
        if seq < self.given_up_below {
            return Fate::Withhold;
        }
        let one_at_a_time = self.ids == Ids::None || self.conduct == Conduct::Sequential;
        if one_at_a_time
            && let (Some(at), Some(patience)) = (asked, self.patience())
            && arrives.saturating_sub(at) > patience.saturating_sub((patience / 8).max(GUARD))
        {
            return Fate::Withhold;
        }
        self.last_answer = Some(arrives);
        Fate::Deliver
    }

    /// Request `seq` gets no answer (a broadcast): it no longer waits, and nothing was written.
    pub fn unanswered(&mut self, seq: u64) {
        self.take(seq);
    }

    /// Request `seq` no longer waits: when it was asked, if it was still tracked.
    fn take(&mut self, seq: u64) -> Option<Duration> {
        let i = self.waiting.iter().position(|&(s, _)| s == seq)?;
        self.waiting.remove(i).map(|(_, at)| at)
    }

    /// Whether the asker gave up on request `seq`.
    #[must_use]
    pub fn given_up(&self, seq: u64) -> bool {
        seq < self.given_up_below
    }

    /// How long this asker waits for an answer, at most, once two give-ups taught it: the
    /// longer of the last two waits after which it asked again.
    #[must_use]
    pub fn patience(&self) -> Option<Duration> {
        match self.gave_up_after {
            [Some(a), Some(b)] => Some(a.max(b)),
            _ => None,
        }
    }

    /// Whether a client with ids has shown it pipelines (nothing of it is ever given up).
    #[must_use]
    pub fn pipelines(&self) -> bool {
        self.conduct == Conduct::Pipelines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// A client with ids asking every `gap` ms, `n` requests, to a line that answers each
    /// `line` ms after the previous answer (one transaction at a time); which requests it gets.
    fn pipelined(gap: u64, line: u64, n: u64) -> Vec<(u64, Fate)> {
        let mut l = Lifetime::new(Ids::Has);
        let mut events: Vec<(u64, bool, u64)> = (0..n).map(|s| (s * gap, true, s)).collect();
        let mut free = 0;
        for s in 0..n {
            free = free.max(s * gap) + line;
            events.push((free, false, s));
        }
        // At equal times the answer is written before the request is read (the worse order).
        events.sort_by_key(|&(t, ask, s)| (t, ask, s));
        let mut got = Vec::new();
        for (t, ask, s) in events {
            if ask {
                l.asked(s, ms(t));
            } else {
                got.push((s, l.answer(s, ms(t))));
            }
        }
        got
    }

    #[test]
    fn a_client_with_ids_gets_every_answer_at_any_spacing() {
        for gap in [50, 150, 250, 500] {
            for line in [300, 600] {
                let got = pipelined(gap, line, 8);
                assert!(got.iter().all(|&(_, f)| f == Fate::Deliver), "gap {gap} ms, line {line} ms: {got:?}");
                assert_eq!(got.len(), 8);
            }
        }
    }

    #[test]
    fn a_write_then_a_read_keeps_the_writes_answer() {
        let mut l = Lifetime::new(Ids::Has);
        assert_eq!(l.asked(0, ms(0)), None);
        assert_eq!(l.asked(1, ms(150)), None);
        assert_eq!(l.answer(0, ms(300)), Fate::Deliver);
        assert_eq!(l.answer(1, ms(600)), Fate::Deliver);
    }

    /// libmodbus's `unit-test-client`: each test asks right after the previous answer; a
    /// request the line cannot answer within its 0.5 s is followed, 0.555 s later, by the next.
    #[test]
    fn a_client_shown_sequential_gave_up_when_it_asks_again_unanswered() {
        let mut l = Lifetime::new(Ids::Has);
        let mut t = 0;
        for seq in 0..=PROOF {
            let seq = u64::from(seq);
            assert_eq!(l.asked(seq, ms(t)), None);
            t += 2;
            assert_eq!(l.answer(seq, ms(t)), Fate::Deliver);
        }
        let slow = u64::from(PROOF) + 1;
        assert_eq!(l.asked(slow, ms(t)), None);
        assert_eq!(l.asked(slow + 1, ms(t + 555)), Some(slow + 1), "it waited 555 ms and moved on");
        assert_eq!(l.answer(slow, ms(t + 800)), Fate::Withhold, "the late 0x0B never meets the next request");
        assert_eq!(l.patience(), None, "one give-up teaches no timeout");
        assert_eq!(l.answer(slow + 1, ms(t + 557)), Fate::Deliver);
    }

    /// A poller on a timer (every 150 ms, whatever the answers do) never shows it waits for
    /// answers: another client's load that delays its answers takes none of them.
    #[test]
    fn a_timer_driven_client_keeps_its_answers_when_the_line_is_slow() {
        let mut l = Lifetime::new(Ids::Has);
        for seq in 0..20 {
            assert_eq!(l.asked(seq, ms(seq * 150)), None);
            assert_eq!(l.answer(seq, ms(seq * 150 + 5)), Fate::Deliver);
        }
        // Now another client's queue delays each answer 400 ms.
        for seq in 20..40 {
            assert_eq!(l.asked(seq, ms(seq * 150)), None);
        }
        for seq in 20..40 {
            assert_eq!(l.answer(seq, ms(seq * 150 + 400)), Fate::Deliver, "request {seq}");
        }
        assert!(l.pipelines());
    }

    #[test]
    fn a_client_without_ids_gave_up_at_its_next_request_whatever_the_spacing() {
        for gap in [1, 50, 150, 600] {
            let mut l = Lifetime::new(Ids::None);
            assert_eq!(l.asked(0, ms(0)), None);
            assert_eq!(l.asked(1, ms(gap)), Some(1));
            assert!(l.given_up(0));
            assert_eq!(l.answer(0, ms(gap + 10)), Fate::Withhold, "gap {gap}");
        }
    }

    /// A serial master with a 200 ms timeout asking again 10 ms after it, to a unit answering in
    /// 300 ms: once seen twice, every answer later than 210 ms is withheld — even when the
    /// master pauses before it asks again.
    #[test]
    fn a_serial_masters_timeout_is_learnt_and_later_answers_withheld() {
        let mut l = Lifetime::new(Ids::None);
        assert_eq!(l.asked(0, ms(0)), None);
        assert_eq!(l.answer(0, ms(300)), Fate::Deliver, "no give-up seen yet: delivered");
        assert_eq!(l.asked(1, ms(1_000)), None);
        assert_eq!(l.asked(2, ms(1_210)), Some(2));
        assert_eq!(l.answer(1, ms(1_300)), Fate::Withhold);
        assert_eq!(l.patience(), None);
        assert_eq!(l.asked(3, ms(1_420)), Some(3));
        assert_eq!(l.patience(), Some(ms(210)));
        assert_eq!(l.answer(3, ms(1_720)), Fate::Withhold, "300 ms > 210 ms: the master stopped waiting");
        assert_eq!(l.asked(4, ms(3_000)), None);
        assert_eq!(l.answer(4, ms(3_060)), Fate::Deliver, "a 60 ms answer is in time");
    }

    /// A master that sends a burst without waiting teaches no timeout: the request it then sends
    /// and waits for is answered.
    #[test]
    fn a_burst_of_requests_teaches_no_timeout() {
        let mut l = Lifetime::new(Ids::None);
        for seq in 0..100 {
            l.asked(seq, ms(seq / 10));
        }
        assert_eq!(l.patience(), None);
        assert_eq!(l.answer(99, ms(400)), Fate::Deliver);
    }

    #[test]
    fn one_early_give_up_withholds_nothing_later() {
        let mut l = Lifetime::new(Ids::None);
        assert_eq!(l.asked(0, ms(0)), None);
        assert_eq!(l.asked(1, ms(20)), Some(1));
        assert_eq!(l.answer(1, ms(620)), Fate::Deliver);
    }

    #[test]
    fn answers_in_time_leave_nothing_waiting() {
        let mut l = Lifetime::new(Ids::None);
        for seq in 0..1_000 {
            assert_eq!(l.asked(seq, ms(seq * 200)), None);
            assert_eq!(l.answer(seq, ms(seq * 200 + 50)), Fate::Deliver);
        }
        assert!(l.waiting.is_empty());
    }

    #[test]
    fn a_pipelining_flood_keeps_bounded_state() {
        let mut l = Lifetime::new(Ids::Has);
        for seq in 0..20_000 {
            l.asked(seq, ms(seq));
        }
        assert!(l.waiting.len() <= TRACKED);
    }
}
