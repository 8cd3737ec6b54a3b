//! A virtual line with a master on it: the master cycles through a SCADA-like poll list, the
//! simulated slaves answer, and every frame is placed in time as the line would carry it
//! (character time from the line settings, a turnaround before each answer). Time is simulated
//! — nanoseconds since the start — so `demo`, tests and benchmarks share this code.

use mbtap_analysis::framer::LineSettings;
use mbtap_proto::{encode_ascii, encode_rtu};

use super::{Slave, world};

/// One frame on the line: when its last byte arrived (ns since the start) and its bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LineFrame {
    pub end_ns: u64,
    pub bytes: Vec<u8>,
}

/// The master and its slaves.
#[derive(Debug, Clone)]
pub struct VirtualBus {
    slaves: Vec<Slave>,
    polls: Vec<(u8, Vec<u8>)>,
    next: usize,
    now_ns: u64,
    char_ns: u64,
    /// Time from the end of one transaction to the next request.
    pub interval_ns: u64,
    /// A slave's time from the end of a request to its answer.
    pub turnaround_ns: u64,
    /// How long the master waits for an answer before it moves on (Serial Line v1.02 §2.4.1
    /// leaves it to the implementation; 1 s is the common default).
    pub master_timeout_ns: u64,
    /// Faults to inject, each into every `fault_every`-th transaction.
    pub faults: Vec<Fault>,
    pub fault_every: u32,
    /// ASCII framing (Serial Line v1.02 §2.5.2) instead of RTU.
    pub ascii: bool,
    count: u32,
    rng: u64,
}

/// A fault the line can suffer, for training and tests (fault injection).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Fault {
    /// One bit of a response flipped on the wire: a bad CRC.
    Corrupt,
    /// A burst of random bytes on the idle line before a request.
    Noise,
    /// A slave that pauses in the middle of its answer (longer than t1.5, Serial Line v1.02
    /// §2.5.1.1), as a slow controller servicing an interrupt does.
    SlowSlave,
    /// The addressed slave does not answer: the master times out.
    SilentSlave,
    /// A second device set to the first slave's address answers with it; the drivers fight and
    /// the line carries the wired-AND of both answers (a dominant 0 wins on RS-485 fail-safe
    /// biasing). Only that address suffers; other units' turns pass unharmed.
    Collision,
    /// A master that sends its next request before t3.5 of silence has passed.
    FastMaster,
    /// A second master on the line: just after the first master's request, when the line has
    /// been quiet for t3.5 (the addressed slave is still turning around), it sends a request of
    /// its own to another unit. The slaves wait for the line to go quiet, then both answer:
    /// first the one the first master asked, then the other.
    SecondMaster,
    /// Not a line fault: the MK4's running pump trips on overcurrent, and the alarm log
    /// records it ([`world::mk4_pump_trip`]).
    PumpTrip,
    /// A unit that loses power for a while: the line's last unit stops answering from the 20th
    /// to the 40th second of every minute of bus time (its master times out each poll), then is
    /// back. Not one of the faults that take turns: it holds for its whole window, and `all`
    /// leaves it out.
    Outage,
}

/// Bus time within each minute when [`Fault::Outage`] silences its unit.
const OUTAGE_WINDOW_S: std::ops::Range<u64> = 20..40;

impl Fault {
    /// Every fault, for `--fault all`.
    pub const ALL: [Self; 8] = [
        Self::Corrupt,
        Self::Noise,
        Self::SlowSlave,
        Self::SilentSlave,
        Self::Collision,
        Self::FastMaster,
        Self::SecondMaster,
        Self::PumpTrip,
    ];
}

impl VirtualBus {
    /// A bus with `slaves`, polled by the built-in list of each one's profile.
    #[must_use]
    pub fn new(slaves: Vec<Slave>, line: LineSettings) -> Self {
        let mut polls = Vec::new();
        for s in &slaves {
            for (function, start, quantity) in super::poll_list::poll_list(s.profile()) {
                let mut pdu = vec![function];
                pdu.extend_from_slice(&start.to_be_bytes());
                pdu.extend_from_slice(&quantity.to_be_bytes());
                polls.push((s.address(), pdu));
            }
        }
        let char_ns = u64::from(line.bits_per_char()) * 1_000_000_000 / u64::from(line.baud.max(1));
        Self {
            slaves,
            polls,
            next: 0,
            now_ns: 0,
            char_ns,
            interval_ns: 100_000_000,
            turnaround_ns: 3_000_000,
            master_timeout_ns: 1_000_000_000,
            faults: Vec::new(),
            fault_every: 4,
            ascii: false,
            count: 0,
            rng: 0x9E37_79B9_7F4A_7C15,
        }
    }

