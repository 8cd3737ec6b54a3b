//! One interface's clock as a capture tells it, made safe for the framer: the times handed on
//! never run backwards, and one bad timestamp does not spoil the ones after it.
//!
//! Captures from real laptops hold two kinds of timestamp trouble. Jitter: a USB read stamped a
//! few microseconds before the previous one; the packet is held at the previous time. Jumps: a
//! clock step or a flipped bit moves one stamp by seconds or hours. Holding every later packet
//! at a stamp 4 295 s ahead (what a reader that only holds does) turns all of them into
//! "answered after 0 s" findings. Instead a jump moves an offset, so later packets keep their
//! own spacing, and a *lone* jump — one packet out of line, its successor back in line with its
//! predecessor — is named as such and timed from its neighbours.

/// A backward step longer than this is a clock jump, not jitter between reads.
const JUMP_NS: u64 = 10_000_000;

/// What the clock says about one packet.
#[derive(Debug, PartialEq, Eq)]
pub enum StampOrder {
    /// In order (or moved by the offset a past jump set).
    InOrder,
    /// Stamped `by_ns` before the previous packet: handed on at the previous time.
    Backwards { by_ns: u64 },
    /// The previous packet's stamp was out of line with both neighbours by `off_ns` (ahead
    /// when `ahead`): this packet is timed from the one before it.
    LoneJump { off_ns: u64, ahead: bool },
}

/// The times of one packet: as stamped, and as handed on.
#[derive(Clone, Copy, Debug, Default)]
struct Stamp {
    raw: u64,
    out: u64,
}

/// One interface's clock.
#[derive(Clone, Debug, Default)]
pub struct Clock {
    /// The last packet, and the one before it when the last was a jump (either way).
    last: Option<Stamp>,
    before_jump: Option<Stamp>,
    /// Added to raw stamps since the last backward jump (never negative in effect: the result
    /// is clamped to the last time handed on).
    offset: i128,
}

impl Clock {
    /// The last stamp as the file gave it (for a packet without one, and for judging whether
    /// a damaged region's next record is plausible).
    #[must_use]
    pub fn last_raw(&self) -> Option<u64> {
        self.last.map(|s| s.raw)
    }

    /// The time to hand on for a packet stamped `raw`, and what was wrong with it.
    #[inline]
    pub fn stamp(&mut self, raw: u64) -> (u64, StampOrder) {
        // The common case, once per packet: a step forward with no offset, the last step not
        // a backward jump (only a forward step after a backward jump can end a lone one). A
        // forward jump — any pause over JUMP_NS, which a polled line has between most polls —
        // is remembered and handed on as it is: it took the slow path for 2 packets in 3 of
        // the per-frame benchmark capture.
        if self.offset == 0
            && let Some(last) = self.last
            && raw >= last.raw
            && self.before_jump.is_none_or(|b| last.raw > b.raw)
        {
            let out = raw.max(last.out);
            self.before_jump = (raw - last.raw > JUMP_NS).then_some(last);
            self.last = Some(Stamp { raw, out });
            return (out, StampOrder::InOrder);
        }
        self.stamp_after_trouble(raw)
    }

