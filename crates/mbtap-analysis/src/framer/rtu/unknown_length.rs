//! Frames whose structure does not fix their length (vendor codes, some diagnostics): ended by
//! the CRC and what follows it, or by a known silence.

use super::RtuFramer;
use super::candidates::Try;
use super::expect::{Reading, diagnostics_even_len, sane_header};
use crate::framer::glitch::Sender;
use mbtap_proto::checksum::{crc16, crc16_update};
use mbtap_proto::function::{EXCEPTION_FLAG, FunctionCode};
use mbtap_proto::length::{PduLength, request_len, response_len};
use mbtap_proto::rtu::{RTU_MAX_LEN, RTU_MIN_LEN};

impl RtuFramer {
    /// The structure cannot say where this frame ends: accept a CRC match only where something
    /// confirms an end — a known silence, the end of input, or a valid frame after it. Public
    /// and user-defined codes may pause inside a frame (slow slaves), so for them only a
    /// silence longer than the incomplete-frame timeout bounds the search.
    pub(super) fn unknown_length_at(&self, g: usize, flushing: bool) -> Try {
        let live_len = self.timed.live_len();
        let s = &self.timed.buf[self.timed.head + g..];
        let base = FunctionCode::from(s[1]);
        let lenient = (base.name().is_some() || base.is_user_defined()) && self.known_units[usize::from(s[0])];
        // A code with no public layout from an address never seen before is far more likely
        // garbage than a vendor frame; such frames are still reported, with their boundaries,
        // once a silence or a valid frame ends them (`emit_piece`).
        if s[0] > self.max_address
            || !(base.name().is_some() || base.is_user_defined() || self.known_units[usize::from(s[0])])
        {
            return Try::NotHere;
        }
        // After damage (bytes before `g` that are not a lone glitch), a known unit's frame must
        // carry a public or user-defined code too: there a 4-byte "frame" of any code is a CRC
        // matching by chance as often as not.
        let after_glitch = g == 1 && self.at_glitch(self.timed.head);
        if g > 0 && !after_glitch && !(base.name().is_some() || base.is_user_defined()) {
            return Try::NotHere;
        }
        // Broadcasts carry writes only (Modbus over Serial Line v1.02 §2.1), and every write has
        // a fixed layout: address 0 with a length the structure cannot tell is garbage.
        if s[0] == 0 || !sane_header(s, self.pasted) {
            return Try::NotHere;
        }
        let max = s.len().min(RTU_MAX_LEN);
        let mut bounded = false;
        let mut crc = 0;
        let mut first_match = true;
        for l in RTU_MIN_LEN..=max {
            // `crc` covers the body s[..l - 2], one byte more each step.
            crc = if l == RTU_MIN_LEN { crc16(&s[..2]) } else { crc16_update(crc, &s[l - 3..l - 2]) };
            let received = u16::from_le_bytes([s[l - 2], s[l - 1]]);
            // A CRC match at a length this unit's function is never seen with is chance — unless
            // it is the shorter twin of one that is (decided below).
            let vetoed = crc == received
                && !(s.get(l) == Some(&0) && l < s.len() && Self::crc_ok(&s[..=l]))
                && self.lengths.contradicts(s[0], s[1], self.sender_at(g), l);
            if crc == received && !vetoed {
                let at_end = g + l == live_len;
                // The first CRC match is taken when a frame plausibly starts right after it
                // (request and response of the same vendor code follow each other); later
                // matches need stronger evidence, because over hundreds of lengths a chance
                // match becomes likely.
                let next_starts = !at_end && self.looks_like_frame_start(g + l);
                // A lone byte and then a silence or a frame: this frame's turnaround glitch.
                // Only on a line seen to glitch: elsewhere a CRC match with one stray byte after it
                // is a chance match inside damage (1 in 65 536 per length tried) as often as not.
                // Before the line is seen to glitch (its first frames), only the values slaves'
                // drivers leave (`FE`, `FF`) count: with one of them the chance match inside damage
                // is 2 in 256 × 1 in 65 536 (a vendor answer and its `FE` at the line's
                // start was one frame failing its check). A `00` there is the CRC-`00` twin
                // question, which the odds on this line decide below once it has glitched.
                let driver_value = s.get(l).is_some_and(|&v| matches!(v, 0xFE | 0xFF));
                let glitch_after = (self.glitches.glitchy() || driver_value)
                    && (self.glitch_then_end(g + l) || (flushing && g + l + 1 == live_len))
                    || self.glitch_then_start(g + l);
                // An answer starts with its request's unit and function (an exception's with the
                // flag set, MAP v1.1b3 §7): the first CRC match followed by this frame's own header
                // ends it, whether or not the unit was heard before (a chance match and a chance
                // header together: 1 in 2³²). Vendor requests and answers glued by a FIFO or a USB
                // timer at the line's start were one frame failing its check. Only the
                // first: a frame and its `00` glitch check too (CRC-16's shift property), and
                // which of those two it is, is decided at the shorter one below.
                let answer_next = first_match
                    && s.get(l) == Some(&s[0])
                    && s.get(l + 1).is_some_and(|&f| f & !EXCEPTION_FLAG == s[1] & !EXCEPTION_FLAG);
                if self.boundary_at(g + l)
                    || (flushing && at_end)
                    || self.exact_frame_at(g + l)
                    || (first_match && next_starts)
                    || answer_next
                    || glitch_after
                {
                    // CRC shift property: a frame whose CRC high byte is 0x00 also validates
                    // one byte shorter. When the byte after this match is 0x00 and the longer
                    // frame validates too, take the longer unless only the shorter is followed
                    // by something that looks like a frame.
                    if s.get(l) == Some(&0) && l < RTU_MAX_LEN && s.len() > l && Self::crc_ok(&s[..=l]) {
                        // Diagnostics data is N × 2 bytes (MAP v1.1b3 §6.8): its structure
                        // decides where the CRC can.
                        if let Some(even) = diagnostics_even_len(s, l) {
                            return Try::Found(even, Reading::Unknown, None);
                        }
                        // The lengths this unit's function was seen with unambiguously decide.
                        if let Some(len) = self.lengths.choose(s[0], s[1], self.sender_at(g), l) {
                            return Try::Found(len, Reading::Unknown, None);
                        }
                        // What follows the longer frame decides below: wait until its start
                        // (two bytes) has arrived, unless nothing more can come.
                        if !flushing && s.len() < l + 3 && !self.boundary_at(g + l + 1) {
                            return Try::NeedMore(l + 3);
                        }
                        // The longer frame followed by its own glitch byte is the longer frame —
                        // a byte taking a glitch's value: a lone other byte before a silence is
                        // as likely a slow slave pausing after its answer's first byte.
                        let glitch_like =
                            s.get(l + 1).is_some_and(|&v| self.glitches.value(v) || matches!(v, 0x00 | 0xFE | 0xFF));
                        let longer_glitch =
                            (glitch_like && self.glitch_then_end(g + l + 1)) || self.glitch_then_start(g + l + 1);
                        let longer_ok = g + l + 1 == live_len
                            || self.boundary_at(g + l + 1)
                            || self.exact_frame_at(g + l + 1)
                            || self.looks_like_frame_start(g + l + 1)
                            || longer_glitch;
                        // Where reads batch bytes (any read held more than one), a silence before
                        // the `00` is a lower bound computed with a latency that may not be learned
                        // yet or short of the adapter's: the longer frame followed by its sender's
                        // glitch outweighs it — a sender leaves one glitch byte, not a `00` and
                        // another (else a vendor answer ending in `00` and its `FF`, 1 215
                        // bytes into a line behind a 16 ms timer, is taken 1 byte short).
                        let batched = self.learner.estimate.longest_read > 1;
                        let shorter_boundary = self.boundary_at(g + l) && !(longer_glitch && batched);
                        let evidence = shorter_boundary || self.exact_frame_at(g + l) || longer_glitch;
                        // Nothing else decides: whether this sender's `00` glitch is likelier
                        // than a CRC ending in `00` (1 in 256), or the length this unit's
                        // function was seen with once.
                        let odds = self.zero_odds(s, l, self.sender_at(g));
                        let shorter_strong =
                            shorter_boundary || self.exact_frame_at(g + l) || (odds.glitch_likelier && !longer_glitch);
                        // A lone `00` between two silences is noise after the frame, or its CRC's
                        // high byte after a slave paused longer than t3.5 inside it: both check.
                        let lone_zero = self.boundary_at(g + l) && self.boundary_at(g + l + 1);
                        let alt =
                            |other: usize| (longer_ok && ((!evidence && odds.ambiguous) || lone_zero)).then_some(other);
                        if longer_ok && !shorter_strong {
                            return Try::Found(l + 1, Reading::Unknown, alt(l));
                        }
                        return Try::Found(l, Reading::Unknown, alt(l + 1));
                    }
                    return self.longer_twin(s, g, l, glitch_after);
                }
                first_match = false;
            }
            // A whole valid frame starting inside this one means this one ended before it (or
            // was never a frame): over hundreds of lengths, running past it invites a chance
            // CRC match further on.
            if !lenient && l < s.len() && self.exact_frame_at(g + l) {
                bounded = true;
                break;
            }
            if l < s.len() {
                let gap = self.timed.gap_lb[self.timed.head + g + l];
                // Even a slow slave's frame cannot hold a whole valid frame after a silence.
                if gap >= self.timing.incomplete_timeout
                    || (gap >= self.timing.t35 && (!lenient || self.exact_frame_at(g + l)))
                {
                    bounded = true;
                    break;
                }
            }
        }
        if !bounded && !flushing && s.len() < RTU_MAX_LEN { Try::NeedMore(s.len() + 1) } else { Try::NotHere }
    }