    /// Polls in the list (0: nothing to poll).
    #[must_use]
    pub fn poll_count(&self) -> usize {
        self.polls.len()
    }

    /// The next transaction: the request and, when a slave answers, the response — with this
    /// transaction's fault, if one is due.
    pub fn next_transaction(&mut self) -> Vec<LineFrame> {
        let Some((unit, pdu)) = self.polls.get(self.next).cloned() else { return Vec::new() };
        self.next = (self.next + 1) % self.polls.len();
        self.count = self.count.wrapping_add(1);
        let mut fault = self.due_fault();
        if fault == Some(Fault::Collision) && self.slaves.first().map(Slave::address) != Some(unit) {
            fault = None;
        }
        let mut frames = Vec::with_capacity(4);
        if fault == Some(Fault::Noise) {
            let len = 3 + usize::try_from(self.random() % 5).unwrap_or(0);
            let noise: Vec<u8> = (0..len).map(|_| self.random().to_le_bytes()[0]).collect();
            self.now_ns = self.now_ns.saturating_add(self.duration(noise.len()));
            frames.push(LineFrame { end_ns: self.now_ns, bytes: noise });
            // Quiet long enough that the request starts a frame of its own.
            self.now_ns = self.now_ns.saturating_add(self.duration(8));
        }
        let mut request = Vec::with_capacity(pdu.len() * 2 + 5);
        self.encode(unit, &pdu, &mut request);
        let request_end = self.now_ns.saturating_add(self.duration(request.len()));
        frames.push(LineFrame { end_ns: request_end, bytes: request });
        let seconds = f64::from(u32::try_from(request_end / 1_000_000).unwrap_or(u32::MAX)) / 1000.0;
        let mut answers = Vec::new();
        for s in &mut self.slaves {
            if fault == Some(Fault::PumpTrip) {
                world::mk4_pump_trip(s, seconds);
            }
            world::step(s, seconds);
            if let Some(answer) = s.handle(unit, &pdu) {
                answers.push(answer);
            }
        }
        let mut end;
        let powered = !self.out(unit, request_end);
        let answer = answers.first().filter(|_| fault != Some(Fault::SilentSlave) && powered);
        // The second master's request and its answer, sent while the first one's is due.
        let second =
            if fault == Some(Fault::SecondMaster) && answer.is_some() { self.second_master(unit) } else { None };
        let mut quiet_from = request_end;
        if let Some((request, _)) = &second {
            // It waits for four characters of silence (more than t3.5), then sends.
            quiet_from = request_end.saturating_add(self.duration(4)).saturating_add(self.duration(request.len()));
            frames.push(LineFrame { end_ns: quiet_from, bytes: request.clone() });
        }
        match answer {
            None => end = request_end.saturating_add(self.master_timeout_ns),
            Some(answer) => {
                let mut response = Vec::with_capacity(answer.len() * 2 + 5);
                self.encode(unit, answer, &mut response);
                self.apply_response_fault(fault, &mut response);
                let start = quiet_from.saturating_add(self.turnaround_ns);
                if fault == Some(Fault::SlowSlave) && response.len() > 2 {
                    let tail = response.split_off(response.len() / 2);
                    let first_end = start.saturating_add(self.duration(response.len()));
                    frames.push(LineFrame { end_ns: first_end, bytes: response });
                    // A pause of five characters: past t1.5 and t3.5 both.
                    end = first_end.saturating_add(self.duration(5)).saturating_add(self.duration(tail.len()));
                    frames.push(LineFrame { end_ns: end, bytes: tail });
                } else {
                    end = start.saturating_add(self.duration(response.len()));
                    frames.push(LineFrame { end_ns: end, bytes: response });
                }
            }
        }
        if let Some((_, response)) = second {
            end = end.saturating_add(self.turnaround_ns).saturating_add(self.duration(response.len()));
            frames.push(LineFrame { end_ns: end, bytes: response });
        }
        self.now_ns = if fault == Some(Fault::FastMaster) {
            // One character of silence instead of at least three and a half.
            end.saturating_add(self.char_ns)
        } else {
            end.saturating_add(self.interval_ns)
        };
        frames
    }

