//! How late this observer's reads deliver bytes, learned from the valid frames it delivered.
//!
//! A read's timestamp is when the read returned, not when its bytes were on the wire: a UART
//! FIFO holds them until 14 have come or 4 characters passed without one, a USB adapter until
//! its latency timer (16 ms on FTDI's default) or its 62-byte packet is full. Where that delay
//! is unknown (a capture from another tool, `--latency-ms` not given), a delayed read looks like
//! a silence before its bytes — and a silence longer than t3.5 ends a frame.
//!
//! Valid frames are ground truth here: their bytes were sent back to back (a slave that pauses
//! inside its frames aside), so any apparent silence between two reads *inside* a valid frame is
//! the observer's delay. Each valid frame that came in more than one read gives one sample, the
//! longest such silence; a batch of [`BATCH`] samples gives its 90th percentile (so the few slow
//! slaves' pauses do not count), and the learned latency is the median of the last
//! [`KEPT_BATCHES`] batches — a lower bound on the observer's true latency, so trusting timing
//! less by it never invents a silence.

/// Samples per batch.
pub(crate) const BATCH: usize = 64;
/// Batches whose 90th percentiles the learned figure is the median of.
const KEPT_BATCHES: usize = 5;
/// The sample of a batch taken as its 90th percentile (0-based, ascending).
const P90_INDEX: usize = BATCH * 9 / 10;

/// What the framer learned about the reads of one port.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ObserverEstimate {
    /// The observer's delivery latency learned from valid frames (ns); `None` until a first
    /// batch of frames split across reads was seen.
    pub learned_latency_ns: Option<u64>,
    /// The latency the framer was given (`--latency-ms`, the capture, the adapter).
    pub configured_latency_ns: u64,
    /// Whether learning may raise the latency the framer works with (not when the user gave it).
    pub learning: bool,
    /// Valid frames that came in more than one read (the samples).
    pub split_frames: u64,
    /// Reads (chunks) and their bytes; the longest read.
    pub reads: u64,
    pub read_bytes: u64,
    pub longest_read: usize,
    /// What the session that recorded this capture learned (its statistics comment).
    pub recorded_latency_ns: Option<u64>,
}

impl ObserverEstimate {
    /// The latency the framer works with: the configured one, or what was learned when more
    /// and learning is on.
    #[must_use]
    pub fn effective_latency_ns(&self) -> u64 {
        match self.learned_latency_ns {
            Some(l) if self.learning => l.max(self.configured_latency_ns),
            _ => self.configured_latency_ns,
        }
    }

    /// How the reads were shaped, in words: bytes per read on average and at most (one per
    /// read: per-byte timestamps; a UART FIFO delivers up to 14, a USB adapter up to 62 — or
    /// as many as its latency timer gathers, which at 9600 baud is 14 too: the figures are said,
    /// not guessed at).
    #[must_use]
    pub fn shape(&self) -> String {
        if self.reads == 0 {
            return "no reads".to_owned();
        }
        #[allow(clippy::cast_precision_loss)]
        let mean = self.read_bytes as f64 / self.reads as f64;
        format!("{mean:.1} bytes per read on average, at most {}", self.longest_read)
    }
}

/// The learner inside a framer.
#[derive(Debug, Clone)]
pub(crate) struct ObserverLearner {
    pub(crate) estimate: ObserverEstimate,
    batch: [u64; BATCH],
    in_batch: usize,
    p90s: [u64; KEPT_BATCHES],
    batches: usize,
}

impl ObserverLearner {
    pub(crate) fn new(configured_latency_ns: u64, learning: bool) -> Self {
        Self {
            estimate: ObserverEstimate { configured_latency_ns, learning, ..ObserverEstimate::default() },
            batch: [0; BATCH],
            in_batch: 0,
            p90s: [0; KEPT_BATCHES],
            batches: 0,
        }
    }

    /// A read of `n` bytes arrived.
    pub(crate) fn read(&mut self, n: usize) {
        let e = &mut self.estimate;
        e.reads = e.reads.saturating_add(1);
        e.read_bytes = e.read_bytes.saturating_add(n as u64);
        e.longest_read = e.longest_read.max(n);
    }

    /// A valid frame came in several reads, the longest apparent silence between two of them
    /// `delay_ns`. Returns the new learned latency when a batch completed.
    pub(crate) fn sample(&mut self, delay_ns: u64) -> Option<u64> {
        self.estimate.split_frames = self.estimate.split_frames.saturating_add(1);
        self.batch[self.in_batch] = delay_ns;
        self.in_batch += 1;
        if self.in_batch < BATCH {
            return None;
        }
        self.in_batch = 0;
        self.batch.sort_unstable();
        self.p90s[self.batches % KEPT_BATCHES] = self.batch[P90_INDEX];
        self.batches = self.batches.saturating_add(1);
        let kept = self.batches.min(KEPT_BATCHES);
        let mut last = self.p90s;
        let last = &mut last[..kept];
        last.sort_unstable();
        let learned = last[kept / 2];
        self.estimate.learned_latency_ns = Some(learned);
        Some(learned)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_of_a_16_ms_timer_are_learned_and_slow_slaves_pauses_are_not() {
        let mut l = ObserverLearner::new(0, true);
        let mut learned = None;
        for i in 0..(BATCH as u64 * 5) {
            // Delays spread over 0–16 ms, and one frame in 32 a slave pausing 40 ms inside it.
            let d = if i % 32 == 0 { 40_000_000 } else { (i * 7919 % 64) * 250_000 };
            learned = l.sample(d).or(learned);
        }
        let learned = learned.expect("five batches");
        assert!((13_000_000..16_000_000).contains(&learned), "{learned}");
        assert_eq!(l.estimate.effective_latency_ns(), learned);
    }

    #[test]
    fn per_byte_reads_learn_no_latency_and_a_given_latency_is_kept() {
        let mut l = ObserverLearner::new(2_000_000, false);
        for i in 0..BATCH as u64 {
            l.sample(if i == 3 { 9_000_000 } else { 0 });
        }
        assert_eq!(l.estimate.learned_latency_ns, Some(0));
        assert_eq!(l.estimate.effective_latency_ns(), 2_000_000);
    }
}
