//! CRC twins: a frame ending in `00` that checks one byte shorter too (CRC-16's shift property) —
//! which length to take and which to keep as the other reading — and a damaged stretch split
//! where a valid frame would begin.

use super::RtuFramer;
use super::expect::{Expect, diagnostics_even_len};
use crate::framer::glitch::{Sender, ZeroTail};
use mbtap_proto::function::EXCEPTION_FLAG;
use mbtap_proto::length::{PduLength, request_len, response_len};
use mbtap_proto::rtu::RTU_MIN_LEN;

impl RtuFramer {
    /// The `n` bytes at absolute `at` end in `00` and check one byte shorter too (CRC-16's shift
    /// property): the length to take ([`Self::twin_reading`]), with the other length kept for
    /// the frame event (see [`Frame::alt_len`]) when it is not negligible.
    pub(super) fn twin_len(&mut self, at: usize, n: usize, sender: Sender) -> usize {
        let (take, other) = self.twin_reading(&self.timed.buf[at..], n, sender);
        self.last.next_alt = other;
        take
    }

    /// Which of the two readings of `s[..n]`, ending in `00` and checking one byte shorter too,
    /// is the frame: Diagnostics' structure decides where it can, then the lengths this unit's
    /// function was seen with, else the odds that `sender` leaves a `00` glitch — with the other
    /// length where those odds do not make it negligible.
    pub(super) fn twin_reading(&self, s: &[u8], n: usize, sender: Sender) -> (usize, Option<usize>) {
        if let Some(even) = diagnostics_even_len(s, n - 1) {
            return (even, None);
        }
        if let Some(len) = self.lengths.choose(s[0], s[1], sender, n - 1) {
            return (len, None);
        }
        let odds = self.zero_odds(s, n - 1, sender);
        let (take, other) = if odds.glitch_likelier { (n - 1, n) } else { (n, n - 1) };
        (take, odds.ambiguous.then_some(other))
    }

    /// How to read the `00` after the `short` bytes of `s` that check both ways, where nothing
    /// decides: this sender's odds of a `00` glitch against a CRC ending in `00`, unless this
    /// unit's function was seen, however few times, only at one of the two lengths and the
    /// odds say the other — then that one first, the other shown too.
    pub(super) fn zero_odds(&self, s: &[u8], short: usize, sender: Sender) -> ZeroTail {
        let odds = self.glitches.turn.zero_tail(sender);
        match self.lengths.lean(s[0], s[1], sender, short) {
            Some(len) if (len == short) != odds.glitch_likelier => {
                ZeroTail { glitch_likelier: len == short, ambiguous: true }
            }
            _ => odds,
        }
    }

    /// Where a damaged frame at absolute `a` ends inside `a..b`, if its structure says so and a
    /// frame of a known unit plausibly starts there.
    pub(super) fn split_damaged(&self, a: usize, b: usize) -> Option<usize> {
        // With timing that can show a t3.5 silence, frames were already cut at their silences;
        // a damaged byte count would only mislead. This is for adapters whose latency hides them.
        if self.timing.latency < self.timing.t35 {
            return None;
        }
        let piece = &self.timed.buf[a..b];
        if !self.looks_like_frame(piece) {
            return None;
        }
        let pdu = &piece[1..];
        let req = if piece[1] & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        let mut cands: Vec<usize> = [req, response_len(pdu)]
            .into_iter()
            .filter_map(|c| match c {
                PduLength::Exact(k) if k + 3 >= RTU_MIN_LEN && k + 3 + 2 <= piece.len() => Some(k + 3),
                _ => None,
            })
            .collect();
        // The expected reading first (a request after a completed transaction), then the shorter.
        let expected_request = self.expect == Expect::Request && a == self.timed.head;
        let req_len = match req {
            PduLength::Exact(k) => Some(k + 3),
            _ => None,
        };
        cands.sort_unstable_by_key(|&l| (!(expected_request && Some(l) == req_len), l));
        // Only when the rest starts like a frame of a known unit: a short rest is as likely the
        // tail of this frame read with the wrong reading (a request's response reading is 5
        // bytes) as noise that followed it.
        cands.into_iter().find(|&l| self.looks_like_frame_start(a - self.timed.head + l))
    }
}