    /// The second master's request — the first poll of a unit other than `busy` — and that
    /// unit's answer, encoded; `None` on a bus with one unit.
    fn second_master(&mut self, busy: u8) -> Option<(Vec<u8>, Vec<u8>)> {
        let (unit, pdu) = self.polls.iter().find(|(u, _)| *u != busy).cloned()?;
        let answer = self.slaves.iter_mut().find_map(|s| s.handle(unit, &pdu))?;
        let mut request = Vec::new();
        self.encode(unit, &pdu, &mut request);
        let mut response = Vec::new();
        self.encode(unit, &answer, &mut response);
        Some((request, response))
    }

    fn encode(&self, unit: u8, pdu: &[u8], out: &mut Vec<u8>) {
        if self.ascii { encode_ascii(unit, pdu, out) } else { encode_rtu(unit, pdu, out) }
    }

    /// The fault of this transaction: faults take turns, one every `fault_every` transactions.
    fn due_fault(&self) -> Option<Fault> {
        let turns: Vec<Fault> = self.faults.iter().copied().filter(|f| *f != Fault::Outage).collect();
        if turns.is_empty() || self.fault_every == 0 || !self.count.is_multiple_of(self.fault_every) {
            return None;
        }
        let turn = usize::try_from(self.count.checked_div(self.fault_every)?).unwrap_or(0);
        turns.get(turn % turns.len()).copied()
    }

    /// Whether `unit` is in its [`Fault::Outage`] window at bus time `t_ns`.
    fn out(&self, unit: u8, t_ns: u64) -> bool {
        self.faults.contains(&Fault::Outage)
            && self.slaves.last().map(Slave::address) == Some(unit)
            && OUTAGE_WINDOW_S.contains(&(t_ns / 1_000_000_000 % 60))
    }

    fn apply_response_fault(&mut self, fault: Option<Fault>, response: &mut [u8]) {
        match fault {
            Some(Fault::Corrupt) => {
                let i = usize::try_from(self.random()).unwrap_or(0) % response.len().max(1);
                let bit = self.random() % 8;
                if let Some(b) = response.get_mut(i) {
                    *b ^= 1 << bit;
                }
            }
            Some(Fault::Collision) => {
                // The other slave's answer: the same frame shape with different data.
                for b in response.iter_mut().skip(3) {
                    *b &= self.random().to_le_bytes()[0];
                }
            }
            _ => {}
        }
    }

    /// xorshift64: deterministic, so a fault run can be replayed exactly.
    fn random(&mut self) -> u64 {
        let mut x = self.rng;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.rng = x;
        x
    }

