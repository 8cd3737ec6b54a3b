//! Typing from one or two samples by what holds across devices, where a series cannot be had: a
//! data logger reads each block once a minute, a capture of a few minutes holds one or two
//! samples per register. Each rule reads the bits of a sample as a value would have to look:
//!
//! - a 32-bit integer, high word first, whose value fits 16 bits' worth of magnitude more: a
//!   high word of `0x0000` beside a low word in its upper range (≥ `0x1000`: what a u16 beside
//!   a zero rarely is, and a float never is — `0x0000 xxxx` is a denormal), or `0xFFFF` beside
//!   a low word ≥ `0x8000` (a small negative, two's complement);
//! - an energy-like counter: across two samples the high word holds and the low word rises, or
//!   carries into the high word;
//! - a block of such pairs: where the master reads a block whose every pair, from the block's
//!   first register, has a high word a 32-bit value of its size would have (`0x0000`–`0x0FFF`,
//!   `0xFFFF` before a negative's low word, `0x8000 0000` the "no value" of a signed one) and at
//!   least a quarter of its pairs are decided by the rules above, every pair is one value: a
//!   device lays out a block of 32-bit values whole, and a master reads whole values; a read of
//!   exactly two registers, the first zero, is one such value.
//!
//! Signedness is what the bits show: signed where a negative was seen, else unsigned (the two
//! read alike below 2³¹). What one or two samples decide is said so, at a confidence of at most
//! [`FEW`]; `learn --confirm` reads the device again to settle it.

use std::collections::BTreeMap;

use super::kind::{Guess, Kind};
use super::stats::PairStat;

/// The most a decision from one or two samples is trusted.
pub const FEW: f64 = 0.5;

/// A high word of a 32-bit value of a size a device reports (up to 2²⁸).
const SMALL_HIGH: u16 = 0x0FFF;
/// A low word in its upper range: beside a zero high word, more likely a 32-bit value's.
const WIDE_LOW: u16 = 0x1000;

/// The integer the samples of `p` (high word first) show by their bits, with the reason and the
/// other reading (two 16-bit registers), so the draft keeps one entry and says both.
#[must_use]
pub fn int_by_bits(p: &PairStat) -> Option<(Kind, String)> {
    let (kind, why) = int_by_bits_alone(p)?;
    let &(h, l) = p.recent.back()?;
    Some((kind, format!("{why} (read as two 16-bit registers instead: {h} and {l})")))
}

fn int_by_bits_alone(p: &PairStat) -> Option<(Kind, String)> {
    let s: Vec<(u16, u16)> = p.recent.iter().copied().collect();
    let (first, last) = (s.first()?, s.last()?);
    let negative = |&(h, l): &(u16, u16)| h == 0xFFFF && (0x8000..0xFFFF).contains(&l);
    // A low word just under 0x10000 beside a zero reads better as a small negative of its own
    // (an i16 after a zero scale factor) than as a 32-bit value near 65 535.
    let zero_high_wide = s.iter().all(|&(h, l)| h == 0 && l < 0xF000) && s.iter().any(|&(_, l)| l >= WIDE_LOW);
    if s.iter().any(negative) && s.iter().all(|w| negative(w) || w.0 == 0) {
        return Some((
            Kind::I32 { high_first: true },
            format!("{:#06X} {:#06X}: a small negative 32-bit value (two's complement)", last.0, last.1),
        ));
    }
    if zero_high_wide {
        let rising = s.len() >= 2 && s.windows(2).all(|w| w[1].1 > w[0].1);
        return Some((
            Kind::U32 { high_first: true, counter: rising && s.len() >= 3 },
            format!(
                "{:#06X} {:#06X}: a zero high word beside a low word in its upper range, as a 32-bit value's",
                last.0, last.1
            ),
        ));
    }
    // Energy-like: the high word holds (or carries by one) while the whole rises.
    let value = |&(h, l): &(u16, u16)| (u32::from(h) << 16) | u32::from(l);
    let climbs = s.len() >= 2
        && s.windows(2).all(|w| value(&w[1]) > value(&w[0]) && value(&w[1]) - value(&w[0]) < 0x8000)
        && s.iter().all(|&(h, _)| h <= SMALL_HIGH)
        && (first.0 != last.0 || first.1 != last.1);
    let carried = s.windows(2).any(|w| w[1].0 == w[0].0.wrapping_add(1));
    if climbs && (s.windows(2).all(|w| w[1].0 == w[0].0) || carried) {
        return Some((
            // Two samples rising say "like a total", not yet "a counter".
            Kind::U32 { high_first: true, counter: s.len() >= 3 },
            format!(
                "{} samples, {} to {}: the high word held{} while the whole rose, as an energy total does",
                s.len(),
                value(first),
                value(last),
                if carried { " (or carried)" } else { "" }
            ),
        ));
    }
    None
}

