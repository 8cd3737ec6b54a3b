//! What a register (or two, or a run of them) probably holds, from what was heard: the tests
//! and their order. Every guess carries its evidence in words. Two adjacent registers are read
//! as one 32-bit value only when the series say so — a float whose every sample is a plausible
//! number that moves smoothly, or an integer whose high word changes only as the carry of its
//! low word — so two registers that move independently are never joined.

use std::collections::BTreeSet;

use super::stats::{PairStat, RegStat};

pub use super::kind::{Guess, Kind};

use super::layout::{Layout, laid_out, plausible_float, round_floats};
use super::series::{ENOUGH, confidence, join, ordered, smooth};

/// How the high word's steps of one agree with the low word: (carries, contradictions).
/// A carry is the high word moving by one while the low word wraps the other way (up by one as
/// the low word falls from near the top to near zero, or down as it climbs back); a
/// contradiction is a step of one with the low word moving the same way, as two registers that
/// move independently do half the time.
fn carries(words: &[(u16, u16)]) -> (u32, u32) {
    let (mut yes, mut no) = (0, 0);
    for w in words.windows(2) {
        let ((h0, l0), (h1, l1)) = (w[0], w[1]);
        let up = h1 == h0.wrapping_add(1);
        let down = h1 == h0.wrapping_sub(1);
        if !(up || down) {
            continue;
        }
        let wrapped_down = l0 >= 0x8000 && l1 < 0x8000;
        let wrapped_up = l0 < 0x8000 && l1 >= 0x8000;
        if (up && wrapped_down) || (down && wrapped_up) {
            yes += 1;
        } else {
            no += 1;
        }
    }
    (yes, no)
}

/// Mean absolute step of a series, over its span: 0 for a constant, about 1/3 for noise.
#[allow(clippy::cast_precision_loss)]
fn roughness(v: &[f64]) -> f64 {
    let (lo, hi) = v.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    if v.len() < 2 || hi <= lo {
        return 0.0;
    }
    v.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / (v.len() - 1) as f64 / (hi - lo)
}

/// A float in this word order, and how well it fits: every sample a plausible number, several
/// values, moving smoothly (the median change under 5 % of the value), its low word varying
/// like a mantissa's, and where the high word steps by one, a carry (never a contradiction
/// more often than a carry). The score counts carries.
#[allow(clippy::cast_precision_loss)]
fn float_fit(pair: &PairStat, high_first: bool) -> Option<u32> {
    let words = ordered(pair, high_first);
    let values: Vec<u32> = words.iter().map(|&(h, l)| (u32::from(h) << 16) | u32::from(l)).collect();
    if values.len() < ENOUGH || !values.iter().all(|&v| plausible_float(v)) {
        return None;
    }
    let mut lows: Vec<u16> = words.iter().map(|&(_, l)| l).collect();
    lows.sort_unstable();
    lows.dedup();
    if lows.len() < ENOUGH {
        return None;
    }
    if !smooth(&values) {
        return None;
    }
    let (yes, no) = carries(&words);
    (no <= yes / 4).then_some(yes + 1)
}

/// A float in this word order from a short series (fewer than [`ENOUGH`] joint samples, down
/// to a single snapshot — what a pasted log or a short recording holds): every sample a
/// plausible number and not all zero, the other word order *not* plausible in some sample (so
/// the order is decided by the bits, not guessed), and the high word changing no more often
/// than the low word (a mantissa's low half moves first). Weaker evidence than a series, and
/// said so; a random pair of registers passes about one time in seven, so the confidence
/// stays low.
fn short_float_fit(pair: &PairStat, high_first: bool) -> bool {
    let words = ordered(pair, high_first);
    if words.is_empty() || words.len() >= ENOUGH {
        return false;
    }
    let value = |&(h, l): &(u16, u16)| (u32::from(h) << 16) | u32::from(l);
    let this = words.iter().all(|w| plausible_float(value(w))) && words.iter().any(|&(h, _)| h != 0);
    let other = words.iter().all(|&(h, l)| plausible_float(value(&(l, h))));
    let steps = |f: fn(&(u16, u16)) -> u16| words.windows(2).filter(|w| f(&w[0]) != f(&w[1])).count();
    this && !other && steps(|w| w.0) <= steps(|w| w.1)
}

