//! Small measures of a register pair's series that both the per-pair tests ([`super::infer`])
//! and the block layout ([`super::layout`]) use: kept here so neither imports the other's.

use super::stats::PairStat;

/// Samples a series needs before its shape is trusted.
pub(super) const ENOUGH: usize = 8;

/// Samples from which a type is as sure as listening makes it.
const DOZENS: f64 = 24.0;

/// How sure a guess is, by how many samples agree with it: one sample 0.3, two 0.44, eight
/// 0.73, two dozen and more 0.95 — growing with the logarithm of the count (each doubling of
/// consistent samples adds as much). A register that never moved has shown no type's behaviour
/// (a counter's rise, a sign's wrap): at most 0.6.
#[allow(clippy::cast_precision_loss)]
pub(super) fn confidence(samples: u64, changes: u64) -> f64 {
    let n = samples.max(1) as f64;
    let by_samples = 0.3 + 0.65 * (n.log2() / DOZENS.log2()).min(1.0);
    let c = if changes == 0 { by_samples.min(0.6) } else { by_samples };
    (c * 100.0).round() / 100.0
}

pub(super) fn join(a: u16, b: u16, high_first: bool) -> u32 {
    let (hi, lo) = if high_first { (a, b) } else { (b, a) };
    (u32::from(hi) << 16) | u32::from(lo)
}

pub(super) fn ordered(pair: &PairStat, high_first: bool) -> Vec<(u16, u16)> {
    pair.recent.iter().map(|&(a, b)| if high_first { (a, b) } else { (b, a) }).collect()
}

/// Whether a series of floats (as bits) moves smoothly: the median change between two samples
/// under 5 % of the value. A series of one sample is smooth.
pub(super) fn smooth(values: &[u32]) -> bool {
    let f: Vec<f64> = values.iter().map(|&v| f64::from(f32::from_bits(v))).collect();
    let mut rel: Vec<f64> =
        f.windows(2).map(|w| (w[1] - w[0]).abs() / (w[0].abs().max(w[1].abs()).max(1e-9))).collect();
    rel.sort_by(f64::total_cmp);
    rel.get(rel.len() / 2).is_none_or(|&m| m < 0.05)
}

#[cfg(test)]
mod tests {
    use super::confidence;

    #[test]
    fn one_sample_is_at_most_a_half_and_dozens_at_least_nine_tenths() {
        assert!(confidence(1, 1) <= 0.5 && confidence(2, 1) <= 0.5);
        assert!(confidence(24, 10) >= 0.9 && confidence(224, 200) >= 0.9);
        assert!(confidence(8, 3) > confidence(2, 1));
        assert!(confidence(300, 0) <= 0.6, "a register that never moved");
    }
}