/// Whether a pair could be one 32-bit value by its high word (the block rule's test).
fn fits(p: &PairStat) -> bool {
    p.recent.iter().all(|&(h, l)| h <= SMALL_HIGH || (h == 0xFFFF && l >= 0x8000) || (h == 0x8000 && l == 0))
}

/// The kind the bits of `p` show, else the plain 32-bit value its high word says (signed where
/// the high word is all ones or a signed value's "no value"), with the reason.
fn kind_of(p: &PairStat, decided: Option<(Kind, String)>, otherwise: &str) -> (Kind, String) {
    decided.unwrap_or_else(|| {
        let signed = p.recent.iter().any(|&(h, _)| h == 0xFFFF || h == 0x8000);
        let kind = if signed { Kind::I32 { high_first: true } } else { Kind::U32 { high_first: true, counter: false } };
        (kind, otherwise.to_owned())
    })
}

/// One joined pair's guess, trusted no more than a few samples allow.
fn joined(address: u16, p: &PairStat, kind: Kind, evidence: String) -> Guess {
    Guess { address, kind, confidence: FEW.min(super::series::confidence(p.samples, 1)), evidence }
}

/// The pairs the block rule joins: first address → kind and evidence. `blocks`: (first,
/// quantity) of the table's reads; `pair(a)`: the joint samples of `a` and `a + 1`.
#[must_use]
pub fn int_blocks<'a>(blocks: &[(u16, u16)], pair: &dyn Fn(u16) -> Option<&'a PairStat>) -> BTreeMap<u16, Guess> {
    let mut out = BTreeMap::new();
    // A series decides where there is one ([`super::infer`]): these rules are for few samples.
    let few = |p: &PairStat| usize::try_from(p.samples).unwrap_or(usize::MAX) < super::series::ENOUGH;
    for &(first, quantity) in blocks {
        // A read of exactly two registers is one value (masters read whole values): one whose
        // high word is zero, or all ones before a negative's low word, is an integer's — a
        // float's never is.
        if quantity == 2
            && let Some(p) = pair(first)
            && few(p)
            && !p.recent.is_empty()
            && p.recent.iter().all(|&(h, l)| h == 0 || (h == 0xFFFF && l >= 0x8000))
            && p.recent.iter().any(|&(h, l)| h != 0 || l != 0)
        {
            let (kind, why) = kind_of(p, int_by_bits(p), "a zero high word");
            let evidence = format!("{} sample(s): {why}; the master reads exactly these two registers", p.samples);
            out.entry(first).or_insert_with(|| joined(first, p, kind, evidence));
            continue;
        }
        if quantity < 4 || quantity % 2 != 0 {
            continue;
        }
        let starts: Vec<u16> = (0..quantity / 2).filter_map(|k| first.checked_add(2 * k)).collect();
        let pairs: Vec<&PairStat> = starts.iter().filter_map(|&a| pair(a)).collect();
        if pairs.len() != starts.len() || pairs.iter().any(|p| p.recent.is_empty() || !few(p) || !fits(p)) {
            continue;
        }
        // Each pair's bits read once: they count towards the block and type the pair.
        let by_bits: Vec<Option<(Kind, String)>> = pairs.iter().map(|p| int_by_bits(p)).collect();
        let decided = by_bits.iter().filter(|d| d.is_some()).count();
        if decided < 2 || decided * 4 < pairs.len() {
            continue;
        }
        for ((&a, p), bits) in starts.iter().zip(&pairs).zip(by_bits) {
            let (kind, why) = kind_of(p, bits, "its high word a 32-bit value's");
            let evidence = format!(
                "{} sample(s): {why}; the block at {first} ({quantity} registers) reads as {} such pairs from its \
                 first register, {decided} decided by their bits",
                p.samples,
                pairs.len()
            );
            out.entry(a).or_insert_with(|| joined(a, p, kind, evidence));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(samples: &[(u16, u16)]) -> PairStat {
        PairStat::of(samples)
    }

    #[test]
    fn one_or_two_samples_decide_a_32_bit_integer_by_its_bits() {
        // 31 250 (0x7A12) beside a zero high word: a power in 0.1 W, u32.
        assert!(matches!(int_by_bits(&pair(&[(0x0000, 0x7A12)])), Some((Kind::U32 { .. }, _))));
        // −150 as an i32: 0xFFFF 0xFF6A.
        assert!(matches!(int_by_bits(&pair(&[(0xFFFF, 0xFF6A)])), Some((Kind::I32 { .. }, _))));
        // 78 232 → 78 233 (0x0001 0x3198 → 0x3199): an energy total in 0.1 kWh; a counter once
        // a third sample rises too.
        assert!(matches!(
            int_by_bits(&pair(&[(0x0001, 0x3198), (0x0001, 0x3199)])),
            Some((Kind::U32 { counter: false, .. }, _))
        ));
        assert!(matches!(
            int_by_bits(&pair(&[(0x0001, 0x3198), (0x0001, 0x3199), (0x0001, 0x31A0)])),
            Some((Kind::U32 { counter: true, .. }, _))
        ));
        // Two small u16 (a status of 1 and 89 A) say nothing; nor do two 0xFFFF ("no value").
        assert_eq!(int_by_bits(&pair(&[(0x0001, 0x0059)])), None);
        assert_eq!(int_by_bits(&pair(&[(0xFFFF, 0xFFFF)])), None);
        // A float's high word is never small: 230.1 (0x4366 0x1999) is no integer here.
        assert_eq!(int_by_bits(&pair(&[(0x4366, 0x1999), (0x4366, 0x1A00)])), None);
    }

    #[test]
    fn a_block_of_such_pairs_is_read_whole() {
        // SMA-like yields: 12 345 678 Wh (0x00BC 0x614E), 12 345 kWh, 12 MWh, 15 230 Wh.
        const BLOCK: [(u16, u16); 4] = [(0x00BC, 0x614E), (0x0000, 0x3039), (0x0000, 0x000C), (0x0000, 0x3B7E)];
        let pairs: BTreeMap<u16, PairStat> = (0u16..).step_by(2).zip(BLOCK).map(|(a, w)| (a, pair(&[w]))).collect();
        let joined = int_blocks(&[(0, 8)], &|a| pairs.get(&a));
        assert_eq!(joined.keys().copied().collect::<Vec<_>>(), [0, 2, 4, 6]);
        assert!(joined.values().all(|g| g.confidence <= FEW));
        // A block whose pairs mix a u16 at 0x7A12 into a high word: not one of 32-bit values.
        let mixed: BTreeMap<u16, PairStat> =
            [(0, pair(&[(0x0001, 0x0000)])), (2, pair(&[(0x7A12, 0x0DAC)]))].into_iter().collect();
        assert!(int_blocks(&[(0, 4)], &|a| mixed.get(&a)).is_empty());
    }
}