    /// A CRC match of `l` bytes at live index `g`, with an end confirmed after it. When it ends
    /// in `00` it also checks one byte shorter (CRC-16's shift property) and the shorter reading
    /// had no end of its own confirmed: which it is, is decided as where the shorter match is
    /// weighed ([`Self::twin_reading`]) (a line's first vendor request ending in `00`
    /// was taken whole without doubt). Followed by its own glitch byte (`glitched`), it is the
    /// longer frame: a sender leaves one.
    fn longer_twin(&self, s: &[u8], g: usize, l: usize, glitched: bool) -> Try {
        let short = l - 1;
        if glitched || s[short] != 0 || short < RTU_MIN_LEN || !Self::crc_ok(&s[..short]) {
            return Try::Found(l, Reading::Unknown, None);
        }
        let (take, other) = self.twin_reading(s, l, self.sender_at(g));
        Try::Found(take, Reading::Unknown, other)
    }

    /// The exact length the structure gives a frame starting at absolute `a`, if it fits
    /// before `stop`.
    pub(super) fn structural_len(&self, a: usize, stop: usize) -> Option<usize> {
        let f = &self.timed.buf[a..stop];
        if !self.looks_like_frame(f) {
            return None;
        }
        let pdu = &f[1..];
        let req = if f[1] & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        [response_len(pdu), req].into_iter().find_map(|c| match c {
            PduLength::Exact(k) if k + 3 <= f.len() => Some(k + 3),
            _ => None,
        })
    }

