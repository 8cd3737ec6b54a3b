//! Candidate frames at a position in the buffer: the lengths the structure allows in each
//! reading, the CRC, and how one reading is chosen over another (expectation, odds, timing).

use super::RtuFramer;
use super::expect::{Expect, Reading, consistent, decodes_clean, sane_header, sender_of};
use crate::framer::glitch::Sender;
use mbtap_proto::checksum::{crc16, crc16_update};
use mbtap_proto::function::{EXCEPTION_FLAG, FunctionCode};
use mbtap_proto::length::{PduLength, request_len, response_len};
use mbtap_proto::rtu::{RTU_MAX_LEN, RTU_MIN_LEN};

pub(super) enum Try {
    /// A frame of this length, read so; with another length that checks too and that nothing
    /// but the odds on this line ruled out (see [`Frame::alt_len`]).
    Found(usize, Reading, Option<usize>),
    NotHere,
    /// Nothing can change until this many bytes (from the candidate start) are buffered.
    NeedMore(usize),
}

impl RtuFramer {
    /// Is `bytes` exactly one frame that the general path would accept at once: every reading
    /// of its structure resolved within it, exactly one with a valid CRC, and that one the
    /// whole chunk? (Gap-cutting sniffers write one frame per packet; this skips buffering.)
    /// The reading it was, if so.
    pub(super) fn whole_frame(bytes: &[u8]) -> Option<Reading> {
        let [_, fc, ..] = *bytes else { return None };
        let pdu = &bytes[1..];
        let req = if fc & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        let mut found = [false; 2];
        for (slot, cand) in [req, response_len(pdu)].into_iter().enumerate() {
            match cand {
                PduLength::Exact(k) if k + 3 <= RTU_MAX_LEN => match bytes.get(..k + 3) {
                    Some(f) if Self::crc_ok(f) => {
                        if f.len() != bytes.len() {
                            return None;
                        }
                        found[slot] = true;
                    }
                    Some(_) => {}
                    None => return None,
                },
                PduLength::Exact(_) => {}
                // An exception's request reading is no reading at all.
                PduLength::Unknown if fc & EXCEPTION_FLAG != 0 => {}
                PduLength::AtLeast(_) | PduLength::Unknown => return None,
            }
        }
        match found {
            // An echo shape validates both ways at the same length: still one frame.
            [true, true] => Some(Reading::Either),
            [true, false] => Some(Reading::Request),
            [false, true] => Some(Reading::Response),
            [false, false] => None,
        }
    }

    pub(super) fn crc_ok(frame: &[u8]) -> bool {
        let [body @ .., lo, hi] = frame else { return false };
        crc16(body) == u16::from_le_bytes([*lo, *hi])
    }

    /// Is there a known silence (≥ t3.5) before live index `i`?
    pub(super) fn boundary_at(&self, i: usize) -> bool {
        self.timed.gap_lb.get(self.timed.head + i).is_some_and(|&g| g >= self.timing.t35)
    }

    /// Does a valid frame of structurally exact length start at live index `i`?
    pub(super) fn exact_frame_at(&self, i: usize) -> bool {
        let s = &self.timed.buf[self.timed.head + i..];
        if s.len() < RTU_MIN_LEN {
            return false;
        }
        let pdu = &s[1..];
        let resp = response_len(pdu);
        let req = if s[1] & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        [req, resp].into_iter().any(|c| match c {
            PduLength::Exact(k) => s.get(..k + 3).is_some_and(Self::crc_ok),
            _ => false,
        })
    }

