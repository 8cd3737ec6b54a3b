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

#[derive(Debug, Clone, Copy)]
struct Counts {
    /// Valid frames from this sender.
    frames: u32,
    /// Of them, followed by a turnaround glitch.
    glitches: u32,
    /// Of those glitches, `00`.
    zeros: u32,
    /// How often each value was this sender's glitch, and the commonest's count.
    values: [u32; 256],
    top: u32,
}

impl Default for Counts {
    fn default() -> Self {
        Self { frames: 0, glitches: 0, zeros: 0, values: [0; 256], top: 0 }
    }
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

/// Until a sender has sent this many valid frames, whether it glitches is unknown: a trailing
/// `00` of its frames is shown with both readings.
const FIRST_FRAMES: u32 = 8;

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
            let n = &mut c.values[usize::from(value)];
            *n = n.saturating_add(1);
            c.top = c.top.max(*n);
        }
    }

    fn counts_mut(&mut self, sender: Sender) -> Option<&mut Counts> {
        match sender {
            Sender::Master => Some(&mut self.master),
            Sender::Slave => Some(&mut self.slave),
            Sender::Unknown => None,
        }
    }

    /// Is `value` one this sender's driver leaves (seen at least 4 times, and at least an
    /// eighth as often as its commonest)? `None` for an unknown sender or one never seen to
    /// glitch: the caller falls back on the line's values.
    pub(crate) fn sender_value(&self, sender: Sender, value: u8) -> Option<bool> {
        let c = match sender {
            Sender::Master => &self.master,
            Sender::Slave => &self.slave,
            Sender::Unknown => return None,
        };
        (c.top >= 4).then(|| {
            let n = c.values[usize::from(value)];
            n >= 4 && n.saturating_mul(8) >= c.top
        })
    }

    /// The odds of the two readings of a frame ending in `00` that `sender` most likely sent:
    /// the frame's CRC high byte `00` with no glitch after it (1/256 of the frames this sender
    /// leaves no glitch after), against a one byte shorter frame and a `00` glitch (this
    /// sender's share of frames followed by one). The other side sent it now and then (a master
    /// repeating a vendor request to a unit that never answers looks like that unit's answer):
    /// it weighs 1 in 1000, so a reading impossible for the likely sender (a slave that glitches
    /// after every frame, here followed by none) still falls to the other. An unknown sender
    /// weighs both sides alike.
    pub(crate) fn zero_tail(&self, sender: Sender) -> ZeroTail {
        let (m, s) = match sender {
            Sender::Master => (0.999, 0.001),
            Sender::Slave => (0.001, 0.999),
            Sender::Unknown => (0.5, 0.5),
        };
        let (mc, mg) = Self::readings(&self.master);
        let (sc, sg) = Self::readings(&self.slave);
        let crc = m * mc + s * sc;
        let glitch = m * mg + s * sg;
        #[allow(clippy::cast_precision_loss)]
        let odds = AMBIGUOUS_ODDS as f64;
        // Too few frames from the likely sender to say it never glitches (a line's first
        // frames): nothing is known, and both readings are shown.
        let seen = match sender {
            Sender::Master => self.master.frames,
            Sender::Slave => self.slave.frames,
            Sender::Unknown => self.master.frames.saturating_add(self.slave.frames),
        };
        ZeroTail {
            glitch_likelier: glitch > crc,
            ambiguous: (glitch > 0.0 && glitch * odds >= crc && crc * odds >= glitch) || seen < FIRST_FRAMES,
        }
    }

    /// (CRC reading, glitch reading) likelihoods for one sender's counts; a sender never seen
    /// counts as one that leaves no glitch.
    fn readings(c: &Counts) -> (f64, f64) {
        let n = f64::from(c.frames) + 2.0;
        let clean = f64::from(c.frames.saturating_sub(c.glitches)) + 1.0;
        (clean / n / 256.0, f64::from(c.zeros) / n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vendor request ending in `00` as a line's first frame is not taken whole without doubt:
    /// nothing is known yet of whether its sender glitches, so both readings are shown.
    #[test]
    fn a_lines_first_frames_show_both_readings_of_a_trailing_zero() {
        let mut s = TurnaroundStats::default();
        assert_eq!(s.zero_tail(Sender::Unknown), ZeroTail { glitch_likelier: false, ambiguous: true });
        for _ in 0..FIRST_FRAMES {
            s.frame(Sender::Master);
        }
        assert_eq!(s.zero_tail(Sender::Master), ZeroTail { glitch_likelier: false, ambiguous: false });
        assert_eq!(s.zero_tail(Sender::Slave), ZeroTail { glitch_likelier: false, ambiguous: true });
    }

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
    fn a_zero_ending_a_slaves_frame_is_its_crc_where_only_the_master_glitches_00() {
        let mut s = TurnaroundStats::default();
        for _ in 0..1000 {
            s.frame(Sender::Slave);
            s.frame(Sender::Master);
            s.glitch(Sender::Master, 0x00);
        }
        assert_eq!(s.zero_tail(Sender::Slave), ZeroTail { glitch_likelier: false, ambiguous: true });
        assert_eq!(s.zero_tail(Sender::Master), ZeroTail { glitch_likelier: true, ambiguous: false });
    }

    /// A master repeating a vendor request to a unit that never answers looks like that unit's
    /// answer; where slaves leave `FF` after every frame, a "slave" frame ending in `00` with no
    /// `FF` after it is likelier the master's, with its `00` glitch (and both lengths are shown:
    /// a slave's frame is a thousand times likelier to begin with).
    #[test]
    fn a_slave_that_always_glitches_ff_did_not_send_a_frame_followed_by_none() {
        let mut s = TurnaroundStats::default();
        for _ in 0..1000 {
            s.frame(Sender::Slave);
            s.glitch(Sender::Slave, 0xFF);
            s.frame(Sender::Master);
            s.glitch(Sender::Master, 0x00);
        }
        assert_eq!(s.zero_tail(Sender::Slave), ZeroTail { glitch_likelier: true, ambiguous: true });
        assert_eq!(s.sender_value(Sender::Slave, 0xFF), Some(true));
        assert_eq!(s.sender_value(Sender::Slave, 0x00), Some(false));
        assert_eq!(s.sender_value(Sender::Unknown, 0x00), None);
    }
}
