//! A virtual line with a master on it: the master cycles through a SCADA-like poll list, the
//! simulated slaves answer, and every frame is placed in time as the line would carry it
//! (character time from the line settings, a turnaround before each answer). Time is simulated
//! — nanoseconds since the start — so `demo`, tests and benchmarks share this code.

use crate::framer::{LineSettings, Parity};
use crate::proto::encode_rtu;

use super::{Slave, world};

/// What a master typically polls on each built-in device (function, start, quantity).
fn poll_list(profile: &str) -> &'static [(u8, u16, u16)] {
    match profile {
        // Phase voltages and their average; state and alarm words; holding set points; coils.
        "mk4" => &[(0x04, 430, 4), (0x04, 400, 10), (0x03, 100, 10), (0x01, 0, 19)],
        // Phase currents, then the first trip record (MKZP: holding registers only).
        "mkzp" => &[(0x03, 50, 8), (0x03, 128, 17)],
        // Totals, the first level-sensor slot, the first flow meter.
        "display" => &[(0x04, 0, 4), (0x04, 4, 4), (0x04, 44, 22)],
        _ => &[],
    }
}

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
}

impl VirtualBus {
    /// A bus with `slaves`, polled by the built-in list of each one's profile.
    #[must_use]
    pub fn new(slaves: Vec<Slave>, line: LineSettings) -> Self {
        let mut polls = Vec::new();
        for s in &slaves {
            for &(function, start, quantity) in poll_list(&s.profile().meta.name) {
                let mut pdu = vec![function];
                pdu.extend_from_slice(&start.to_be_bytes());
                pdu.extend_from_slice(&quantity.to_be_bytes());
                polls.push((s.address(), pdu));
            }
        }
        // Start, data, parity and stop bits of one character (Serial Line v1.02 §2.5.1).
        let bits = 1 + u64::from(line.data_bits) + u64::from(line.parity != Parity::None) + u64::from(line.stop_bits);
        let char_ns = bits * 1_000_000_000 / u64::from(line.baud.max(1));
        Self { slaves, polls, next: 0, now_ns: 0, char_ns, interval_ns: 100_000_000, turnaround_ns: 3_000_000 }
    }

    /// Polls in the list (0: nothing to poll).
    #[must_use]
    pub fn poll_count(&self) -> usize {
        self.polls.len()
    }

    /// The next transaction: the request and, when a slave answers, the response.
    pub fn next_transaction(&mut self) -> Vec<LineFrame> {
        let Some((unit, pdu)) = self.polls.get(self.next).cloned() else { return Vec::new() };
        self.next = (self.next + 1) % self.polls.len();
        let mut frames = Vec::with_capacity(2);
        let mut request = Vec::with_capacity(pdu.len() + 3);
        encode_rtu(unit, &pdu, &mut request);
        let request_end = self.now_ns.saturating_add(self.duration(request.len()));
        frames.push(LineFrame { end_ns: request_end, bytes: request });
        let mut end = request_end;
        let seconds = f64::from(u32::try_from(request_end / 1_000_000).unwrap_or(u32::MAX)) / 1000.0;
        for s in &mut self.slaves {
            world::step(s, seconds);
            if let Some(answer) = s.handle(unit, &pdu) {
                let mut response = Vec::with_capacity(answer.len() + 3);
                encode_rtu(unit, &answer, &mut response);
                end = request_end.saturating_add(self.turnaround_ns).saturating_add(self.duration(response.len()));
                frames.push(LineFrame { end_ns: end, bytes: response });
                break;
            }
        }
        self.now_ns = end.saturating_add(self.interval_ns);
        frames
    }

    fn duration(&self, bytes: usize) -> u64 {
        self.char_ns.saturating_mul(u64::try_from(bytes).unwrap_or(u64::MAX))
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::proto::parse_rtu;

    fn bus() -> VirtualBus {
        let slaves = [("mk4", 1), ("display", 5), ("mkzp", 17)]
            .map(|(n, a)| Slave::new(Arc::new(crate::profile::builtin::get(n).unwrap().unwrap()), a));
        VirtualBus::new(slaves.to_vec(), LineSettings::default())
    }

    #[test]
    fn every_poll_is_answered_without_an_exception() {
        let mut b = bus();
        assert_eq!(b.poll_count(), 9);
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
}