    pub(super) fn try_frame_at(&self, g: usize, flushing: bool) -> Try {
        let live = &self.timed.buf[self.timed.head..];
        let s = &live[g..];
        let [addr, fc, ..] = *s else { return if flushing { Try::NotHere } else { Try::NeedMore(2) } };
        // Addresses 248–255 are reserved (Modbus over Serial Line v1.02 §2.2): no frame on a line
        // starts with one, whatever its CRC says (pasted frames may: `FramerConfig::pasted`).
        if addr > self.max_address {
            return Try::NotHere;
        }
        // While resynchronising through garbage, a chance CRC match (1 in 65 536 per
        // candidate) is likelier than the first frame of a never-seen unit with no silence
        // before it — unless what follows confirms it too (a silence, another valid frame, its
        // glitch): then a damaged start does not hide the valid frames after it. Right after a
        // frame's glitch byte a frame may start anyway.
        let after_glitch = g == 1 && self.at_glitch(self.timed.head);
        let unconfirmed_start = g > 0 && !self.known_units[usize::from(addr)] && !self.boundary_at(g) && !after_glitch;
        // Inside damage, a never-seen unit's frame must at least carry a function code with a
        // public layout: checked before any CRC is computed, so a stream of garbage costs a
        // byte comparison per position, not a CRC over every length.
        if unconfirmed_start && FunctionCode::from(fc & !EXCEPTION_FLAG).name().is_none() {
            return Try::NotHere;
        }
        let pdu = &s[1..];
        // Address 0 is a broadcast: a request, of a write, never answered (Serial Line v1.02
        // §2.1) — no other reading of it is worth waiting for.
        let broadcast = addr == 0;
        if !sane_header(s, self.pasted) {
            return Try::NotHere;
        }
        let resp = if broadcast { PduLength::Unknown } else { response_len(pdu) };
        let req = if fc & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        let mut need_more = false;
        let mut need = usize::MAX;
        let mut unknown = false;
        // Whether a reading still waiting for bytes could be a well-formed frame at all.
        let mut wait_worth = false;
        // Both readings are tried: a frame whose CRC ends in 0x00 also validates one byte
        // shorter (the CRC's shift property), and a next frame starting with 0x00 validates
        // one byte longer; the structure decides between them (see `best`).
        let mut found: [Option<(usize, bool)>; 2] = [None, None];
        let mut exact: [(usize, usize, bool); 2] = [(usize::MAX, 0, false); 2];
        for (slot, (cand, is_request)) in [(req, true), (resp, false)].into_iter().enumerate() {
            match cand {
                PduLength::Exact(k) => {
                    let l = k + 3;
                    if l > RTU_MAX_LEN {
                        continue;
                    }
                    if l > s.len() {
                        need_more = true;
                        need = need.min(l);
                        wait_worth |= consistent(pdu, is_request);
                    } else {
                        exact[slot] = (l, slot, is_request);
                    }
                }
                PduLength::AtLeast(k) => {
                    need_more = true;
                    need = need.min(k + 1);
                    wait_worth = true;
                }
                PduLength::Unknown => unknown = true,
            }
        }
        // Shorter candidate first, so one running CRC serves both.
        exact.sort_unstable_by_key(|e| e.0);
        let (mut crc, mut done) = (mbtap_proto::checksum::CRC16_INIT, 0usize);
        for (l, slot, is_request) in exact {
            if l == usize::MAX {
                continue;
            }
            if l < RTU_MIN_LEN {
                continue;
            }
            crc = crc16_update(crc, &s[done..l - 2]);
            done = l - 2;
            if crc == u16::from_le_bytes([s[l - 2], s[l - 1]]) {
                found[slot] = Some((l, is_request));
            }
        }
        let reading_of = Reading::of;
        let clean = |l: usize, is_request: bool| decodes_clean(&s[1..l - 2], is_request);
        let answer_expected = (g == 0 || after_glitch) && matches!(self.expect, Expect::Response { .. });
        // Bytes before `g` that are not a lone glitch are damage too, not yet emitted.
        let inside_damage = g > 0 && !after_glitch;
        for slot in &mut found {
            if let Some((l, is_request)) = *slot
                // A reading whose byte count its own quantity contradicts is no frame, whatever
                // its CRC says: valid frames glued together check as one (each leaves the CRC at
                // zero), and a chance match over damage does in 1 of 65 536.
                && (!consistent(&s[1..l - 2], is_request)
                    // While an answer is awaited, a reading that is not it must at least be well
                    // formed: a damaged answer ending in `00` checks one byte shorter, as a
                    // request with an absurd quantity. Inside damage too: a CRC matching by
                    // chance over a damaged byte count gives absurd quantities.
                    || ((inside_damage || (answer_expected && !self.expected(g, l, reading_of(is_request))))
                        && !clean(l, is_request)))
            {
                *slot = None;
            }
        }
        // Right after damage nothing is expected, and a damaged byte count can make a shorter
        // frame whose CRC matches by chance (1 in 65 536): what follows must confirm it.
        let after_damage = self.last.after_damage && (g == 0 || after_glitch) && found.iter().any(Option::is_some);
        if unconfirmed_start || after_damage {
            // Confirmed by what follows, and well formed: no findings in its decode.
            let confirmed = |(l, is_request): (usize, bool)| {
                (self.ends_at(g + l) || self.glitch_then_end(g + l) || (flushing && g + l == live.len()))
                    && consistent(&s[1..l - 2], is_request)
                    && clean(l, is_request)
            };
            let found_any = found.iter().any(Option::is_some);
            for slot in &mut found {
                if slot.is_some_and(|r| !confirmed(r)) {
                    *slot = None;
                }
            }
            return match found {
                [Some((a, _)), Some((b, _))] if a == b => Try::Found(a, Reading::Either, None),
                [Some(a), Some(b)] => {
                    let (l, r) = self.best(g, a, b);
                    Try::Found(l, reading_of(r), None)
                }
                [Some((l, r)), None] | [None, Some((l, r))] => Try::Found(l, reading_of(r), None),
                // Not yet confirmed: wait for what follows, unless nothing more can come.
                [None, None] if !flushing && (need_more || found_any) => Try::NeedMore(s.len() + 1),
                [None, None] => Try::NotHere,
            };
        }
        match found {
            // A valid reading need not wait for another reading that could only be malformed
            // (a 0x10 response read as a request: its byte count disagrees with its quantity),
            // nor for one the bus does not expect now.
            [Some((l, r)), None] | [None, Some((l, r))]
                if !need_more || flushing || !wait_worth || self.expected(g, l, reading_of(r)) =>
            {
                return Try::Found(l, reading_of(r), None);
            }
            // Echo shapes (05, 06, 08, 15, 16) read the same length both ways: one frame.
            [Some(a), Some(b)] if a.0 == b.0 => return Try::Found(a.0, Reading::Either, None),
            [Some(a), Some(b)] => {
                let (l, r) = self.best(g, a, b);
                return Try::Found(l, reading_of(r), None);
            }
            [Some(_), None] | [None, Some(_)] => return Try::NeedMore(need),
            [None, None] => {}
        }
        if unknown && fc & EXCEPTION_FLAG == 0 {
            match self.unknown_length_at(g, flushing) {
                Try::NeedMore(n) => {
                    need_more = true;
                    need = need.min(n);
                }
                t @ Try::Found(..) => return t,
                Try::NotHere => {}
            }
        }
        if need_more && !flushing { Try::NeedMore(need.max(s.len() + 1)) } else { Try::NotHere }
    }

