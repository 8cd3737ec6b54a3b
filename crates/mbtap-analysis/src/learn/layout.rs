//! How a device lays out its 32-bit floats, judged over whole blocks rather than pair by pair
//!: a device uses one word order, and the master reads whole values, so pairs start
//! at the block's first register and every second one after it. A pair alone cannot say this —
//! in a block of floats, the pair straddling two values (one's low word, the next one's high
//! word) reads as a plausible float in the other word order exactly as often as the true pairs
//! do — but the blocks together can: the pairs aligned with the blocks' starts vote on the word
//! order by their bits (a plausible float one way and absurd the other), and each block's
//! alignment is then the one whose pairs read as floats in that order.
//!
//! A table whose votes disagree (a device mixing word orders, or no float at all) gets no
//! layout, and its pairs are judged one by one ([`super::infer`]). Where it has one,
//! [`laid_out`] types the pair at each of its starts.

use std::collections::BTreeMap;

use super::kind::{Guess, Kind};
use super::series::{confidence, join, ordered, smooth};
use super::stats::{PairStat, RegStat};

/// An IEEE-754 single a meter would report: zero, or a normal number from 1e-4 to 1e8 in
/// magnitude. A float's high word outside 0x38D1–0x4CBE (or its negative twin) reads as a
/// denormal, a tiny or a huge number: what two small integers or a mantissa's low half give.
#[must_use]
pub fn plausible_float(bits: u32) -> bool {
    let f = f32::from_bits(bits);
    f == 0.0 || (f.is_normal() && (1e-4..=1e8).contains(&f.abs()))
}

/// The pair's samples as (high word, low word) in this word order.
fn value((a, b): (u16, u16), high_first: bool) -> u32 {
    let (hi, lo) = if high_first { (a, b) } else { (b, a) };
    (u32::from(hi) << 16) | u32::from(lo)
}

/// Whether every sample of `p` is a plausible float in this word order, and not all zero.
#[must_use]
pub fn floats_in(p: &PairStat, high_first: bool) -> bool {
    !p.recent.is_empty()
        && p.recent.iter().all(|&w| plausible_float(value(w, high_first)))
        && p.recent.iter().any(|&w| value(w, high_first) != 0)
}

/// The word order the bits of `p` decide: a plausible float in every sample one way, and absurd
/// in some sample the other way.
#[must_use]
pub fn bits_order(p: &PairStat) -> Option<bool> {
    match (floats_in(p, true), floats_in(p, false)) {
        (true, false) => Some(true),
        (false, true) => Some(false),
        _ => None,
    }
}

/// A table's float layout: the word order its blocks agree on, and where pairs start.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Layout {
    pub high_first: bool,
    /// Pairs decided by their bits for this order, and against it (the evidence).
    pub votes: u32,
    pub against: u32,
    /// Register address → whether a pair starts there (only registers inside a block).
    starts: BTreeMap<u16, bool>,
}

impl Layout {
    /// Whether a pair starts at `a` in the blocks (`None`: `a` is in no block).
    #[must_use]
    pub fn starts_at(&self, a: u16) -> Option<bool> {
        self.starts.get(&a).copied()
    }

