//! How late this observer's reads deliver bytes, learned from the valid frames it delivered.
//!
//! A read's timestamp is when the read returned, not when its bytes were on the wire: a UART
//! FIFO holds them until 14 have come or 4 characters passed without one, a USB adapter until
//! its latency timer (16 ms on FTDI's default) or its 62-byte packet is full. Where that delay
//! is unknown (a capture from another tool, `--latency-ms` not given), a delayed read looks like
//! a silence before its bytes — and a silence longer than t3.5 ends a frame.
//!
//! Valid frames are ground truth here: their bytes were sent back to back — unless their sender
//! pauses inside its frames, the very fault a health report must find. So the observer's delay
//! is learned **per sender** and the port's figure taken across senders: the delay is a property
//! of the port (the master's requests are split by the same timer as the slaves' answers), a
//! pause is a property of one sender. Each valid frame that came in more than one read gives its
//! sender one sample, the longest apparent silence between two of its reads; a batch of
//! [`BATCH`] samples of one sender gives that sender's figure (its largest); a sender's figure is
//! the median of its last [`KEPT_BATCHES`] (so a pause now and then does not count). The
//! port's latency is the lower median of the senders' figures, so one slow unit — or a few,
//! while most senders are healthy — cannot raise it and hide its own pauses, and a healthy
//! sender's longest delays, not a 90th percentile below the timer, set it.
//!
//! (The first version took one 90th percentile over all senders: behind a 16 ms USB timer it
//! learned 14 ms and the timer's own 15–16 ms delays became "gaps inside frames" against every
//! unit; a slow unit's pauses, a fifth of the samples, raised it and hid themselves.)