    /// Two readings with valid CRCs (the CRC shift property makes a valid frame followed by
    /// 0x00 validate one byte longer too): prefer the one the bus expects, then the one that
    /// fits its function's structure without findings, then the one the next bytes confirm (a
    /// silence, a valid frame, or a lone glitch byte before either), then the shorter.
    pub(super) fn best(&self, g: usize, a: (usize, bool), b: (usize, bool)) -> (usize, bool) {
        let score = |(l, is_request): (usize, bool)| {
            let confirmed = self.ends_at(g + l) || self.glitch_then_end(g + l);
            let s = &self.timed.buf[self.timed.head + g..self.timed.head + g + l];
            let clean = decodes_clean(&s[1..l - 2], is_request);
            (self.expected(g, l, Reading::of(is_request)), clean, confirmed, std::cmp::Reverse(l))
        };
        if score(b) > score(a) { b } else { a }
    }

    /// Who sends the frame starting at live index `g`, as far as the expectation says.
    pub(super) fn sender_at(&self, g: usize) -> Sender {
        sender_of(self.expect_at(g), &self.timed.buf[self.timed.head + g..], None)
    }

    /// Does a frame end before live index `i`: a known silence or a valid frame starts there?
    pub(super) fn ends_at(&self, i: usize) -> bool {
        self.boundary_at(i) || self.exact_frame_at(i)
    }
}