    /// The layout of a table from its blocks (first address, quantity) and its adjacent pairs,
    /// when the blocks agree on one word order: at least one pair decided by its bits, and
    /// fewer than one in four of the blocks' votes for the other order. `heard(a)`
    /// tells whether register `a` was heard (only those are given a place).
    #[must_use]
    pub fn decide<'a>(
        blocks: &[(u16, u16)],
        pair: &dyn Fn(u16) -> Option<&'a PairStat>,
        heard: &dyn Fn(u16) -> bool,
    ) -> Option<Self> {
        // Votes per block: [aligned with the start, shifted by one] × [high first, low first].
        let votes_of = |&(first, quantity): &(u16, u16)| {
            let mut v = [[0u32; 2]; 2];
            for k in 0..quantity.saturating_sub(1) {
                let Some(a) = first.checked_add(k) else { break };
                if let Some(order) = pair(a).and_then(bits_order) {
                    v[usize::from(k % 2)][usize::from(!order)] += 1;
                }
            }
            v
        };
        let per_block: Vec<[[u32; 2]; 2]> = blocks.iter().map(votes_of).collect();
        // Each block votes for the order of its best alignment, the block's start preferred:
        // in a block of floats the straddling pairs (shifted by one) read as floats in the other
        // order about as often as the true ones, but never more often. A block where the other
        // order shifted ties with one order aligned (a 16-bit register, then floats) says
        // nothing of the order.
        let (mut high, mut low) = (0, 0);
        for v in &per_block {
            let best = |s: usize| if v[s][0] >= v[s][1] { (true, v[s][0]) } else { (false, v[s][1]) };
            let (aligned, shifted) = (best(0), best(1));
            if aligned.1 == shifted.1 && aligned.0 != shifted.0 {
                continue;
            }
            // Both orders' votes at the block's alignment: a block mixing them is against.
            let s = usize::from(shifted.1 > aligned.1);
            high += v[s][0];
            low += v[s][1];
        }
        let (high_first, votes, against) = if high >= low { (true, high, low) } else { (false, low, high) };
        if votes == 0 || against * 4 >= votes {
            return None;
        }
        let o = usize::from(!high_first);
        // Bigger blocks first: where blocks overlap, the one that holds more of the device's
        // registers places the pairs.
        let mut order: Vec<usize> = (0..blocks.len()).collect();
        order.sort_by_key(|&i| std::cmp::Reverse(blocks[i].1));
        let mut starts = BTreeMap::new();
        for i in order {
            let (first, quantity) = blocks[i];
            // Shifted only when more of the block's pairs read as floats in the device's order
            // that way (a block opening with a 16-bit register, then floats).
            let shift = u16::from(per_block[i][1][o] > per_block[i][0][o]);
            for k in 0..quantity {
                let Some(a) = first.checked_add(k) else { break };
                if heard(a) {
                    starts.entry(a).or_insert(k >= shift && (k - shift) % 2 == 0);
                }
            }
        }
        Some(Self { high_first, votes, against, starts })
    }
}

/// Whether every sample of `p` in this word order is a float of at most five significant
/// digits (its shortest decimal form): a value a person set or a device rounded.
pub(super) fn round_floats(p: &PairStat, high_first: bool) -> bool {
    p.recent.iter().all(|&(x, y)| {
        let shown = f32::from_bits(join(x, y, high_first)).to_string();
        let digits: String = shown.chars().filter(char::is_ascii_digit).collect();
        digits.trim_start_matches('0').trim_end_matches('0').len() <= 5
    })
}

