//! Frame lengths learned per unit, function and direction, where the function's structure
//! does not fix them (vendor codes, Diagnostics sub-functions, Report Server ID): a device
//! sends the same vendor function with the same lengths all day, so the frames that are
//! unambiguous tell which length a CRC-`00` twin has.
//!
//! A frame is unambiguous about its length when neither twin of CRC-16/MODBUS's shift property
//! exists: its last byte is not `00` (else it validates one byte shorter) and the byte after it
//! has arrived and is not `00` (else it validates one byte longer). Only those are learned
//! from, which keeps a wrong guess from teaching itself (a first version learned from the last
//! byte alone, and a 7-byte twin of an 8-byte frame ending in `00` — whose last byte is the
//! CRC's low byte — taught it the wrong length).

use std::collections::BTreeMap;

use super::glitch::Sender;
use mbtap_proto::length::{PduLength, request_len, response_len};

/// Lengths kept per key (the most frequent win; a device uses one or two).
const PER_KEY: usize = 4;
/// Keys kept (units × vendor functions × directions on one line: a handful; bounded anyway).
const MAX_KEYS: usize = 4096;
/// Sightings before a length decides.
const SURE: u32 = 2;
/// A length decides only when it is at least this share (in tenths) of its key's sightings: a
/// function whose length varies (sub-functions, variable data) decides nothing.
const SHARE_TENTHS: u64 = 9;

/// Sightings before a learned length may veto a CRC match of another length.
const FIRM: u32 = 16;
/// …and the share (in percent) of the key's sightings it must have: a function seen at that
/// length nearly always.
const FIRM_PERCENT: u64 = 98;

/// What followed a frame when it was emitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum After {
    /// This byte.
    Byte(u8),
    /// Nothing within the incomplete-frame timeout: no `00` (a glitch or a CRC's high byte
    /// comes within a character) followed it.
    Silence,
    /// Nothing yet (the frame went out on its own structure, or at the end of the input).
    Unknown,
}

/// Direction of a frame, for the key.
fn dir(sender: Sender) -> Option<u8> {
    match sender {
        Sender::Master => Some(0),
        Sender::Slave => Some(1),
        Sender::Unknown => None,
    }
}

/// The directions a frame from `sender` may have (either, after damage), without allocating:
/// this is asked of every frame that checks.
fn dirs(sender: Sender) -> &'static [u8] {
    match dir(sender) {
        Some(0) => &[0],
        Some(_) => &[1],
        None => &[0, 1],
    }
}

/// The learned lengths of one port.
#[derive(Debug, Clone, Default)]
pub(crate) struct LearnedLengths {
    seen: BTreeMap<(u8, u8, u8), [(u16, u32); PER_KEY]>,
    /// The function codes with a key in `seen`, as bits: the question asked of every frame
    /// that checks is answered without a map lookup for the functions never learned (the
    /// standard ones, whose lengths their structure fixes; the replay's speed).
    functions: [u64; 4],
    /// Off: nothing is learned (to measure what learning does).
    on: bool,
}

impl LearnedLengths {
    /// Whether any length of function `fc` is kept (of any unit, either direction).
    fn knows(&self, fc: u8) -> bool {
        self.functions[usize::from(fc / 64)] & (1 << (fc % 64)) != 0
    }

    pub(crate) fn new(on: bool) -> Self {
        Self { seen: BTreeMap::new(), functions: [0; 4], on }
    }

    /// A length a device's profile declares for `unit`'s function `fc` (`request` or answer):
    /// taken as [`FIRM`] × 4 sightings — it decides from the first frame on, and what the line
    /// shows for long enough still overrules it (a profile written for another firmware).
    pub(crate) fn declare(&mut self, unit: u8, fc: u8, request: bool, len: u16) {
        let key = (unit, fc, u8::from(!request));
        // The map's size first: a second search of it only when it is full.
        if self.seen.len() >= MAX_KEYS && !self.seen.contains_key(&key) {
            return;
        }
        self.functions[usize::from(key.1 / 64)] |= 1 << (key.1 % 64);
        let slots = self.seen.entry(key).or_default();
        if let Some(s) = slots.iter_mut().find(|(l, n)| *l == len && *n > 0) {
            s.1 = s.1.saturating_add(FIRM * 4);
        } else if let Some(s) = slots.iter_mut().min_by_key(|(_, n)| *n) {
            *s = (len, FIRM * 4);
        }
    }