/// Samples per batch of one sender.
pub(crate) const BATCH: usize = 16;
/// Batches whose figures a sender's figure is the median of.
const KEPT_BATCHES: usize = 5;
/// The sample of a batch taken as its figure (0-based, ascending): the largest. A read's
/// apparent delay depends on how many bytes it holds (its timestamp is its last byte's), so
/// only the longest delays reach the timer; one pause in a batch is outvoted by the median
/// over batches.
const FIGURE_INDEX: usize = BATCH - 1;
/// Batches a sender needs before its figure counts alone (while any sender has as many).
const SETTLED: usize = 3;
/// Senders: the master, then units 0–255 by the frame's address byte.
const SENDERS: usize = 257;

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
    /// Valid frames seen.
    pub frames: u64,
    /// Reads (chunks) and their bytes; the longest read.
    pub reads: u64,
    pub read_bytes: u64,
    pub longest_read: usize,
    /// What the session that recorded this capture learned (its statistics comment).
    pub recorded_latency_ns: Option<u64>,
    /// Senders (the master, units) whose frames gave a figure; the learned latency is the lower
    /// median of theirs.
    pub senders_learned: usize,
    /// The median number of bytes per read.
    pub typical_read: usize,
    /// One character time on this port (ns): a read's timestamp cannot place a byte closer
    /// than that.
    pub char_ns: u64,
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

    /// The shortest timing fault these reads can prove (ns): where reads are delayed, an
    /// apparent silence is uncertain by the latency (and a sixteenth for what learning may have
    /// missed) plus one character; per-byte timestamps (no latency) resolve everything.
    #[must_use]
    ///
    /// Reads that hold several bytes each while no delay shows between them were delayed
    /// alike — a USB timer shorter than its batch (1 ms at 19200 holds two characters per
    /// read), with every frame's last read shared with its glitch — and the delay nobody could
    /// see is at least the time the bytes of a typical read took: the resolution is never
    /// finer than that plus a character.
    ///
    /// Where every read holds one byte, a byte's timestamp is its end plus the observer's delay
    /// for that read: a silence between two bytes is uncertain by how much those delays differ
    /// — the learned figure, a sixteenth more — and no character (a unit pausing 2.3 ms inside
    /// its answers at 9600, read byte by byte with 0.2 ms of jitter, is named; behind a
    /// resolution of 1.4 ms it would not be).
    pub fn resolution_ns(&self) -> u64 {
        if self.reads > 0 && self.longest_read <= 1 {
            let l = self.effective_latency_ns();
            return l.saturating_add(l / 16);
        }
        // Only where most frames come in several reads: one read per frame (a gap-cutting
        // sniffer's packets) places every frame's end exactly.
        let mostly_split = self.split_frames.saturating_mul(2) > self.frames;
        let batched =
            if mostly_split { self.char_ns.saturating_mul(self.typical_read.saturating_sub(1) as u64) } else { 0 };
        // A learned figure is the longest delay seen, which may fall short of the adapter's
        // true one by a little: a sixteenth more (behind a 16 ms timer at 115200, a character is
        // 87 µs, less than the learned figure's shortfall).
        let margin = |l: u64| l.saturating_add(l / 16).saturating_add(self.char_ns);
        match self.effective_latency_ns() {
            0 if batched == 0 => 0,
            l if l < self.char_ns => margin(l.max(batched)),
            l => margin(l),
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

/// Who sent a frame, as the learner keys its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SampleSender {
    Master,
    Unit(u8),
}

impl SampleSender {
    const fn slot(self) -> usize {
        match self {
            Self::Master => 0,
            Self::Unit(u) => 1 + u as usize,
        }
    }
}

/// One sender's samples.
#[derive(Debug, Clone, Copy, Default)]
struct SenderSamples {
    batch: [u64; BATCH],
    in_batch: usize,
    figures: [u64; KEPT_BATCHES],
    batches: usize,
}

impl SenderSamples {
    /// Adds a sample; the sender's new figure when a batch completed.
    fn add(&mut self, delay_ns: u64) -> Option<u64> {
        self.batch[self.in_batch] = delay_ns;
        self.in_batch += 1;
        if self.in_batch < BATCH {
            return None;
        }
        self.in_batch = 0;
        self.batch.sort_unstable();
        self.figures[self.batches % KEPT_BATCHES] = self.batch[FIGURE_INDEX];
        self.batches = self.batches.saturating_add(1);
        self.figure()
    }

    /// The median of the kept batch figures; `None` before a first batch.
    fn figure(&self) -> Option<u64> {
        let kept = self.batches.min(KEPT_BATCHES);
        if kept == 0 {
            return None;
        }
        let mut last = self.figures;
        let last = &mut last[..kept];
        last.sort_unstable();
        Some(last[kept / 2])
    }
}

/// The learner inside a framer.
#[derive(Debug, Clone)]
pub(crate) struct ObserverLearner {
    pub(crate) estimate: ObserverEstimate,
    senders: Box<[SenderSamples]>,
    /// Each sender's figure, where it has one (kept apart so the port's figure is cheap).
    figures: Box<[Option<u64>]>,
    /// The slots that have a figure, in the order they got it: the port's figure is taken over
    /// these, not over all 257 (the walk cost replay a percent).
    active: Vec<usize>,
    /// Whether any sender has [`SETTLED`] batches (it stays so: batches only grow).
    settled: bool,
    /// Reads by size (the last slot: that many bytes or more), for the typical read.
    read_sizes: [u64; READ_SIZES],
}

/// Read sizes counted one by one; longer reads share the last slot.
const READ_SIZES: usize = 64;

impl ObserverLearner {
    pub(crate) fn new(configured_latency_ns: u64, learning: bool, char_ns: u64) -> Self {
        Self {
            estimate: ObserverEstimate { configured_latency_ns, learning, char_ns, ..ObserverEstimate::default() },
            senders: vec![SenderSamples::default(); SENDERS].into_boxed_slice(),
            figures: vec![None; SENDERS].into_boxed_slice(),
            active: Vec::new(),
            settled: false,
            read_sizes: [0; READ_SIZES],
        }
    }

    /// A read of `n` bytes arrived.
    pub(crate) fn read(&mut self, n: usize) {
        let e = &mut self.estimate;
        e.reads = e.reads.saturating_add(1);
        e.read_bytes = e.read_bytes.saturating_add(n as u64);
        e.longest_read = e.longest_read.max(n);
        self.read_sizes[n.min(READ_SIZES - 1)] += 1;
        // The median read size, brought up to date now and then (64 slots to walk).
        if e.reads > 64 && !e.reads.is_multiple_of(64) {
            return;
        }
        let half = e.reads.div_ceil(2);
        let mut seen = 0;
        e.typical_read = self
            .read_sizes
            .iter()
            .position(|&k| {
                seen += k;
                seen >= half
            })
            .unwrap_or(0);
    }

    /// A valid frame was emitted (split across reads or not).
    pub(crate) fn frame(&mut self) {
        self.estimate.frames = self.estimate.frames.saturating_add(1);
    }

    /// A valid frame from `sender` came in several reads, the longest apparent silence between
    /// two of them `delay_ns`. Returns the port's new learned latency when it was recomputed.
    pub(crate) fn sample(&mut self, sender: SampleSender, delay_ns: u64) -> Option<u64> {
        self.estimate.split_frames = self.estimate.split_frames.saturating_add(1);
        let slot = sender.slot();
        let figure = self.senders[slot].add(delay_ns)?;
        if self.figures[slot].replace(figure).is_none() {
            self.active.push(slot);
        }
        self.settled |= self.senders[slot].batches >= SETTLED;
        // The lower median across the senders that have a figure — from those with a median of
        // at least [`SETTLED`] batches where any has one: a sender's first batch may hold its
        // one pause of the day (on a short capture, two units' single batches with a
        // slow answer each made the port's figure 6.5 ms behind per-byte timestamps).
        let mut all = [0u64; SENDERS];
        let mut n = 0;
        for &k in &self.active {
            if let Some(f) = self.figures[k]
                && (!self.settled || self.senders[k].batches >= SETTLED)
            {
                all[n] = f;
                n += 1;
            }
        }
        let all = &mut all[..n];
        all.sort_unstable();
        let learned = *all.get(n.saturating_sub(1) / 2)?;
        self.estimate.learned_latency_ns = Some(learned);
        self.estimate.senders_learned = all.len();
        Some(learned)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds `n` batches of samples from `sender`, delays from `delay(i)`.
    fn feed(l: &mut ObserverLearner, sender: SampleSender, n: usize, delay: impl Fn(u64) -> u64) {
        for i in 0..(BATCH * n) as u64 {
            l.sample(sender, delay(i));
        }
    }

    #[test]
    fn delays_of_a_16_ms_timer_are_learned_up_to_the_timer() {
        let mut l = ObserverLearner::new(0, true, 1_146_000);
        // Delays spread over 14.9–16 ms, and one frame in 64 a slave pausing 40 ms inside it.
        for sender in [SampleSender::Master, SampleSender::Unit(1), SampleSender::Unit(5)] {
            feed(&mut l, sender, 5, |i| if i % 64 == 0 { 40_000_000 } else { 14_900_000 + (i * 7919 % 64) * 17_000 });
        }
        let learned = l.estimate.learned_latency_ns.expect("three senders");
        assert!((15_800_000..16_000_000).contains(&learned), "{learned}");
        assert_eq!(l.estimate.effective_latency_ns(), learned);
    }

    /// A unit pausing 30 characters inside every answer, a fifth of the samples, does not raise the
    /// port's learned latency (one 90th percentile over all would), so its own pauses stay visible.
    #[test]
    fn a_slow_units_pauses_do_not_raise_the_ports_latency() {
        // As on a bus: the master sends every request, each unit answers its share.
        let mut l = ObserverLearner::new(0, true, 1_146_000);
        feed(&mut l, SampleSender::Master, 12, |i| 15_000_000 + i % 5 * 100_000);
        feed(&mut l, SampleSender::Unit(17), 3, |_| 34_000_000);
        for sender in [SampleSender::Unit(1), SampleSender::Unit(5), SampleSender::Unit(33)] {
            feed(&mut l, sender, 3, |i| 15_000_000 + i % 7 * 100_000);
        }
        let learned = l.estimate.learned_latency_ns.expect("five senders");
        assert!(learned < 16_000_000, "{learned}");
        assert_eq!(l.estimate.senders_learned, 5);
        // With only the master and the slow unit, the lower of the two.
        let mut two = ObserverLearner::new(0, true, 1_146_000);
        feed(&mut two, SampleSender::Unit(17), 3, |_| 34_000_000);
        feed(&mut two, SampleSender::Master, 3, |_| 15_000_000);
        assert_eq!(two.estimate.learned_latency_ns, Some(15_000_000));
        // Units answering in single batches, most with a pause: the settled master's figure.
        let mut noisy = ObserverLearner::new(0, true, 1_146_000);
        feed(&mut noisy, SampleSender::Master, 6, |_| 573_000);
        for u in [1, 5, 17] {
            feed(&mut noisy, SampleSender::Unit(u), 1, |i| if i == 7 { 8_000_000 } else { 573_000 });
        }
        assert_eq!(noisy.estimate.learned_latency_ns, Some(573_000));
    }

    #[test]
    fn per_byte_reads_learn_no_latency_and_a_given_latency_is_kept() {
        let mut l = ObserverLearner::new(2_000_000, false, 1_146_000);
        // One pause in three batches: outvoted.
        feed(&mut l, SampleSender::Master, 3, |i| if i == 3 { 9_000_000 } else { 0 });
        assert_eq!(l.estimate.learned_latency_ns, Some(0));
        assert_eq!(l.estimate.effective_latency_ns(), 2_000_000);
    }
}