    /// [`Clock::stamp`] for a first packet, a jump, or any packet after one.
    #[cold]
    fn stamp_after_trouble(&mut self, raw: u64) -> (u64, StampOrder) {
        let Some(last) = self.last else {
            self.last = Some(Stamp { raw, out: raw });
            return (raw, StampOrder::InOrder);
        };
        let before = self.before_jump.take();
        let step = i128::from(raw) - i128::from(last.raw);
        let jump = step.unsigned_abs() > u128::from(JUMP_NS);
        // The last stamp jumped, this one jumps back to after the one before it: the last one
        // alone was wrong. Time this packet from the one before it.
        if let Some(b) = before
            && jump
            && raw >= b.raw
            && (step < 0) == (last.raw > b.raw)
        {
            let out = b.out.saturating_add(raw - b.raw).max(last.out);
            self.offset = i128::from(out) - i128::from(raw);
            self.last = Some(Stamp { raw, out });
            let ahead = last.raw > b.raw;
            let off_ns = if ahead { last.raw - b.raw } else { b.raw - last.raw };
            return (out, StampOrder::LoneJump { off_ns, ahead });
        }
        if jump {
            self.before_jump = Some(last);
        }
        let (out, verdict) = if step < 0 {
            // Held at the last time; a jump also moves the offset so later packets keep
            // their spacing from here instead of being held too.
            if jump {
                self.offset = i128::from(last.out) - i128::from(raw);
            }
            (last.out, StampOrder::Backwards { by_ns: last.raw - raw })
        } else {
            let moved = (i128::from(raw) + self.offset).clamp(0, i128::from(u64::MAX));
            (u64::try_from(moved).unwrap_or(u64::MAX).max(last.out), StampOrder::InOrder)
        };
        self.last = Some(Stamp { raw, out });
        (out, verdict)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000_000;
    const MS: u64 = 1_000_000;

    fn run(raws: &[u64]) -> (Vec<u64>, Vec<StampOrder>) {
        let mut c = Clock::default();
        raws.iter().map(|&r| c.stamp(r)).unzip()
    }

    #[test]
    fn in_order_times_pass_unchanged() {
        let (out, v) = run(&[10 * S, 10 * S + 5 * MS, 15 * S]);
        assert_eq!(out, vec![10 * S, 10 * S + 5 * MS, 15 * S]);
        assert!(v.iter().all(|v| *v == StampOrder::InOrder));
    }

    #[test]
    fn jitter_is_held_at_the_previous_time_without_moving_later_ones() {
        let (out, v) = run(&[10 * S, 10 * S - 20_000, 10 * S + MS]);
        assert_eq!(out, vec![10 * S, 10 * S, 10 * S + MS]);
        assert_eq!(v[1], StampOrder::Backwards { by_ns: 20_000 });
    }

    /// One flipped bit (+4 295 s) in one stamp is named, and the packets after it keep their
    /// spacing (never all held at that value).
    #[test]
    fn a_lone_stamp_ahead_is_named_and_later_packets_keep_their_spacing() {
        let jumped = 10 * S + 2 * MS + 4_295 * S;
        let (out, v) = run(&[10 * S, jumped, 10 * S + 4 * MS, 10 * S + 9 * MS]);
        assert_eq!(v[2], StampOrder::LoneJump { off_ns: 4_295 * S + 2 * MS, ahead: true });
        // Timed from the packet before the bad one, but never before the bad one's time.
        assert_eq!(out[2], jumped);
        assert_eq!(out[3] - out[2], 5 * MS, "the spacing after the jump is the file's");
        assert_eq!(v[3], StampOrder::InOrder);
    }

    #[test]
    fn a_lone_stamp_behind_is_held_then_named() {
        let (out, v) = run(&[10_000 * S, 10_000 * S - 3_600 * S, 10_000 * S + 4 * MS, 10_000 * S + 9 * MS]);
        assert_eq!(v[1], StampOrder::Backwards { by_ns: 3_600 * S });
        assert_eq!(v[2], StampOrder::LoneJump { off_ns: 3_600 * S, ahead: false });
        assert_eq!(out, vec![10_000 * S, 10_000 * S, 10_000 * S + 4 * MS, 10_000 * S + 9 * MS]);
    }

    #[test]
    fn a_clock_step_back_keeps_later_spacing() {
        // Stepped back an hour for good: held once, then the file's own spacing.
        let back = 10_000 * S - 3_600 * S;
        let (out, v) = run(&[10_000 * S, back, back + 7 * MS, back + 20 * MS]);
        assert_eq!(v[1], StampOrder::Backwards { by_ns: 3_600 * S });
        assert_eq!(v[2], StampOrder::InOrder);
        assert_eq!(out, vec![10_000 * S, 10_000 * S, 10_000 * S + 7 * MS, 10_000 * S + 20 * MS]);
    }

    #[test]
    fn a_long_silence_is_not_a_jump() {
        let (out, v) = run(&[10 * S, 70 * S, 70 * S + MS]);
        assert_eq!(out, vec![10 * S, 70 * S, 70 * S + MS]);
        assert!(v.iter().all(|v| *v == StampOrder::InOrder));
    }

    #[test]
    fn extreme_stamps_do_not_overflow() {
        let (out, _) = run(&[u64::MAX, 0, u64::MAX, 1, 0]);
        assert!(out.windows(2).all(|w| w[0] <= w[1]), "{out:?}");
    }

    /// The fast path takes forward jumps too (a polled line's pauses); it hands on what the general
    /// path does, stamp for stamp, on any mix of jitter, pauses, jumps either way and lone jumps.
    #[test]
    fn the_fast_path_agrees_with_the_general_one_on_every_kind_of_step() {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..200 {
            let (mut fast, mut general) = (Clock::default(), Clock::default());
            let mut raw = 1_000 * S;
            for _ in 0..200 {
                let r = next();
                raw = match r % 8 {
                    0 => raw.saturating_sub(r % (20 * MS)),
                    1 => raw + 10 * MS + r % (5 * S),
                    2 => raw.saturating_sub(S + r % (3 * S)),
                    3 => raw + JUMP_NS,
                    _ => raw + r % (2 * MS),
                };
                assert_eq!(fast.stamp(raw), general.stamp_after_trouble(raw), "at {raw}");
            }
        }
    }
}
