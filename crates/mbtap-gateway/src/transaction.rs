//! One serial request at a time, as a state machine: the I/O shell sends what it is told, feeds
//! back the bytes it reads and the time, and does what the machine says next — send, wait
//! until, or take the reply. No port, no clock here; a test drives it with a byte script and a
//! virtual clock.
//!
//! What it knows of real lines: an adapter that echoes what is sent (detected with
//! `--echo auto` from the first request whose answer cannot look like the request itself), a
//! collision when the echo differs, a transceiver's turnaround glitch before the answer, an
//! answer of unknown length ended by t3.5 of silence plus the adapter's latency (RTU) or by
//! CR LF (ASCII), a damaged answer (retried), a late answer to an earlier request (dropped: it
//! must reach no one), and after a timeout a unit whose next answer is not trusted for the
//! cache and whose late words are listened for and dropped once its client has its 0x0B.
//!
//! Its modules: `steps` (what the machine is configured with and says) and `master` (the serial
//! master's memory between requests).

use std::time::Duration;

use mbtap_proto::answer_end::{Verdict, judge_ascii, judge_rtu};
use mbtap_proto::parse_ascii;
use mbtap_proto::serial_line::SerialMode;

use crate::answer::check;

use crate::rules::GATEWAY_TARGET_FAILED;

mod steps;
pub use steps::{EchoMode, Ending, MasterConfig, Note, Reply, Step};

mod late;
mod master;
pub use late::{LateListener, turnaround_glitch};
pub use master::SerialMaster;

#[derive(Debug)]
enum Phase {
    /// The ADU is being written.
    Sending,
    /// Reading the frame back. `decided`: the adapter is known to echo.
    Echo {
        heard: Vec<u8>,
        decided: bool,
    },
    /// Reading the answer. `collision`: what came in place of the echo, judged whole: if it is
    /// no answer, it was a collision.
    Answer {
        buf: Vec<u8>,
        last: Duration,
        collision: Option<Vec<u8>>,
    },
    /// Quiet before a retry.
    Pause,
    Done,
}

/// One request with its retries.
#[derive(Debug)]
pub struct Transaction<'m> {
    master: &'m mut SerialMaster,
    unit: u8,
    pdu: &'m [u8],
    function: u8,
    adu: Vec<u8>,
    attempt: u32,
    /// When the request's last character left.
    sent: Duration,
    timeout: Duration,
    phase: Phase,
    notes: Vec<Note>,
    was_suspect: bool,
    flush: Option<Duration>,
    outcome: Option<Ending>,
}