    /// A failed-check piece is reported as a frame when it could be one: 4 to 256 bytes
    /// starting with a unicast or broadcast address and either a public, user-defined or
    /// exception function code, or an address already seen in valid frames.
    pub(super) fn looks_like_frame(&self, piece: &[u8]) -> bool {
        let [addr, fc, ..] = *piece else { return false };
        let base = FunctionCode::from(fc & !EXCEPTION_FLAG);
        (RTU_MIN_LEN..=RTU_MAX_LEN).contains(&piece.len())
            && addr <= self.max_address
            && ((fc != 0 && (base.name().is_some() || base.is_user_defined())) || self.known_units[usize::from(addr)])
    }

    /// Do the two bytes at live index `i` look like the start of a frame: an address already
    /// seen in valid frames and a public, user-defined or exception function code?
    pub(super) fn looks_like_frame_start(&self, i: usize) -> bool {
        let (Some(&addr), Some(&fc)) =
            (self.timed.buf.get(self.timed.head + i), self.timed.buf.get(self.timed.head + i + 1))
        else {
            return false;
        };
        let base = FunctionCode::from(fc & !EXCEPTION_FLAG);
        if addr == 0 {
            // Broadcasts carry writes only (Modbus over Serial Line v1.02 §2.1).
            return self.known_units[0] && matches!(fc, 0x05 | 0x06 | 0x0F | 0x10 | 0x15 | 0x16);
        }
        self.known_units[usize::from(addr)] && fc != 0 && (base.name().is_some() || base.is_user_defined())
    }

    /// A whole frame: it looks like one, its CRC holds, and its length is one its structure allows.
    pub(super) fn plausible_frame(&self, f: &[u8]) -> bool {
        // A code with no public layout that is not a user-defined one either (MAP v1.1b3 §5):
        // from garbage, a chance CRC match is likelier than such a frame.
        let base = FunctionCode::from(f.get(1).map_or(0, |fc| fc & !EXCEPTION_FLAG));
        // Addresses 248–255 start no frame on a line (Modbus over Serial Line v1.02 §2.2), as
        // `try_frame_at` holds: a noise burst that checks by chance stays noise.
        if !self.looks_like_frame(f)
            || !sane_header(f, self.pasted)
            || f.first().is_some_and(|&a| a > self.max_address)
            || !(base.name().is_some() || base.is_user_defined())
            || !Self::crc_ok(f)
        {
            return false;
        }
        let pdu = &f[1..];
        let fits = |c: PduLength| match c {
            PduLength::Exact(k) => k + 3 == f.len(),
            PduLength::AtLeast(_) => false,
            PduLength::Unknown => true,
        };
        let structural = fits(response_len(pdu)) || (f[1] & EXCEPTION_FLAG == 0 && fits(request_len(pdu)));
        structural && !self.length_vetoed(f)
    }

    /// A frame whose length only the CRC vouches for (the structure gives none), at a length
    /// this unit's function is never seen with ([`crate::framer::lengths`]): chance.
    pub(super) fn length_vetoed(&self, f: &[u8]) -> bool {
        let unknown = |c: PduLength| matches!(c, PduLength::Unknown);
        let (Some(&unit), Some(&fc), Some(pdu)) = (f.first(), f.get(1), f.get(1..)) else { return false };
        unknown(response_len(pdu))
            && (fc & EXCEPTION_FLAG != 0 || unknown(request_len(pdu)))
            && self.lengths.contradicts(unit, fc, Sender::Unknown, f.len())
    }

    /// [`Self::plausible_frame`] at any length: the shape, the code and the CRC.
    pub(super) fn plausible_shape(&self, f: &[u8]) -> bool {
        let base = FunctionCode::from(f.get(1).map_or(0, |fc| fc & !EXCEPTION_FLAG));
        self.looks_like_frame(f)
            && sane_header(f, self.pasted)
            && f.first().is_some_and(|&a| a <= self.max_address)
            && (base.name().is_some() || base.is_user_defined())
            && Self::crc_ok(f)
    }
}