/// A 32-bit integer in this word order: the high word takes more than one value and either
/// changes only as its low word's carry, or the low word alone jumps about (wrapping) while
/// the two together move smoothly. Signed when the high word is found on both sides of zero
/// (0xFFFF… and 0x0000…). The score counts carries.
fn int_fit(pair: &PairStat, high_first: bool) -> Option<(Kind, u32)> {
    let words = ordered(pair, high_first);
    if words.len() < ENOUGH {
        return None;
    }
    let highs: BTreeSet<u16> = words.iter().map(|&(h, _)| h).collect();
    if highs.len() < 2 {
        return None;
    }
    let (yes, no) = carries(&words);
    let small_high_steps = words.windows(2).all(|w| {
        let d = w[1].0.wrapping_sub(w[0].0);
        d <= 16 || d >= 0xFFF0
    });
    let signed = highs.iter().any(|&h| h >= 0xFFF0) && highs.iter().any(|&h| h <= 0x000F);
    let combined: Vec<f64> = words
        .iter()
        .map(|&(h, l)| {
            let v = (u32::from(h) << 16) | u32::from(l);
            if signed { f64::from(v.cast_signed()) } else { f64::from(v) }
        })
        .collect();
    let low: Vec<f64> = words.iter().map(|&(_, l)| f64::from(l)).collect();
    // Two carries and no contradiction; or a low word that jumps about (a large value's low
    // half) while the whole moves smoothly — there steps of one in the high word come with big
    // moves of the low word either way, so carries cannot be counted.
    let by_carries = yes >= 2 && no == 0;
    let by_smoothing = small_high_steps && roughness(&low) > 0.15 && roughness(&combined) < 0.1;
    if !(by_carries || by_smoothing) {
        return None;
    }
    let only_up = combined.windows(2).all(|w| w[1] >= w[0]);
    let kind = if signed { Kind::I32 { high_first } } else { Kind::U32 { high_first, counter: only_up } };
    Some((kind, yes + 1))
}

/// Text: a run of at least two registers whose every sample is printable ASCII, and which
/// (as names, models and serial numbers do) changes rarely if ever — a float's high word can be
/// printable in every sample too (0x43 0x66 is "Cf"), but it moves.
fn texty(r: &RegStat) -> bool {
    r.samples > 0 && r.ascii == r.samples && r.changes * 20 <= r.samples
}

/// String lengths devices give their text fields, in registers (serial numbers of 10, 16, 20
/// characters; SunSpec's 8 and 16 registers).
const TEXT_LENGTHS: [usize; 12] = [2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32];

/// A text run of `run` registers at `regs[i]` to its full length: the NUL or space padding after
/// it (registers that held only `0x0000` or `0x2020`), taken up to the longest usual string
/// length it reaches — a field is padded to its size, and what lies past the usual size is a
/// value of its own.
fn padded_length(regs: &[(u16, &RegStat)], i: usize, run: usize) -> usize {
    let Some(&(a, _)) = regs.get(i) else { return run };
    let padding = regs[i + run..]
        .iter()
        .enumerate()
        .take_while(|(k, (addr, r))| {
            usize::from(*addr) == usize::from(a) + run + k && r.min == r.max && matches!(r.min, 0x0000 | 0x2020)
        })
        .count();
    let total = (run + padding).min(32);
    TEXT_LENGTHS.iter().rev().copied().find(|&n| n <= total && n >= run).unwrap_or(run)
}

fn text_of(regs: &[&RegStat]) -> String {
    regs.iter().filter_map(|r| r.last).flat_map(u16::to_be_bytes).filter(|&b| b != 0).map(char::from).collect()
}

