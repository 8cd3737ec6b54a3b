//! Small measures of a register pair's series that both the per-pair tests ([`super::infer`])
//! and the block layout ([`super::layout`]) use: kept here so neither imports the other's.

use super::stats::PairStat;

/// Samples a series needs before its shape is trusted.
pub(super) const ENOUGH: usize = 8;

#[allow(clippy::cast_precision_loss)]
pub(super) fn confidence(samples: u64, changes: u64) -> f64 {
    let s = (samples as f64 / 32.0).min(1.0);
    let c = if changes == 0 { 0.5 } else { (changes as f64 / 8.0).min(1.0) };
    (s * c * 100.0).round() / 100.0
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
