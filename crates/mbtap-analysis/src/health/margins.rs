//! Timing evidence kept with its margin, judged at report time against what the observer can
//! resolve.
//!
//! A pause inside a frame, or a silence shorter than t3.5 before one, is seen through reads
//! that may each be delayed by the observer's latency (a USB adapter's timer, a UART FIFO's
//! timeout). The framer says how far each apparent violation goes beyond its threshold — its
//! *margin*; only a margin at least the observer's resolution (its latency plus a character)
//! proves the fault. The latency is learned while the capture is read, so the evidence is kept
//! bucketed by margin and judged once, at report time, with the figure the port finally
//! learned: early frames are not judged with a latency not yet known.
//!
//! Buckets are logarithmic, eight per octave from 1 µs (a margin is undercounted by at most 9 %,
//! never overcounted: a bucket counts only when its lower edge is at least the resolution), so
//! memory is fixed whatever the capture's length.

use super::Tally;

/// Buckets: one below 1 µs, then eight per octave up to about 2^20 µs (1 s), one above.
const BUCKETS: usize = 2 + 8 * 20;

/// Timing evidence by margin.
#[derive(Debug, Clone, Default)]
pub(super) struct Margins {
    /// Per bucket: the tally of the evidence whose margin fell in it (allocated at first use).
    buckets: Vec<Tally>,
}

/// Margins are bucketed in eighths of a microsecond, so that from 1 µs on the eight steps of
/// an octave are whole units.
const UNIT_NS: u64 = 125;

/// The bucket of a margin in ns.
fn bucket(margin_ns: u64) -> usize {
    let u = margin_ns / UNIT_NS;
    if u < 8 {
        return 0;
    }
    // 8 × log2(u / 8), by the integer part and the three bits below the leading one.
    let log = 63 - u64::from(u.leading_zeros());
    let frac = (u >> (log - 3)) & 7;
    usize::try_from(1 + (log - 3) * 8 + frac).map_or(BUCKETS - 1, |b| b.min(BUCKETS - 1))
}

/// The smallest margin in ns that falls in bucket `b`.
fn lower_edge(b: usize) -> u64 {
    if b == 0 {
        return 0;
    }
    let k = (b - 1) as u64;
    ((8 + k % 8) << (k / 8)).saturating_mul(UNIT_NS)
}

impl Margins {
    /// Evidence at time `t` with margin `margin_ns`.
    pub(super) fn add(&mut self, margin_ns: u64, t: u64) {
        if self.buckets.is_empty() {
            self.buckets = vec![Tally::default(); BUCKETS];
        }
        self.buckets[bucket(margin_ns)].add(t);
    }

    /// All the evidence, proven or not.
    pub(super) fn total(&self) -> u64 {
        self.buckets.iter().map(|b| b.count).sum()
    }

    /// The evidence that proves the fault through an observer resolving `resolution_ns`.
    pub(super) fn proven(&self, resolution_ns: u64) -> Tally {
        self.buckets
            .iter()
            .enumerate()
            .filter(|(b, t)| t.count > 0 && (resolution_ns == 0 || lower_edge(*b) >= resolution_ns))
            .fold(Tally::default(), |all, (_, t)| all.merged(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bucket_never_claims_more_margin_than_its_evidence_had() {
        for m in [0u64, 999, 1000, 1500, 7_999, 8_000, 15_999_999, 16_000_000, 34_000_000, u64::MAX / 16] {
            let b = bucket(m);
            assert!(lower_edge(b) <= m, "{m}: bucket {b} from {}", lower_edge(b));
            if b + 1 < BUCKETS {
                assert!(lower_edge(b + 1) > m, "{m}: bucket {b}");
            }
            // Within 1/8 octave below (about 9 %), above a microsecond.
            if m >= 1000 && b + 1 < BUCKETS {
                assert!(lower_edge(b) * 11 >= m * 10, "{m}: {}", lower_edge(b));
            }
        }
    }

    #[test]
    fn evidence_counts_only_where_its_margin_reaches_the_resolution() {
        let mut m = Margins::default();
        m.add(500_000, 1);
        m.add(20_000_000, 2);
        m.add(20_000_000, 3);
        assert_eq!(m.total(), 3);
        assert_eq!(m.proven(0).count, 3);
        assert_eq!(m.proven(400_000).count, 3);
        assert_eq!(m.proven(17_146_000).count, 2);
        assert_eq!(m.proven(17_146_000).first, 2);
        assert_eq!(m.proven(25_000_000).count, 0);
    }
}