/// One register on its own.
#[allow(clippy::cast_possible_wrap)]
fn single(address: u16, r: &RegStat) -> Guess {
    let c = confidence(r.samples, r.changes);
    // A value just under 0x10000 among small ones is a small negative (two's complement): a
    // scale factor of −2, a temperature of −8.1 °C, a power factor of −0.98 — a u16 there would
    // be a reading near its top, which few are. 0xFFFF alone is left: many maps' "no value".
    let negative = |v: u16| (0xF000..0xFFFF).contains(&v);
    let small_negative = r.recent.iter().all(|&v| v <= 0x0FFF || negative(v)) && r.recent.iter().any(|&v| negative(v));
    let (kind, evidence) = if r.changes == 0 && small_negative {
        (Kind::I16, format!("{} samples, always {} ({}): a small negative", r.samples, r.min, r.min.cast_signed()))
    } else if r.changes == 0 {
        (Kind::Constant, format!("{} samples, always {}", r.samples, r.min))
    } else if r.downs == 0 && r.ups >= 3 && r.wraps <= (r.ups / 4).max(1) {
        (Kind::Counter, format!("{} samples, rose {} times, wrapped {} times, never fell", r.samples, r.ups, r.wraps))
    } else if r.low_quarter > 0 && r.high_quarter > 0 && {
        let (lo, hi) = r.recent.iter().fold((i16::MAX, i16::MIN), |(lo, hi), &v| (lo.min(v as i16), hi.max(v as i16)));
        lo > -16_384 && hi < 16_384
    } {
        (Kind::I16, format!("{} samples, values on both sides of zero (wrapping 0 ↔ 65535)", r.samples))
    } else if small_negative && r.one_bit_changes < r.changes.max(1) {
        (
            Kind::I16,
            format!(
                "{} samples, last {}: values just under 0x10000 among small ones, small negatives",
                r.samples,
                r.last.map_or(0, u16::cast_signed)
            ),
        )
    } else if r.one_bit_changes == r.changes && r.flipped_bits.count_ones() >= 2 && r.changes >= 3 {
        (
            Kind::Bits(r.flipped_bits),
            format!("{} changes, each flipping one bit; bits that changed: {:#06X}", r.changes, r.flipped_bits),
        )
    } else if !r.many_distinct && r.distinct.len() <= 8 && r.max <= 255 {
        let mut values = r.distinct.clone();
        values.sort_unstable();
        let shown: Vec<String> = values.iter().map(u16::to_string).collect();
        (Kind::Enum(values), format!("{} samples, only {} values: {}", r.samples, shown.len(), shown.join(", ")))
    } else {
        (Kind::U16, format!("{} samples from {} to {}, {} changes", r.samples, r.min, r.max, r.changes))
    };
    Guess { address, kind, confidence: c, evidence }
}