    /// A valid frame `f` from `sender` was emitted, and `after` it what followed: a
    /// vendor request to a unit that never answers is followed by a silence, never by a byte
    /// when it goes out — such a unit's lengths were never learned, and its frames' trailing
    /// `00` stayed a coin toss all day.
    pub(crate) fn record(&mut self, f: &[u8], after: After, sender: Sender) {
        if !self.on || matches!(after, After::Unknown | After::Byte(0)) {
            return;
        }
        let (Some(d), [unit, fc, ..], Some(&last)) = (dir(sender), f, f.last()) else { return };
        if last == 0 {
            return;
        }
        let pdu = &f[1..f.len().saturating_sub(2).max(1)];
        let fixed = match d {
            0 => request_len(pdu),
            _ => response_len(pdu),
        };
        if matches!(fixed, PduLength::Exact(_)) {
            return;
        }
        let Ok(len) = u16::try_from(f.len()) else { return };
        let key = (*unit, *fc, d);
        // The map's size first: a second search of it only when it is full.
        if self.seen.len() >= MAX_KEYS && !self.seen.contains_key(&key) {
            return;
        }
        self.functions[usize::from(key.1 / 64)] |= 1 << (key.1 % 64);
        let slots = self.seen.entry(key).or_default();
        if let Some(s) = slots.iter_mut().find(|(l, n)| *l == len && *n > 0) {
            s.1 = s.1.saturating_add(1);
        } else if let Some(s) = slots.iter_mut().min_by_key(|(_, n)| *n) {
            // A new length takes the place of the rarest (a frame taken wrong in damage now
            // and then must not end learning for good).
            *s = (len, 1);
        }
    }

    /// Of `short` and `short + 1` bytes, the one this unit's function from `sender` was always
    /// seen with (at least [`SURE`] times, and never another length). A function seen with
    /// several lengths (sub-functions, variable data) decides nothing.
    pub(crate) fn choose(&self, unit: u8, fc: u8, sender: Sender, short: usize) -> Option<usize> {
        self.choose_among(unit, fc, sender, &[short, short + 1])
    }

    /// Of `short` and `short + 1` bytes, the one every sighting of this unit's function from
    /// `sender` had, however few (one is enough): too weak to decide alone, strong enough to put
    /// that length first, the other still shown (a unit's second vendor request ending in
    /// `00` is read as its first, certain one was).
    pub(crate) fn lean(&self, unit: u8, fc: u8, sender: Sender, short: usize) -> Option<usize> {
        if !self.knows(fc) {
            return None;
        }
        // Each direction the frame may have (either, after damage): its one length, if it fits.
        let mut fits = dirs(sender).iter().filter_map(|d| {
            let mut seen = self.seen.get(&(unit, fc, *d))?.iter().filter(|&&(_, n)| n > 0);
            let len = usize::from(seen.next()?.0);
            (seen.next().is_none() && (len == short || len == short + 1)).then_some(len)
        });
        let len = fits.next()?;
        fits.all(|other| other == len).then_some(len)
    }

    /// Does a CRC match of `len` bytes contradict what this unit's function was seen with —
    /// every direction `sender` may be has a firm length ([`FIRM`] sightings, [`FIRM_PERCENT`]
    /// of them) and none is `len`? Then the match is far likelier chance (1 in 65 536 per
    /// length tried, inside damage or noise) than the one odd frame of a device that sends
    /// the same vendor function with the same length all day (a corrupted request and
    /// the frame after it checked as one 21-byte "frame" of a function seen 7 and 14 bytes long).
    pub(crate) fn contradicts(&self, unit: u8, fc: u8, sender: Sender, len: usize) -> bool {
        if !self.knows(fc) {
            return false;
        }
        let dirs = dirs(sender);
        let mut firm = 0;
        for d in dirs {
            let Some(slots) = self.seen.get(&(unit, fc, *d)) else { return false };
            let total: u64 = slots.iter().map(|&(_, n)| u64::from(n)).sum();
            let Some(&(l, n)) = slots.iter().max_by_key(|&&(_, n)| n) else { return false };
            if n < FIRM || u64::from(n) * 100 < total * FIRM_PERCENT {
                return false;
            }
            if usize::from(l) == len {
                return false;
            }
            firm += 1;
        }
        firm > 0
    }

