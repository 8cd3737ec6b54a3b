//! What each valid frame teaches the framer: the observer's delay from the silences inside it,
//! and the shorter tolerance a silence before it may be given (its margins).

use super::RtuFramer;
use crate::framer::glitch::Sender;
use crate::framer::observer::SampleSender;

impl RtuFramer {
    /// A valid frame at absolute `a`, `delay` the longest apparent silence between two of its
    /// reads (`None`: it came in one): its bytes were sent back to back, so that silence is the
    /// observer's delay.
    pub(super) fn learn_from(&mut self, a: usize, delay: Option<u64>) {
        self.learner.frame();
        let sender = match self.last.last_sender {
            Sender::Master => SampleSender::Master,
            Sender::Slave | Sender::Unknown => SampleSender::Unit(self.timed.buf[a]),
        };
        if let Some(d) = delay
            && self.learner.sample(sender, d).is_some()
        {
            self.timing.latency = self.learner.estimate.effective_latency_ns();
        }
    }

    /// The longest apparent silence between two reads inside absolute `a..b`, taken at face
    /// value (no latency allowed for); `None` when the bytes came in one read.
    ///
    /// A read's bytes are placed back to back before its timestamp; where the frame's last read
    /// also holds bytes of the next frame, the silence between the two frames is hidden inside
    /// that read and its first bytes look later than they were — by up to that silence. That
    /// read's boundary says nothing about the observer or the sender and is left out (
    /// through a 16550 FIFO, which holds the tail of one frame with the head of the next, it
    /// made healthy frames look paused). For learning the observer's delay it is kept (the
    /// first of the pair returned): that errs high, towards fewer findings, and a glitchy
    /// line's frames always share their last read with their glitch. One pass over the frame
    /// gives all three: `(the longest silence the reads prove inside it, every boundary, the
    /// boundaries the gap evidence may use)`.
    pub(super) fn apparent_inner_silence(&self, a: usize, b: usize) -> (u64, Option<u64>, Option<u64>) {
        if self.timed.in_one_read(a, b) {
            // Inside one read every byte after the first is back to back with the one before
            // (no gap proven, none bounded): no silence, no boundary.
            return (0, None, None);
        }
        let c = self.timing.char_ns;
        // A read began at `i` where the gap before it is bounded (inside a read it is unknown
        // and set to `u64::MAX`).
        let starts_read = |i: usize| self.timed.gap_ub.get(i).is_some_and(|&g| g != u64::MAX);
        let (mut before_last, mut last) = (None::<u64>, None::<u64>);
        // One pass over slices, the frame's longest proven gap with it (two scans of
        // every frame cost replay its speed).
        let t = &self.timed;
        let (Some(lb), Some(ub), Some(end)) = (t.gap_lb.get(a + 1..b), t.gap_ub.get(a + 1..b), t.end.get(a..b)) else {
            return (0, None, None);
        };
        let mut inner_gap = 0;
        for ((&l, &g), w) in lb.iter().zip(ub).zip(end.windows(2)) {
            inner_gap = inner_gap.max(l);
            if g != u64::MAX {
                before_last = before_last.max(last);
                last = Some(w[1].saturating_sub(c).saturating_sub(w[0]));
            }
        }
        let every = before_last.max(last);
        let last_read_spills = b < self.timed.buf.len() && !starts_read(b);
        (inner_gap, every, if last_read_spills { before_last } else { every })
    }

    /// How far an apparent silence before a frame fell short of t3.5 after the previous frame.
    pub(super) fn short_tolerance(&self, apparent_before: Option<u64>) -> Option<u64> {
        apparent_before
            .filter(|_| self.last.after_frame)
            .and_then(|g| self.timing.t35.checked_sub(g))
            .filter(|&t| t > 0)
    }
}