/// The pair at `regs[i]`, `regs[i + 1]`, where the table's layout starts one, as a float in the
/// layout's word order: every sample a plausible number (not all zero) and, if it moved, moving
/// smoothly. A pair that never changed is typed by its bits and the layout.
pub(super) fn laid_out<'a>(
    regs: &[(u16, &'a RegStat)],
    pair: &dyn Fn(u16) -> Option<&'a PairStat>,
    i: usize,
    l: &Layout,
) -> Option<Guess> {
    let &(a, r) = regs.get(i)?;
    let &(b, r2) = regs.get(i + 1)?;
    if u32::from(b) != u32::from(a) + 1 {
        return None;
    }
    let p = pair(a)?;
    let h = l.high_first;
    let values: Vec<u32> = ordered(p, h).iter().map(|&(hi, lo)| (u32::from(hi) << 16) | u32::from(lo)).collect();
    let still = r.changes == 0 && r2.changes == 0;
    if !floats_in(p, h) || !(still || smooth(&values)) {
        return None;
    }
    let last = values.last().map(|&v| f32::from_bits(v)).unwrap_or_default();
    // Both word orders plausible (0x4120 0x4120): the layout alone decides, said so.
    let by_bits = bits_order(p) == Some(h);
    let c = confidence(p.samples, r.changes.max(r2.changes));
    Some(Guess {
        address: a,
        kind: Kind::F32 { high_first: h },
        confidence: if by_bits { c } else { c.min(0.3) },
        evidence: format!(
            "{} joint samples, every one a plausible float {} ({}last {last}){}; the table's blocks read as floats \
             this way ({} pairs decided by their bits, {} against)",
            p.samples,
            if h { "high word first" } else { "low word first" },
            if still { "never changed, " } else { "moving smoothly, " },
            if by_bits { "" } else { " — the other word order is plausible too" },
            l.votes,
            l.against,
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(samples: &[(u16, u16)]) -> PairStat {
        PairStat::of(samples)
    }

    /// A single-phase meter's block of floats high word first, two of them zero. Pair
    /// by pair, the straddles around the zeros read as floats low word first (0x0000 0x3F99 as
    /// 1.2); over the block, the pairs aligned with its start decide: high word first, pairs at
    /// 8192, 8194, … .
    #[test]
    fn the_block_decides_the_word_order_and_where_pairs_start() {
        // 230.1, 4.71, 1083.0, 0.0, 1.2, 0.98, 0.0, 50.05 (0x4248 0x3333), high word first.
        const WORDS: [u16; 16] = [
            0x4366, 0x1999, 0x4096, 0xB852, 0x4487, 0x6000, 0x0000, 0x0000, 0x3F99, 0x999A, 0x3F7A, 0xE148, 0x0000,
            0x0000, 0x4248, 0x3333,
        ];
        let pairs: BTreeMap<u16, PairStat> =
            (0..15u16).map(|k| (0x2000 + k, pair(&[(WORDS[usize::from(k)], WORDS[usize::from(k) + 1])]))).collect();
        let l = Layout::decide(&[(0x2000, 16)], &|a| pairs.get(&a), &|_| true).unwrap();
        assert!(l.high_first);
        assert_eq!((l.votes, l.against), (6, 0));
        assert_eq!(l.starts_at(0x200E), Some(true));
        assert_eq!(l.starts_at(0x200D), Some(false));
        assert_eq!(l.starts_at(0x3000), None);
    }

    /// A device mixing word orders (as `truth::Device` does) has no layout: its pairs are judged
    /// one by one.
    #[test]
    fn blocks_that_disagree_give_no_layout() {
        let hi = pair(&[(0x4366, 0x1999)]);
        let lo = pair(&[(0x1999, 0x4366)]);
        let pairs: BTreeMap<u16, &PairStat> = [(0, &hi), (2, &lo)].into_iter().collect();
        assert_eq!(Layout::decide(&[(0, 4)], &|a| pairs.get(&a).copied(), &|_| true), None);
    }

    /// A block opening with a 16-bit register and then floats is shifted by one.
    #[test]
    fn a_block_opening_with_a_single_register_is_shifted() {
        // Block 0–6: a u16 (7), then 13.09 (0x4151 0x70A4), 10.32 (0x4125 0x1EB8), 230.1 —
        // alone, as likely three floats low word first from 0 (0x4151_0007 is 13.06).
        const WORDS: [u16; 7] = [0x0007, 0x4151, 0x70A4, 0x4125, 0x1EB8, 0x4366, 0x1999];
        // A second block elsewhere, aligned (230.1, 4.71), decides the order: high word first.
        const OTHER: [u16; 4] = [0x4366, 0x1999, 0x4096, 0xB852];
        let mut pairs: BTreeMap<u16, PairStat> =
            (0..6u16).map(|k| (k, pair(&[(WORDS[usize::from(k)], WORDS[usize::from(k) + 1])]))).collect();
        pairs.extend((0..3u16).map(|k| (100 + k, pair(&[(OTHER[usize::from(k)], OTHER[usize::from(k) + 1])]))));
        let l = Layout::decide(&[(0, 7), (100, 4)], &|a| pairs.get(&a), &|_| true).unwrap();
        assert!(l.high_first);
        assert_eq!(
            (0..7).map(|a| l.starts_at(a).unwrap()).collect::<Vec<_>>(),
            [false, true, false, true, false, true, false]
        );
    }
}