    fn duration(&self, bytes: usize) -> u64 {
        self.char_ns.saturating_mul(u64::try_from(bytes).unwrap_or(u64::MAX))
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use mbtap_proto::parse_rtu;

    /// A profile mbtap has no poll list for: holding 10–12 and 20, input 0–1.
    const OTHER: &str = "[profile]\nname = \"other\"\ndevice = \"Other\"\n\n\
        [[holding_registers]]\naddresses = [10, 12]\nname = \"H{n}\"\n\n\
        [[holding_registers]]\naddress = 20\nname = \"H20\"\n\n\
        [[input_registers]]\naddresses = [0, 1]\nname = \"I{n}\"\n";

    /// Regression: `simulate --poll --device FILE@N` polled nothing for a profile
    /// without a built-in poll list, and the line loop then spun without end, `--duration` unseen.
    #[test]
    fn a_profile_without_a_poll_list_is_polled_over_its_mapped_runs() {
        let p = mbtap_device::profile::loader::load("other.toml", OTHER).unwrap();
        let mut bus = VirtualBus::new(vec![Slave::new(Arc::new(p), 7)], LineSettings::default());
        assert_eq!(bus.poll_count(), 3, "holding 10–12, holding 20, input 0–1");
        for _ in 0..3 {
            let frames = bus.next_transaction();
            assert_eq!(frames.len(), 2, "a request and its answer");
            let answer = parse_rtu(&frames[1].bytes).unwrap();
            assert!(answer.check_ok() && answer.pdu[0] & 0x80 == 0, "{:02X?}", frames[1].bytes);
        }
    }

    fn bus() -> VirtualBus {
        let slaves = [("mk4", 1), ("display", 5), ("mkzp", 17)]
            .map(|(n, a)| Slave::new(Arc::new(mbtap_device::profile::builtin::get(n).unwrap().unwrap()), a));
        VirtualBus::new(slaves.to_vec(), LineSettings::default())
    }

    #[test]
    fn every_poll_is_answered_without_an_exception() {
        let mut b = bus();
        assert_eq!(b.poll_count(), 10);
        for _ in 0..b.poll_count() {
            let frames = b.next_transaction();
            assert_eq!(frames.len(), 2, "{frames:?}");
            let response = parse_rtu(&frames[1].bytes).unwrap();
            assert_eq!(response.crc_received, response.crc_computed);
            assert!(response.pdu[0] < 0x80, "exception to {:02X?}: {:02X?}", frames[0].bytes, frames[1].bytes);
        }
    }

    #[test]
    fn frames_are_placed_in_time_like_the_line() {
        let mut b = bus();
        let frames = b.next_transaction();
        // 8-byte request at 19200 8E1: 11 bits × 8 = 88 bits ≈ 4.58 ms.
        assert_eq!(frames[0].end_ns, 8 * (11 * 1_000_000_000 / 19_200));
        let response_chars = u64::try_from(frames[1].bytes.len()).unwrap();
        assert_eq!(frames[1].end_ns, frames[0].end_ns + 3_000_000 + response_chars * (11 * 1_000_000_000 / 19_200));
        let next = b.next_transaction();
        assert!(next[0].end_ns > frames[1].end_ns + 100_000_000);
    }

    #[test]
    fn faults_take_turns_and_leave_the_other_transactions_alone() {
        let mut b = bus();
        b.faults = vec![Fault::SilentSlave];
        let answered: Vec<bool> = (0..12).map(|_| b.next_transaction().len() == 2).collect();
        // Transactions 4, 8 and 12 (counting from 1) are the silent ones.
        let expected: Vec<bool> = (1..=12).map(|n| n % 4 != 0).collect();
        assert_eq!(answered, expected);
    }

    #[test]
    fn every_fault_keeps_the_bus_going() {
        for every in [0, 1, 2, 7] {
            let mut b = bus();
            b.faults = Fault::ALL.to_vec();
            b.fault_every = every;
            let mut last = 0;
            for _ in 0..200 {
                let frames = b.next_transaction();
                assert!(!frames.is_empty());
                for f in &frames {
                    assert!(f.end_ns > last, "time moves forward");
                    last = f.end_ns;
                }
            }
        }
    }

    /// A unit that loses power, for DDEATH and DBIRTH — silent through its window of
    /// every minute, answering before and after; the other units never miss a turn.
    #[test]
    fn an_outage_silences_the_last_unit_for_its_window_only() {
        let mut b = bus();
        b.faults = vec![Fault::Outage];
        let last = b.slaves.last().map(Slave::address).unwrap();
        let (mut silent_in, mut answered_in, mut answered_out, mut others_missed) = (0, 0, 0, 0);
        while b.now_ns < 70 * 1_000_000_000 {
            let frames = b.next_transaction();
            let unit = frames[0].bytes[0];
            let in_window = OUTAGE_WINDOW_S.contains(&(frames[0].end_ns / 1_000_000_000 % 60));
            match (unit == last, in_window, frames.len() == 2) {
                (true, true, false) => silent_in += 1,
                (true, true, true) => answered_in += 1,
                (true, false, true) => answered_out += 1,
                (false, _, false) | (true, false, false) => others_missed += 1,
                (false, _, true) => {}
            }
        }
        assert!(silent_in > 5, "{silent_in}");
        assert_eq!(answered_in, 0);
        assert!(answered_out > 5, "{answered_out}");
        assert_eq!(others_missed, 0);
    }
}