    /// Of the `candidates` (lengths at which the same bytes all check: a frame ending in
    /// `00 00` checks at three), the one this unit's function from `sender` was (nearly) always
    /// seen with.
    pub(crate) fn choose_among(&self, unit: u8, fc: u8, sender: Sender, candidates: &[usize]) -> Option<usize> {
        if !self.knows(fc) {
            return None;
        }
        // The length each direction was (nearly) always seen with (nobody can say who sent a
        // frame after damage: then either direction's).
        let dirs = dirs(sender);
        let mut fits = Vec::new();
        for slots in dirs.iter().filter_map(|d| self.seen.get(&(unit, fc, *d))) {
            let total: u64 = slots.iter().map(|&(_, n)| u64::from(n)).sum();
            let Some(&(len, n)) = slots.iter().max_by_key(|&&(_, n)| n) else { continue };
            let len = usize::from(len);
            if n >= SURE && u64::from(n) * 10 >= total * SHARE_TENTHS && candidates.contains(&len) {
                fits.push(len);
            }
        }
        fits.dedup();
        match fits.as_slice() {
            [one] => Some(*one),
            // Who sent it was guessed from the expectation, which damage misleads (a corrupted
            // request leaves the master expected, and the answer comes): where that direction's
            // firm length is none of the candidates, the other direction's may decide (else
            // an answer after a corrupted request reads as the master's request with its `00`
            // glitch, one byte short).
            [] if sender != Sender::Unknown && candidates.iter().all(|&l| self.contradicts(unit, fc, sender, l)) => {
                self.choose_among(unit, fc, Sender::Unknown, candidates)
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vendor request (function 0x41) from the master, CRC not ending in 00.
    fn vendor(unit: u8, data: &[u8]) -> Vec<u8> {
        let mut pdu = vec![0x41];
        pdu.extend_from_slice(data);
        let mut f = Vec::new();
        mbtap_proto::encode_rtu(unit, &pdu, &mut f);
        f
    }

    #[test]
    fn lengths_seen_unambiguously_decide_a_twin() {
        let mut l = LearnedLengths::new(true);
        let mut n = 0;
        for k in 0u8..=255 {
            let f = vendor(5, &[k, 1, 2]);
            if f.last() != Some(&0) {
                l.record(&f, After::Byte(0x11), Sender::Master);
                n += 1;
            }
            if n == 3 {
                break;
            }
        }
        // Frames of 7 bytes: between 7 and 8, 7.
        assert_eq!(l.choose(5, 0x41, Sender::Master, 7), Some(7));
        assert_eq!(l.choose(5, 0x41, Sender::Unknown, 6), Some(7));
        // Not learned for answers, nor for another unit.
        assert_eq!(l.choose(5, 0x41, Sender::Slave, 7), None);
        assert_eq!(l.choose(6, 0x41, Sender::Master, 7), None);
        // As often another length for the same key: it varies, nothing decides.
        let mut n = 0;
        for k in 0u8..=255 {
            let f = vendor(5, &[k, 1, 2, 3]);
            if f.last() != Some(&0) {
                l.record(&f, After::Byte(0x11), Sender::Master);
                n += 1;
            }
            if n == 3 {
                break;
            }
        }
        assert_eq!(l.choose(5, 0x41, Sender::Master, 7), None);
        // Standard functions have their structure: not learned.
        let mut f = Vec::new();
        mbtap_proto::encode_rtu(5, &[0x03, 0, 1, 0, 2], &mut f);
        l.record(&f, After::Byte(0x11), Sender::Master);
        assert_eq!(l.choose(5, 0x03, Sender::Master, 8), None);
    }

    /// A CRC match at a length a unit's vendor function is never seen with is
    /// vetoed only once the learned length is firm, and never for a length either direction
    /// has; with nothing learned, nothing is vetoed.
    #[test]
    fn only_a_firm_length_vetoes_another() {
        let mut l = LearnedLengths::new(true);
        assert!(!l.contradicts(5, 0x41, Sender::Unknown, 9));
        let (mut requests, mut k) = (0, 0u8);
        while requests < FIRM {
            let f = vendor(5, &[k, 1, 2]);
            k = k.wrapping_add(1);
            if f.last() != Some(&0) {
                l.record(&f, After::Byte(0x05), Sender::Master);
                requests += 1;
            }
            if requests == FIRM - 1 {
                // Not firm yet.
                assert!(!l.contradicts(5, 0x41, Sender::Master, 9));
            }
        }
        // Requests are 7 bytes (unit, code, 3 data, CRC).
        assert!(l.contradicts(5, 0x41, Sender::Master, 9));
        assert!(!l.contradicts(5, 0x41, Sender::Master, 7));
        // The answers' direction has learned nothing: who sent it unknown, no veto.
        assert!(!l.contradicts(5, 0x41, Sender::Unknown, 9));
        assert!(!l.contradicts(5, 0x41, Sender::Slave, 9));
        // Another unit: nothing learned.
        assert!(!l.contradicts(6, 0x41, Sender::Master, 9));
    }

    /// A vendor request to a unit that never answers goes out on the silence after it, no byte
    /// behind it, and is learned from: a silence after a frame rules out a `00` after it as
    /// surely as a byte does, so that unit's twins do not stay a coin toss all day.
    #[test]
    fn a_frame_followed_by_a_silence_teaches_its_length() {
        let mut l = LearnedLengths::new(true);
        let (mut n, mut k) = (0, 0u8);
        while n < SURE {
            let f = vendor(0x21, &[k, 1, 2, 3, 4]);
            k = k.wrapping_add(1);
            if f.last() != Some(&0) {
                l.record(&f, After::Unknown, Sender::Master);
                assert_eq!(l.choose(0x21, 0x41, Sender::Master, 8), None, "nothing after it yet: learns nothing");
                l.record(&f, After::Silence, Sender::Master);
                n += 1;
            }
        }
        assert_eq!(l.choose(0x21, 0x41, Sender::Master, 8), Some(9));
        // A `00` after it leaves its length open: not learned from.
        let mut m = LearnedLengths::new(true);
        for _ in 0..4 {
            m.record(&vendor(0x21, &[1, 1, 2, 3, 4]), After::Byte(0), Sender::Master);
        }
        assert_eq!(m.choose(0x21, 0x41, Sender::Master, 8), None);
    }

    /// One certain sighting puts that length first (with the other still shown);
    /// a function seen at two lengths leans nowhere.
    #[test]
    fn one_sighting_leans_a_twin_towards_its_length() {
        let mut l = LearnedLengths::new(true);
        let f = (0u8..=255).map(|k| vendor(5, &[k, 1])).find(|f| f.last() != Some(&0)).unwrap_or_default();
        l.record(&f, After::Byte(0x05), Sender::Master);
        // Too few to decide, enough to lean: 6 bytes, between 5 and 6.
        assert_eq!(l.choose(5, 0x41, Sender::Master, 5), None);
        assert_eq!(l.lean(5, 0x41, Sender::Master, 5), Some(6));
        assert_eq!(l.lean(5, 0x41, Sender::Unknown, 5), Some(6));
        assert_eq!(l.lean(5, 0x41, Sender::Slave, 5), None);
        assert_eq!(l.lean(5, 0x41, Sender::Master, 7), None);
        let g = (0u8..=255).map(|k| vendor(5, &[k, 1, 2])).find(|f| f.last() != Some(&0)).unwrap_or_default();
        l.record(&g, After::Byte(0x05), Sender::Master);
        assert_eq!(l.lean(5, 0x41, Sender::Master, 6), None);
    }

    /// After a corrupted request the framer still expects one, so the answer that follows is
    /// guessed to be the master's: where that direction's firm length fits neither of its twin
    /// readings, the answers' length decides — not the odds of the master's `00` glitch, which
    /// would read it one byte short.
    #[test]
    fn a_frame_whose_guessed_direction_fits_neither_twin_takes_the_other_s() {
        let mut l = LearnedLengths::new(true);
        let (mut n, mut k) = (0, 0u8);
        while n < FIRM {
            let (q, a) = (vendor(5, &[k, 1, 2]), vendor(5, &[k, 1, 2, 3, 4, 5, 6, 7]));
            k = k.wrapping_add(1);
            if q.last() != Some(&0) && a.last() != Some(&0) {
                l.record(&q, After::Byte(0x05), Sender::Master);
                l.record(&a, After::Byte(0x05), Sender::Slave);
                n += 1;
            }
        }
        // Requests 7 bytes, answers 12: a "request" that checks at 11 and 12 is an answer.
        assert_eq!(l.choose(5, 0x41, Sender::Master, 11), Some(12));
        assert_eq!(l.choose(5, 0x41, Sender::Slave, 11), Some(12));
        // Where the guessed direction's length is one of the two, it decides.
        assert_eq!(l.choose(5, 0x41, Sender::Master, 6), Some(7));
    }
}