impl Transaction<'_> {
    /// What happened since the last call, in order.
    pub fn take_notes(&mut self) -> Vec<Note> {
        std::mem::take(&mut self.notes)
    }

    /// The result, once the step is [`Step::Done`].
    #[must_use]
    pub fn outcome(&self) -> Option<&Ending> {
        self.outcome.as_ref()
    }

    fn attempt(&mut self) -> Step {
        self.attempt += 1;
        self.notes.push(Note::Request);
        self.phase = Phase::Sending;
        Step::Send(self.adu.clone())
    }

    /// The ADU was written at `now`. `drained`: the write returned when its last character
    /// had left (`tcdrain`, as with RTS direction control); otherwise it is on the wire one
    /// character time per byte later.
    pub fn sent(&mut self, now: Duration, drained: bool) -> Step {
        let on_wire = Duration::from_nanos(self.master.config.line.char_ns())
            .saturating_mul(u32::try_from(self.adu.len()).unwrap_or(u32::MAX));
        self.sent = if drained { now } else { now + on_wire };
        if self.unit == 0 {
            // Broadcast (Serial Line v1.02 §2.1): no answer; the turnaround delay follows.
            let reply = if self.master.config.broadcast_reply { broadcast_reply(self.pdu) } else { Reply::Silence };
            return self.finish(reply, self.sent + self.master.config.turnaround);
        }
        self.timeout = self.master.timeouts.get(self.unit);
        self.notes.push(Note::UnitTimeout(self.timeout));
        match self.master.echo_expected(self.function) {
            None => self.answer(now, Vec::new(), None),
            Some(decided) => {
                self.phase = Phase::Echo { heard: Vec::with_capacity(self.adu.len() + 64), decided };
                Step::WaitUntil(self.deadline())
            }
        }
    }

    fn deadline(&self) -> Duration {
        self.sent + self.timeout
    }

    /// Bytes read at `now`.
    pub fn bytes(&mut self, now: Duration, got: &[u8]) -> Step {
        match &mut self.phase {
            Phase::Echo { heard, decided } => {
                heard.extend_from_slice(got);
                let n = heard.len().min(self.adu.len());
                if !*decided && heard.get(..n) != self.adu.get(..n) {
                    // Not the frame: the adapter does not echo; these bytes start the answer.
                    let heard = std::mem::take(heard);
                    self.master.echo_found = Some(false);
                    return self.answer(now, heard, None);
                }
                if heard.len() >= self.adu.len() {
                    let mut heard = std::mem::take(heard);
                    return if heard.get(..self.adu.len()) == Some(self.adu.as_slice()) {
                        let rest = heard.split_off(self.adu.len());
                        if self.master.echo_found.is_none() && self.master.config.echo == EchoMode::Auto {
                            self.notes.push(Note::EchoFound);
                        }
                        self.master.echo_found = Some(true);
                        self.answer(now, rest, None)
                    } else {
                        self.answer(now, heard.clone(), Some(heard))
                    };
                }
                self.tick(now)
            }
            Phase::Answer { buf, last, .. } => {
                if self.master.config.monitored {
                    self.notes.push(Note::Heard { port: 1, bytes: got.to_vec() });
                }
                buf.extend_from_slice(got);
                // Bounded (a serial server streaming garbage grew this to gigabytes):
                // no answer is longer than the longest ADU, so older bytes cannot begin it.
                let cap = self.master.config.max_adu();
                if let Some(excess) = buf.len().checked_sub(cap).filter(|&n| n > 0) {
                    buf.drain(..excess);
                    self.notes.push(Note::Garbage(excess));
                }
                *last = now;
                self.judge(now, false)
            }
            // Bytes while sending or pausing: nobody asked; the next send drops stale input.
            Phase::Sending | Phase::Pause | Phase::Done => self.tick(now),
        }
    }

    /// The time is `now` and nothing (more) came.
    pub fn tick(&mut self, now: Duration) -> Step {
        let deadline = self.deadline();
        match &mut self.phase {
            Phase::Echo { heard, decided } => {
                if now < deadline {
                    return Step::WaitUntil(deadline);
                }
                // Too little came back in time. An echoing adapter gives the frame back whether
                // or not the unit answers: undecided, silence means no echo.
                let heard = std::mem::take(heard);
                match (*decided, heard.is_empty()) {
                    (true, true) => {
                        self.notes.push(Note::EchoMissing);
                        self.master.timeouts.timed_out(self.unit);
                        self.notes.push(Note::WaitedInVain(self.timeout));
                        self.retry_or_fail(now, now)
                    }
                    (true, false) => self.answer(now, heard.clone(), Some(heard)),
                    (false, _) => {
                        self.master.echo_found = Some(false);
                        self.answer(now, heard, None)
                    }
                }
            }
            Phase::Answer { buf, last, .. } => {
                let silent = !buf.is_empty() && now >= (*last + self.master.config.silence()).min(deadline);
                self.judge(now, silent)
            }
            Phase::Pause => self.attempt(),
            Phase::Sending => Step::Send(self.adu.clone()),
            Phase::Done => Step::Done,
        }
    }

    /// Starts reading the answer with `initial` bytes already in hand.
    fn answer(&mut self, now: Duration, initial: Vec<u8>, collision: Option<Vec<u8>>) -> Step {
        let mut last = self.sent;
        if !initial.is_empty() {
            if self.master.config.monitored {
                self.notes.push(Note::Heard { port: 1, bytes: initial.clone() });
            }
            last = now;
        }
        // Bytes already in hand are judged before waiting for more: the answer may be whole
        // (an ASCII answer that came in place of an echo waited for the 1 s silence).
        let judge_now = !initial.is_empty();
        self.phase = Phase::Answer { buf: initial, last, collision };
        if judge_now { self.judge(now, false) } else { self.next_wait(now) }
    }

    /// Judges the bytes in hand; `silent`: the silence that ends a frame has passed.
    fn judge(&mut self, now: Duration, mut silent: bool) -> Step {
        let config = &self.master.config;
        let Phase::Answer { buf, last, collision } = &mut self.phase else { return self.tick(now) };
        let strict = collision.is_some();
        loop {
            if config.mode == SerialMode::Rtu && turnaround_glitch(buf, self.unit) {
                // A transceiver's turnaround glitch before the answer (00, FE or FF): dropped,
                // as `read` and the sniffer do (the bridge answered 0x0B).
                buf.remove(0);
            }
            let verdict = match config.mode {
                SerialMode::Rtu => judge_rtu(buf, self.unit, self.function, silent),
                SerialMode::Ascii => judge_ascii(buf, self.unit, silent),
            };
            match verdict {
                Verdict::Pending => break,
                Verdict::Answer { len } => {
                    let frame = buf.get(..len).unwrap_or_default();
                    // The answer's unit and PDU, as its frame carries them.
                    let heard = match config.mode {
                        SerialMode::Rtu => frame
                            .split_first()
                            .and_then(|(&u, rest)| Some((u, rest.get(..rest.len().checked_sub(2)?)?.to_vec()))),
                        SerialMode::Ascii => {
                            let start = frame.iter().position(|&b| b == b':').unwrap_or(0);
                            parse_ascii(frame.get(start..).unwrap_or_default())
                                .ok()
                                .map(|f| (f.unit(), f.pdu().to_vec()))
                        }
                    };
                    let misfit = heard.as_ref().and_then(|(u, p)| check(self.unit, self.pdu, *u, p).err());
                    let pdu = heard.map(|(_, p)| p);
                    if let Some(why) = misfit {
                        // Another request's answer (a late one after a timeout: another
                        // quantity, address or function): never this client's. Dropped,
                        // counted; the real answer may follow it.
                        self.notes.push(Note::LateAnswer(why));
                        buf.drain(..len);
                        silent = false;
                        if buf.is_empty() {
                            break;
                        }
                        continue;
                    }
                    let last = *last;
                    return self.answered(now, pdu, last);
                }
                Verdict::BadCheck => {
                    self.notes.push(Note::CrcError);
                    let last = *last;
                    return self.answered(now, None, last);
                }
                // `strict`: the answer must begin with the first byte (what came in place of an
                // echo is judged whole: anything else is a collision).
                Verdict::Foreign if strict => {
                    let last = *last;
                    return self.answered(now, None, last);
                }
                Verdict::Foreign => {
                    buf.clear();
                    break;
                }
            }
        }
        self.next_wait(now)
    }

    /// Waits on, or ends at the deadline.
    fn next_wait(&mut self, now: Duration) -> Step {
        let deadline = self.deadline();
        let Phase::Answer { buf, last, .. } = &self.phase else { return self.tick(now) };
        if now >= deadline {
            if !buf.is_empty() {
                self.notes.push(Note::CrcError);
            }
            self.notes.push(Note::Timeout);
            let last = (*last).max(now);
            return self.answered(now, None, last);
        }
        // Bytes in hand wait for the silence that ends them; once it has passed and they are still
        // not a whole answer, only more bytes or the deadline can decide (the fuzzer found a
        // buffer that stays pending after its silence: the machine asked to wait until a moment
        // already past, and the shell spun on it until the deadline).
        let quiet = *last + self.master.config.silence();
        let quiet_until = if buf.is_empty() || now >= quiet { deadline } else { quiet.min(deadline) };
        Step::WaitUntil(quiet_until)
    }

    /// The answer phase ended: with the answer's PDU, or none; the line last busy at `last`.
    fn answered(&mut self, now: Duration, pdu: Option<Vec<u8>>, last: Duration) -> Step {
        let collision = match std::mem::replace(&mut self.phase, Phase::Pause) {
            Phase::Answer { collision, .. } => collision,
            _ => None,
        };
        if let Some(pdu) = pdu {
            if collision.is_some() {
                // What came in place of the echo was the answer: the adapter did not echo.
                self.notes.push(Note::EchoMissing);
            }
            self.master.timeouts.answered(self.unit, last.saturating_sub(self.sent));
            return self.finish(Reply::Pdu(pdu), last);
        }
        if let Some(heard) = collision {
            // The monitor sees what was really on the line in place of the request.
            if self.master.config.monitored {
                self.notes.push(Note::Heard { port: 0, bytes: heard });
            }
            self.notes.push(Note::Collision);
            return self.retry_or_fail(now, last);
        }
        if last.saturating_sub(self.sent) >= self.timeout {
            self.master.timeouts.timed_out(self.unit);
            self.notes.push(Note::WaitedInVain(self.timeout));
            // A unit slower than the timeout answers later: that answer must reach no one
            // (the answer to h150 went to the client asking h160). The line is
            // listened to once this client has its 0x0B (a retry of the same request may take
            // the late answer: it is that request's).
            self.master.suspect.insert(self.unit);
            self.flush = Some(self.timeout);
        }
        self.retry_or_fail(now, last)
    }

    /// Retries after the line has been quiet for its guard since `last` (never a moment before
    /// `now`: a damaged answer judged late needs no wait), or gives up with 0x0B.
    fn retry_or_fail(&mut self, now: Duration, last: Duration) -> Step {
        if self.attempt <= self.master.config.retries {
            self.phase = Phase::Pause;
            return Step::PauseUntil((last + self.master.config.line_guard()).max(now));
        }
        self.finish(Reply::Gateway(GATEWAY_TARGET_FAILED), last)
    }

    fn finish(&mut self, reply: Reply, last: Duration) -> Step {
        let cacheable =
            matches!(reply, Reply::Pdu(_)) && !self.was_suspect && !self.master.suspect.contains(&self.unit);
        self.phase = Phase::Done;
        self.outcome = Some(Ending { reply, last, cacheable, flush: self.flush.take() });
        Step::Done
    }
}