/// Guesses for one table's registers: `regs` by address, `pair(a)` the joint samples of `a` and
/// `a + 1` when they were read together, `layout` the table's float layout when its blocks agree
/// on one ([`Layout::decide`]): there a pair where the layout starts one is read in the
/// layout's word order by its bits, however still it sat, and no float is joined across the
/// layout's pairs.
pub fn guess_table<'a>(
    regs: &[(u16, &'a RegStat)],
    pair: &dyn Fn(u16) -> Option<&'a PairStat>,
    layout: Option<&Layout>,
    still: &std::collections::BTreeMap<u16, bool>,
    ints: &std::collections::BTreeMap<u16, Guess>,
) -> Vec<Guess> {
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(&(a, r)) = regs.get(i) {
        let start = layout.and_then(|l| l.starts_at(a));
        // A run of text: consecutive addresses, every sample printable; a NUL ends a text, so
        // the run stops after the register holding one ("0\0" ends "DG1.0": what follows is
        // another field).
        let mut run = 0;
        for (k, (addr, reg)) in regs[i..].iter().enumerate() {
            if usize::from(*addr) != usize::from(a) + k || !texty(reg) {
                break;
            }
            run += 1;
            if reg.last.is_some_and(|v| v.to_be_bytes()[1] == 0) {
                break;
            }
        }
        // Printable words that the layout reads as floats pair by pair, each a short decimal
        // (0x3F33 0x3333 is "?333" and 0.7), are floats: a rating or a factor stored as a float
        // is a round number, where text read as a float has a mantissa of many digits
        // ("ABCD" is 12.141422).
        let floats_too = layout.is_some_and(|l| {
            start == Some(true)
                && run % 2 == 0
                && (0..run / 2).all(|k| {
                    u16::try_from(2 * k)
                        .ok()
                        .and_then(|k| a.checked_add(k))
                        .and_then(pair)
                        .is_some_and(|p| super::layout::floats_in(p, l.high_first) && round_floats(p, l.high_first))
                })
        });
        if run >= 2 && !floats_too {
            let padded = padded_length(regs, i, run);
            let part: Vec<&RegStat> = regs[i..i + padded].iter().map(|(_, r)| *r).collect();
            let text = text_of(&part);
            let registers = u16::try_from(padded).unwrap_or(u16::MAX);
            out.push(Guess {
                address: a,
                confidence: confidence(r.samples, 8),
                evidence: if padded > run {
                    format!(
                        "{run} registers of printable ASCII in every sample: {text:?}, padded with NULs or spaces to {padded}"
                    )
                } else {
                    format!("{run} registers of printable ASCII in every sample: {text:?}")
                },
                kind: Kind::Text { registers, text },
            });
            i += padded;
            continue;
        }
        if let (Some(l), Some(true)) = (layout, start)
            && let Some(g) = laid_out(regs, pair, i, l)
        {
            out.push(g);
            i += 2;
            continue;
        }
        // A block of 32-bit integers read whole (few samples): its pairs as the block says.
        if let (Some(g), Some(&(b, _))) = (ints.get(&a), regs.get(i + 1))
            && u32::from(b) == u32::from(a) + 1
        {
            out.push(g.clone());
            i += 2;
            continue;
        }
        // Where the layout has no pair start, a float decided by its bits alone (a short series)
        // would straddle two of the layout's: only a series may show one there.
        let few = |g: &Guess| pair(g.address).is_none_or(|p| usize::try_from(p.samples).unwrap_or(usize::MAX) < ENOUGH);
        // Inside a float layout's block, off its pair starts: a float only from a series, and no
        // integer decided by a few samples' bits.
        let allowed = |g: &Guess, start: Option<bool>| {
            start != Some(false) || !few(g) || !(matches!(g.kind, Kind::F32 { .. }) || g.kind.width() == 2)
        };
        if let Some((g, score)) = wide_at(regs, pair, i).filter(|(g, _)| allowed(g, start)) {
            // The pair starting one register later may be the real one (this register being a
            // value of its own): the better evidence wins.
            let later_start = layout.and_then(|l| l.starts_at(a.saturating_add(1)));
            let later = wide_at(regs, pair, i + 1).filter(|(g, _)| allowed(g, later_start)).map_or(0, |(_, s)| s);
            if later <= score {
                out.push(g);
                i += 2;
                continue;
            }
        }
        if let (Some(&high_first), Some(&(b, r2))) = (still.get(&a), regs.get(i + 1))
            && u32::from(b) == u32::from(a) + 1
        {
            out.push(still_wide(a, r, r2, high_first));
            i += 2;
            continue;
        }
        out.push(single(a, r));
        i += 1;
    }
    out
}

/// The pair `a`, `a + 1` as a 32-bit value whose high word never moved (its table's blocks say
/// so: [`super::still_words`]), trusted no more than that evidence.
fn still_wide(a: u16, r: &RegStat, r2: &RegStat, high_first: bool) -> Guess {
    let (high, low) = if high_first { (r, r2) } else { (r2, r) };
    let counter = low.downs == 0 && low.ups > 0;
    Guess {
        address: a,
        kind: Kind::U32 { high_first, counter },
        confidence: confidence(r.samples, low.changes).min(super::still_words::CONFIDENCE),
        evidence: format!(
            "{} samples; the {} word stayed {} while the other moved, as in every moving pair of its blocks: \
             a 32-bit value whose high word did not change while recorded",
            r.samples,
            if high_first { "first" } else { "second" },
            high.min,
        ),
    }
}

/// The pair at `regs[i]`, `regs[i + 1]` (adjacent addresses, read together, at least one
/// moving) as one 32-bit value, with its score.
fn wide_at<'a>(
    regs: &[(u16, &'a RegStat)],
    pair: &dyn Fn(u16) -> Option<&'a PairStat>,
    i: usize,
) -> Option<(Guess, u32)> {
    let &(a, r) = regs.get(i)?;
    let &(b, r2) = regs.get(i + 1)?;
    if u32::from(b) != u32::from(a) + 1 {
        return None;
    }
    let p = pair(a)?;
    // Over a short series "never changed" says little (one snapshot changes nothing): the
    // plausibility of the bits decides there.
    if usize::try_from(p.samples).unwrap_or(usize::MAX) < ENOUGH {
        // Bits that read as an integer high word first are never called a float (a zero high
        // word is a denormal one way and any low-word-first float the other).
        if let Some((kind, why)) = super::few_samples::int_by_bits(p) {
            return Some((
                Guess {
                    address: a,
                    kind,
                    confidence: super::few_samples::FEW.min(confidence(p.samples, 1)),
                    evidence: format!("{} joint sample(s): {why} — decided by few samples", p.samples),
                },
                // Weaker than a float its bits decide: a pair starting one register later that
                // reads as one takes the register (a float's zero low word beside the next
                // value's high word reads as such an integer).
                0,
            ));
        }
        return short(a, p);
    }
    if r.changes == 0 && r2.changes == 0 {
        return None;
    }
    wide(a, p, r, r2)
}

/// The pair `a`, `a + 1` as a float from a short series ([`short_float_fit`]), score 1.
fn short(a: u16, p: &PairStat) -> Option<(Guess, u32)> {
    let high_first = [true, false].into_iter().find(|&h| short_float_fit(p, h))?;
    let last = p.recent.back().map(|&(x, y)| f32::from_bits(join(x, y, high_first))).unwrap_or_default();
    Some((
        Guess {
            address: a,
            kind: Kind::F32 { high_first },
            confidence: confidence(p.samples, 0).min(0.2),
            evidence: format!(
                "only {} joint sample(s): every one a plausible float {} and not in the other word order \
                 (last {last}); by the bits alone — a longer recording would show the series",
                p.samples,
                if high_first { "high word first" } else { "low word first" },
            ),
        },
        1,
    ))
}

/// The pair `a`, `a + 1` as one 32-bit value, when the series say so, with its score (how much
/// evidence: carries seen).
fn wide(a: u16, p: &PairStat, r: &RegStat, r2: &RegStat) -> Option<(Guess, u32)> {
    let c = confidence(p.samples, r.changes.max(r2.changes));
    let floats = [true, false].map(|h| float_fit(p, h).map(|score| (h, score)));
    let float = match floats {
        [Some(x), Some(y)] => Some(if x.1 >= y.1 { x } else { y }),
        [x, y] => x.or(y),
    };
    // No carry seen and the high word never moved: nothing couples the two registers but a
    // plausible number — unless the low word is a plain analog value on its own, a register
    // with a shape of its own (counter, signed, bits, enumeration) is read alone.
    let float = float.filter(|&(high_first, score)| {
        let (high, low) = if high_first { (r, r2) } else { (r2, r) };
        score > 1 || high.changes > 0 || matches!(single(0, low).kind, Kind::U16)
    });
    if let Some((high_first, score)) = float {
        let last = p.recent.back().map(|&(x, y)| f32::from_bits(join(x, y, high_first))).unwrap_or_default();
        return Some((
            Guess {
                address: a,
                kind: Kind::F32 { high_first },
                confidence: c,
                evidence: format!(
                    "{} joint samples, every one a plausible float moving smoothly, {} carries between the words ({}: last {last})",
                    p.samples,
                    score - 1,
                    if high_first { "high word first" } else { "low word first" }
                ),
            },
            score,
        ));
    }
    let ints = [true, false].map(|h| int_fit(p, h));
    let (kind, score) = match ints {
        [Some(x), Some(y)] => {
            if x.1 >= y.1 {
                x
            } else {
                y
            }
        }
        [x, y] => x.or(y)?,
    };
    let first = matches!(kind, Kind::U32 { high_first: true, .. } | Kind::I32 { high_first: true });
    Some((
        Guess {
            address: a,
            evidence: format!(
                "{} joint samples; the {} word moves as the other's carry ({} carries seen), the two together smoothly",
                p.samples,
                if first { "first" } else { "second" },
                score - 1
            ),
            kind,
            confidence: c,
        },
        score,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(samples: &[(u16, u16)]) -> PairStat {
        PairStat::of(samples)
    }

    /// Real recordings hold a few polls: the order a float's words come in is decided
    /// by the bits when only one order is a plausible number, and not at all when both are.
    #[test]
    fn short_series_floats_are_decided_by_their_bits() {
        // PM5350 frequency, high word first: 0x426F_FC67 = 59.99 Hz; 0xFC67_426F is -4.8e36.
        let hz = pair(&[(0x426F, 0xFC67), (0x426F, 0xF642)]);
        assert!(short_float_fit(&hz, true));
        assert!(!short_float_fit(&hz, false));
        // A voltage low word first: 0x42BB_07F7 = 93.5; 0x07F7_42BB is 3.7e-34.
        let volts = pair(&[(0x07F7, 0x42BB)]);
        assert!(short_float_fit(&volts, false));
        assert!(!short_float_fit(&volts, true));
        // Two small integers: no order is a plausible float.
        let small = pair(&[(3, 7), (4, 7)]);
        assert!(!short_float_fit(&small, true) && !short_float_fit(&small, false));
        // Both orders plausible (0x4120_4120 is 10.0 either way): undecided, not guessed.
        let both = pair(&[(0x4120, 0x4120)]);
        assert!(!short_float_fit(&both, true) && !short_float_fit(&both, false));
        // A high word that moves more often than the low word is not a float's.
        let moving_high = pair(&[(0x4270, 0x0001), (0x4271, 0x0001), (0x4272, 0x0001)]);
        assert!(!short_float_fit(&moving_high, true));
        // All zero: nothing says float.
        assert!(!short_float_fit(&pair(&[(0, 0)]), true));
        // A long series ([`ENOUGH`] samples) is not judged this way (the series tests decide there).
        let long: Vec<(u16, u16)> = (0..8u16).map(|i| (0x426F, 0xF000 + i)).collect();
        assert_eq!(long.len(), ENOUGH);
        assert!(!short_float_fit(&pair(&long), true));
    }
}
