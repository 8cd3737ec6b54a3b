//! What is kept of one register, and of two adjacent registers read together, while a line is
//! listened to: bounded figures (counts, extremes, a few distinct values, the last
//! [`RECENT`] samples), so memory depends on the number of registers, never on the length of
//! the capture.

use std::collections::VecDeque;

/// Samples kept per register and per adjacent pair, for the tests that need a series.
pub const RECENT: usize = 96;
/// Distinct values remembered per register (beyond: "many").
pub const DISTINCT: usize = 16;

/// One register's history.
#[derive(Debug, Clone, Default)]
pub struct RegStat {
    pub samples: u64,
    pub changes: u64,
    /// Changes up (as an unsigned number), down, and down from near the top to near zero.
    pub ups: u64,
    pub downs: u64,
    pub wraps: u64,
    /// Changes that flipped exactly one bit, and the bits that ever flipped.
    pub one_bit_changes: u64,
    pub flipped_bits: u16,
    pub min: u16,
    pub max: u16,
    /// Samples in the lowest and the highest quarter of the 16-bit range.
    pub low_quarter: u64,
    pub high_quarter: u64,
    /// Samples whose two bytes are printable ASCII or NUL, with at least one letter or digit.
    pub ascii: u64,
    pub distinct: Vec<u16>,
    pub many_distinct: bool,
    pub last: Option<u16>,
    pub recent: VecDeque<u16>,
}

fn printable(b: u8) -> bool {
    b == 0 || (0x20..=0x7E).contains(&b)
}

impl RegStat {
    /// One value read at this register.
    pub fn push(&mut self, v: u16) {
        if self.samples == 0 {
            self.min = v;
            self.max = v;
        }
        self.samples += 1;
        self.min = self.min.min(v);
        self.max = self.max.max(v);
        if v < 0x4000 {
            self.low_quarter += 1;
        } else if v >= 0xC000 {
            self.high_quarter += 1;
        }
        let [hi, lo] = v.to_be_bytes();
        if printable(hi) && printable(lo) && (hi.is_ascii_alphanumeric() || lo.is_ascii_alphanumeric()) {
            self.ascii += 1;
        }
        if let Some(prev) = self.last
            && prev != v
        {
            self.changes += 1;
            if (prev ^ v).is_power_of_two() {
                self.one_bit_changes += 1;
            }
            self.flipped_bits |= prev ^ v;
            if v > prev {
                self.ups += 1;
            } else if prev >= 0xC000 && v < 0x4000 {
                self.wraps += 1;
            } else {
                self.downs += 1;
            }
        }
        if !self.many_distinct && !self.distinct.contains(&v) {
            if self.distinct.len() < DISTINCT {
                self.distinct.push(v);
            } else {
                self.many_distinct = true;
            }
        }
        self.last = Some(v);
        if self.recent.len() == RECENT {
            self.recent.pop_front();
        }
        self.recent.push_back(v);
    }
}

/// Two adjacent registers (`a`, `a + 1`) as read in the same answers: the joint samples.
#[derive(Debug, Clone, Default)]
pub struct PairStat {
    pub samples: u64,
    pub recent: VecDeque<(u16, u16)>,
}

impl PairStat {
    /// The joint samples `samples`, in order (tests and examples build series this way).
    #[must_use]
    pub fn of(samples: &[(u16, u16)]) -> Self {
        let mut p = Self::default();
        for &(a, b) in samples {
            p.push(a, b);
        }
        p
    }

    pub fn push(&mut self, first: u16, second: u16) {
        self.samples += 1;
        if self.recent.len() == RECENT {
            self.recent.pop_front();
        }
        self.recent.push_back((first, second));
    }
}