/// The normal response a write would get, for `--broadcast-reply`: 05/06 echo the request,
/// 0F/10 answer address and quantity (MAP v1.1b3 §6.5, §6.6, §6.11, §6.12).
fn broadcast_reply(pdu: &[u8]) -> Reply {
    match pdu.first() {
        Some(0x05 | 0x06 | 0x0F | 0x10) if pdu.len() >= 5 => Reply::Pdu(pdu.get(..5).unwrap_or_default().to_vec()),
        _ => Reply::Silence,
    }
}

#[cfg(test)]
mod tests {
    use std::collections::{BTreeMap, VecDeque};

    use super::*;
    use crate::timeouts::{TimeoutMode, Timeouts};
    use mbtap_proto::serial_line::LineSettings;
    use mbtap_proto::{encode_ascii, encode_rtu};

    /// Read holding registers 0–1 (MAP v1.1b3 §6.3): function 03, address 0000, quantity 0002.
    const READ_TWO: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x02];
    /// Its normal answer: function 03, byte count 04, values 000A 000B.
    const ANSWER_TWO: [u8; 6] = [0x03, 0x04, 0x00, 0x0A, 0x00, 0x0B];
    /// Another request's answer (one register: byte count 02, value 0063): a late one.
    const ANSWER_ONE: [u8; 4] = [0x03, 0x02, 0x00, 0x63];
    /// Write single register 1 = 3 (MAP v1.1b3 §6.6), for broadcasts.
    const WRITE_ONE: [u8; 5] = [0x06, 0x00, 0x01, 0x00, 0x03];
    /// 100 ms: the response timeout of these tests.
    const TIMEOUT: Duration = Duration::from_millis(100);

    fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        encode_rtu(unit, pdu, &mut out);
        out
    }

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    fn master(mode: SerialMode, echo: EchoMode, retries: u32) -> SerialMaster {
        let config = MasterConfig {
            line: LineSettings::default(),
            mode,
            echo,
            retries,
            turnaround: Duration::ZERO,
            broadcast_reply: false,
            latency: Duration::ZERO,
            monitored: true,
        };
        SerialMaster::new(config, Timeouts::new(TIMEOUT, TimeoutMode::Fixed, BTreeMap::new()))
    }

    /// A virtual line: the bytes the devices (or the adapter) deliver, each at its time, and
    /// what the master wrote.
    #[derive(Default)]
    struct Line {
        at: Duration,
        script: VecDeque<(Duration, Vec<u8>)>,
        sent: Vec<(Duration, Vec<u8>)>,
    }

    impl Line {
        fn with(script: &[(u64, &[u8])]) -> Self {
            Self { script: script.iter().map(|(t, b)| (ms(*t), b.to_vec())).collect(), ..Self::default() }
        }

        /// Runs one transaction to its end: the outcome and every note.
        fn drive(&mut self, m: &mut SerialMaster, unit: u8, pdu: &[u8]) -> (Ending, Vec<Note>) {
            let (mut t, mut step) = m.transaction(unit, pdu);
            let mut notes = Vec::new();
            loop {
                notes.extend(t.take_notes());
                step = match step {
                    Step::Send(adu) => {
                        // The shell drops stale input before each send.
                        while self.script.front().is_some_and(|(at, _)| *at < self.at) {
                            self.script.pop_front();
                        }
                        self.sent.push((self.at, adu));
                        t.sent(self.at, false)
                    }
                    Step::WaitUntil(until) => match self.script.front() {
                        Some((at, _)) if *at <= until => {
                            let (at, bytes) = self.script.pop_front().unwrap();
                            self.at = self.at.max(at);
                            t.bytes(self.at, &bytes)
                        }
                        _ => {
                            self.at = self.at.max(until);
                            t.tick(self.at)
                        }
                    },
                    Step::PauseUntil(until) => {
                        self.at = self.at.max(until);
                        t.tick(self.at)
                    }
                    Step::Done => break,
                };
            }
            notes.extend(t.take_notes());
            (t.outcome().cloned().unwrap(), notes)
        }
    }

    fn count(notes: &[Note], want: &Note) -> usize {
        notes.iter().filter(|n| *n == want).count()
    }

    #[test]
    fn an_answer_is_passed_on_and_may_fill_the_cache() {
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 0);
        let answer = rtu(1, &ANSWER_TWO);
        let mut line = Line::with(&[(10, &answer)]);
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(out.last, ms(10));
        assert!(out.cacheable);
        assert_eq!(out.flush, None);
        assert_eq!(line.sent, [(Duration::ZERO, rtu(1, &READ_TWO))]);
        assert_eq!(count(&notes, &Note::Request), 1);
        assert!(notes.contains(&Note::UnitTimeout(TIMEOUT)));
    }

    /// An answer behind a transceiver's turnaround glitch (FE), arriving in two reads, is taken:
    /// the glitch is set aside, never a 0x0B.
    #[test]
    fn a_turnaround_glitch_before_an_answer_in_two_reads_is_set_aside() {
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 0);
        let answer = rtu(1, &ANSWER_TWO);
        let mut glitched = vec![0xFE];
        glitched.extend_from_slice(&answer[..4]);
        let mut line = Line::with(&[(10, &glitched), (12, &answer[4..])]);
        let (out, _) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert!(turnaround_glitch(&[0x00, 0x11, 0x03], 0x11));
        assert!(!turnaround_glitch(&[0xFE, 0x02, 0x03], 1), "another unit's frame is no glitch of ours");
        assert!(!turnaround_glitch(&[0xFE, 0xFE, 0x03], 0xFE), "unit 254's own address");
    }

    #[test]
    fn a_timeout_is_retried_and_the_unit_stays_suspect_for_the_cache() {
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 1);
        let answer = rtu(1, &ANSWER_TWO);
        // Nothing to the first request; the retry leaves ~107 ms in and is answered at 150 ms.
        let mut line = Line::with(&[(150, &answer)]);
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(line.sent.len(), 2);
        let guard = m.config.line_guard();
        let first_sent = Duration::from_nanos(m.config.line.char_ns() * 8);
        assert_eq!(line.sent[1].0, first_sent + TIMEOUT + guard, "the retry waits t3.5 after the timeout");
        assert_eq!(count(&notes, &Note::Request), 2);
        assert_eq!(count(&notes, &Note::Timeout), 1);
        assert_eq!(count(&notes, &Note::WaitedInVain(TIMEOUT)), 1);
        assert!(!out.cacheable, "an answer after a timeout may be the late one");
        assert_eq!(out.flush, Some(TIMEOUT));
        // The next answer of that unit is still not trusted; the one after is.
        let mut line = Line::with(&[(10, &answer)]);
        assert!(!line.drive(&mut m, 1, &READ_TWO).0.cacheable);
        let mut line = Line::with(&[(10, &answer)]);
        assert!(line.drive(&mut m, 1, &READ_TWO).0.cacheable);
    }

    #[test]
    fn no_answer_at_all_is_0b_after_every_retry() {
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 2);
        let mut line = Line::default();
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Gateway(GATEWAY_TARGET_FAILED));
        assert_eq!(line.sent.len(), 3);
        assert_eq!(count(&notes, &Note::Timeout), 3);
    }

    /// A slow unit's late answer to h150 never reaches the client asking h160.
    #[test]
    fn a_late_answer_to_another_request_reaches_no_one() {
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 0);
        let (late, answer) = (rtu(1, &ANSWER_ONE), rtu(1, &ANSWER_TWO));
        let mut line = Line::with(&[(6, &late), (20, &answer)]);
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(notes.iter().filter(|n| matches!(n, Note::LateAnswer(_))).count(), 1);
    }

    #[test]
    fn a_damaged_answer_is_retried() {
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 1);
        let answer = rtu(1, &ANSWER_TWO);
        let mut damaged = answer.clone();
        damaged[4] ^= 0x40;
        let mut line = Line::with(&[(10, &damaged), (40, &answer)]);
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(count(&notes, &Note::CrcError), 1);
        assert_eq!(line.sent.len(), 2);
        assert!(out.cacheable, "a damaged answer is no timeout");
    }

    #[test]
    fn an_echoing_adapter_is_found_and_its_echo_consumed() {
        let mut m = master(SerialMode::Rtu, EchoMode::Auto, 0);
        let (request, answer) = (rtu(1, &READ_TWO), rtu(1, &ANSWER_TWO));
        let mut line = Line::with(&[(5, &request), (15, &answer)]);
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(count(&notes, &Note::EchoFound), 1);
        // Known now: the echo and the answer in one read.
        let mut both = request.clone();
        both.extend_from_slice(&answer);
        let mut line = Line::with(&[(15, &both)]);
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(count(&notes, &Note::EchoFound), 0, "said once");
    }

    #[test]
    fn without_an_echo_auto_takes_the_first_bytes_for_the_answer() {
        let mut m = master(SerialMode::Rtu, EchoMode::Auto, 0);
        let answer = rtu(1, &ANSWER_TWO);
        let mut line = Line::with(&[(10, &answer)]);
        assert_eq!(line.drive(&mut m, 1, &READ_TWO).0.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(m.echo_expected(0x03), None, "decided: no echo");
    }

    #[test]
    fn a_different_echo_is_a_collision_counted_and_seen() {
        let mut m = master(SerialMode::Rtu, EchoMode::On, 0);
        // Another driver's bytes over the request: the same length, not a frame.
        let garbled = [0x01, 0x03, 0x00, 0x00, 0x7F, 0x02, 0xC4, 0x0B];
        let mut line = Line::with(&[(5, &garbled)]);
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Gateway(GATEWAY_TARGET_FAILED));
        assert_eq!(count(&notes, &Note::Collision), 1);
        assert!(notes.contains(&Note::Heard { port: 0, bytes: garbled.to_vec() }));
    }

    #[test]
    fn a_missing_echo_is_a_timeout_of_its_own() {
        let mut m = master(SerialMode::Rtu, EchoMode::On, 0);
        let mut line = Line::default();
        let (out, notes) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Gateway(GATEWAY_TARGET_FAILED));
        assert_eq!(count(&notes, &Note::EchoMissing), 1);
        assert_eq!(count(&notes, &Note::WaitedInVain(TIMEOUT)), 1);
    }

    #[test]
    fn a_broadcast_waits_for_nothing() {
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 3);
        m.config.turnaround = ms(50);
        let mut line = Line::default();
        let (out, notes) = line.drive(&mut m, 0, &WRITE_ONE);
        assert_eq!(out.reply, Reply::Silence);
        let on_wire = Duration::from_nanos(m.config.line.char_ns() * 8);
        assert_eq!(out.last, on_wire + ms(50), "the turnaround delay follows the broadcast");
        assert_eq!(count(&notes, &Note::Request), 1);
        m.config.broadcast_reply = true;
        assert_eq!(line.drive(&mut m, 0, &WRITE_ONE).0.reply, Reply::Pdu(WRITE_ONE.to_vec()));
    }

    #[test]
    fn an_ascii_answer_ends_at_its_cr_lf() {
        let mut m = master(SerialMode::Ascii, EchoMode::Off, 0);
        let mut answer = Vec::new();
        encode_ascii(1, &ANSWER_TWO, &mut answer);
        let mut line = Line::with(&[(30, &answer[..5]), (31, &answer[5..])]);
        let (out, _) = line.drive(&mut m, 1, &READ_TWO);
        assert_eq!(out.reply, Reply::Pdu(ANSWER_TWO.to_vec()));
        assert_eq!(out.last, ms(31), "no 1 s silence waited: the frame is whole");
    }

    #[test]
    fn the_late_listener_ends_at_the_silence_after_the_last_late_byte() {
        let m = master(SerialMode::Rtu, EchoMode::Off, 0);
        let mut l = LateListener::new(&m.config, TIMEOUT, ms(200));
        assert_eq!(l.wait_until(), ms(300));
        assert!(l.bytes(ms(250), 4), "the first late bytes are one late answer");
        assert!(!l.bytes(ms(251), 5));
        let silence = Duration::from_nanos(m.config.line.t35_ns()) + ms(1);
        assert_eq!(l.wait_until(), ms(251) + silence);
        assert_eq!(l.last(), ms(251));
        // Noise that never stops: held at most twice the window.
        let mut noisy = LateListener::new(&m.config, TIMEOUT, ms(0));
        noisy.bytes(ms(199), 1);
        assert_eq!(noisy.wait_until(), ms(200));
    }

    /// A serial server streaming garbage does not hold the line twice the window after every
    /// timeout: more bytes than the longest answer end the listening.
    #[test]
    fn garbage_stream_ends_the_late_listener_at_once() {
        let m = master(SerialMode::Rtu, EchoMode::Off, 0);
        let mut l = LateListener::new(&m.config, TIMEOUT, ms(0));
        l.bytes(ms(1), 200);
        assert!(!l.garbage());
        l.bytes(ms(2), 200);
        assert!(l.garbage());
        assert_eq!(l.wait_until(), ms(2), "nothing more to wait for");
    }

    /// A server streaming garbage that begins with the unit's address costs at most one ADU
    /// of buffer, however long it streams.
    #[test]
    fn garbage_stream_the_answer_buffer_holds_at_most_one_adu() {
        /// A vendor request (function 0x41, MAP v1.1b3 §5: user-defined): its answer's length
        /// is unknown, so only a silence ends it.
        const VENDOR: [u8; 2] = [0x41, 0x00];
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 0);
        let (mut t, _) = m.transaction(1, &VENDOR);
        let mut step = t.sent(ms(0), true);
        // 01 41 and then a stream with no silence: never a whole answer.
        let mut garbage = vec![0x01, 0x41];
        garbage.extend(std::iter::repeat_n(0x41, 10_000));
        let mut dropped = 0;
        for (i, chunk) in garbage.chunks(512).enumerate() {
            step = t.bytes(ms(1 + i as u64 / 10), chunk);
            dropped += t.take_notes().iter().map(|n| if let Note::Garbage(b) = n { *b } else { 0 }).sum::<usize>();
        }
        assert!(dropped >= 10_002 - 256, "{dropped} bytes dropped");
        assert!(matches!(step, Step::WaitUntil(_)), "{step:?}");
        assert_eq!(t.tick(TIMEOUT + ms(1)), Step::Done);
        assert_eq!(t.outcome().map(|o| o.reply.clone()), Some(Reply::Gateway(GATEWAY_TARGET_FAILED)));
    }

    /// Bytes that stay pending after their silence — an answer to a two-register read whose byte
    /// count says 5 — wait for the deadline: the machine never asks to wait until a moment already
    /// past (the shell would spin on it). Found by the `gateway` fuzz target.
    #[test]
    fn bytes_still_pending_after_their_silence_wait_for_the_deadline_not_the_past() {
        // Unit 1, function 03, byte count 05, then four bytes of values and one more.
        const ODD_ANSWER: [u8; 7] = [0x01, 0x03, 0x05, 0x01, 0x00, 0x05, 0xF6];
        let mut m = master(SerialMode::Rtu, EchoMode::Off, 0);
        let (mut t, step) = m.transaction(1, &READ_TWO);
        assert!(matches!(step, Step::Send(_)));
        let deadline = match t.sent(Duration::ZERO, true) {
            Step::WaitUntil(at) => at,
            other => panic!("{other:?}"),
        };
        assert_eq!(deadline, TIMEOUT);
        let _ = t.bytes(ms(10), &ODD_ANSWER);
        // 20 ms: well past the bytes' silence (t3.5 + 1 ms), well before the deadline.
        match t.tick(ms(20)) {
            Step::WaitUntil(at) => assert_eq!(at, deadline, "waits for more bytes or the deadline"),
            other => panic!("{other:?}"),
        }
        match t.tick(deadline) {
            Step::Done => assert_eq!(t.outcome().unwrap().reply, Reply::Gateway(GATEWAY_TARGET_FAILED)),
            other => panic!("{other:?}"),
        }
    }

    /// Regression (found by the `gateway` fuzz target): a collision judged when the
    /// shell next looked — long after the last byte — asked for a pause until a moment already
    /// past. A pause never ends before it is asked for.
    #[test]
    fn a_retry_never_pauses_until_a_moment_already_past() {
        // Another driver's bytes over the request: the same length, not a frame.
        const GARBLED: [u8; 8] = [0x01, 0x03, 0x00, 0x02, 0xC4, 0x02, 0xC4, 0x0B];
        let mut m = master(SerialMode::Rtu, EchoMode::On, 1);
        let (mut t, _) = m.transaction(1, &READ_TWO);
        let _ = t.sent(Duration::ZERO, true);
        let _ = t.bytes(ms(5), &GARBLED);
        match t.tick(ms(15)) {
            Step::PauseUntil(at) => assert!(at >= ms(15), "{at:?}"),
            other => panic!("{other:?}"),
        }
        assert!(t.take_notes().contains(&Note::Collision));
    }
}
