//! How often each side of this line leaves a `00` turnaround glitch, learned from the frames
//! and glitches the framer has told apart — the odds it needs where the CRC cannot decide.
//!
//! CRC-16/MODBUS's shift property: a valid frame F whose CRC high byte is `00` also checks one
//! byte shorter, and F followed by a `00` checks one byte longer. For a frame whose length no
//! structure fixes (vendor codes, Diagnostics 0000) the bytes `… 00` then read two ways, both
//! CRC-valid and equally close in time: F, or F without the `00` plus a turnaround glitch. What
//! is left to decide by is how likely each is on this line: a CRC high byte is `00` in 1 frame
//! of 256, and a `00` glitch follows as often as this sender's frames were seen followed by
//! one. The master's and the slaves' drivers glitch differently (`00` after the master, `FE` or
//! `FF` after slaves on typical transceivers), so the odds are kept per sender.

/// Who sent a frame, as far as the expectation says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Sender {
    Master,
    Slave,
    /// Nobody can say (after damage, or before the first transaction).
    Unknown,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    /// Valid frames from this sender.
    frames: u32,
    /// Of them, followed by a turnaround glitch.
    glitches: u32,
    /// Of those glitches, `00`.
    zeros: u32,
}

/// The learned turnaround behaviour of the master and the slaves.
#[derive(Debug, Default, Clone)]
pub(crate) struct TurnaroundStats {
    master: Counts,
    slave: Counts,
}

/// How to read a trailing `00` that both readings pass the CRC with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ZeroTail {
    /// A `00` glitch after the shorter frame is likelier than a CRC ending in `00`.
    pub glitch_likelier: bool,
    /// The other reading is not negligible (likelier than 1 in 1000): the frame is reported
    /// with both lengths.
    pub ambiguous: bool,
}

/// The losing reading is reported too when its odds are at least 1 in this many.
const AMBIGUOUS_ODDS: u64 = 1000;

impl TurnaroundStats {
    /// A valid frame from `sender` was emitted.
    pub(crate) fn frame(&mut self, sender: Sender) {
        if let Some(c) = self.counts_mut(sender) {
            c.frames = c.frames.saturating_add(1);
        }
    }

    /// The last frame, from `sender`, was followed by the turnaround glitch `value`.
    pub(crate) fn glitch(&mut self, sender: Sender, value: u8) {
        if let Some(c) = self.counts_mut(sender) {
            c.glitches = c.glitches.saturating_add(1);
            if value == 0 {
                c.zeros = c.zeros.saturating_add(1);
            }
        }
    }

    fn counts_mut(&mut self, sender: Sender) -> Option<&mut Counts> {
        match sender {
            Sender::Master => Some(&mut self.master),
            Sender::Slave => Some(&mut self.slave),
            Sender::Unknown => None,
        }
    }

    /// The odds of the two readings of a frame from `sender` ending in `00`: a CRC high byte
    /// `00` after a frame not followed by a glitch (1/256 of those), against a shorter frame
    /// followed by a `00` glitch (this sender's share of frames followed by one). An unknown
    /// sender takes the master's and the slaves' together.
    pub(crate) fn zero_tail(&self, sender: Sender) -> ZeroTail {
        let c = match sender {
            Sender::Master => self.master,
            Sender::Slave => self.slave,
            Sender::Unknown => Counts {
                frames: self.master.frames.saturating_add(self.slave.frames),
                glitches: self.master.glitches.saturating_add(self.slave.glitches),
                zeros: self.master.zeros.saturating_add(self.slave.zeros),
            },
        };
        // P(glitch reading) ∝ zeros / frames; P(CRC reading) ∝ (frames − glitches) / frames / 256.
        let glitch = u64::from(c.zeros) * 256;
        let crc = u64::from(c.frames.saturating_sub(c.glitches)) + 1;
        ZeroTail {
            glitch_likelier: glitch > crc,
            ambiguous: glitch > 0
                && glitch.saturating_mul(AMBIGUOUS_ODDS) >= crc
                && crc.saturating_mul(AMBIGUOUS_ODDS) >= glitch,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_that_never_glitched_reads_a_trailing_zero_as_the_crc_without_doubt() {
        let mut s = TurnaroundStats::default();
        for _ in 0..500 {
            s.frame(Sender::Master);
        }
        assert_eq!(s.zero_tail(Sender::Master), ZeroTail { glitch_likelier: false, ambiguous: false });
    }

    #[test]
    fn a_master_glitching_after_three_frames_in_ten_makes_a_trailing_zero_a_glitch_but_not_surely() {
        let mut s = TurnaroundStats::default();
        for i in 0..1000 {
            s.frame(Sender::Master);
            if i % 10 < 3 {
                s.glitch(Sender::Master, 0x00);
            }
        }
        assert_eq!(s.zero_tail(Sender::Master), ZeroTail { glitch_likelier: true, ambiguous: true });
    }

    #[test]
    fn slaves_that_glitch_ff_say_nothing_about_a_zero_after_their_frames() {
        let mut s = TurnaroundStats::default();
        for _ in 0..1000 {
            s.frame(Sender::Slave);
            s.glitch(Sender::Slave, 0xFF);
            s.frame(Sender::Master);
            s.glitch(Sender::Master, 0x00);
        }
        assert_eq!(s.zero_tail(Sender::Slave), ZeroTail { glitch_likelier: false, ambiguous: false });
        assert_eq!(s.zero_tail(Sender::Master), ZeroTail { glitch_likelier: true, ambiguous: false });
    }
}
