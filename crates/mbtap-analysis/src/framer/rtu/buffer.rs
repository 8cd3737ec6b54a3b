//! The timed buffer: the bytes not yet decided, each with the latest moment it can have ended
//! and the bounds of the silence before it — what the reads' timestamps prove, given the
//! observer's latency (see the timing model in the module's documentation).

use mbtap_proto::rtu::RTU_MAX_LEN;

/// Decided bytes are dropped from the front once this many have gathered (or all are decided).
const COMPACT_AT: usize = 8192;

/// Buffered bytes and their timing; indices are absolute until [`TimedBuffer::compact`].
#[derive(Debug)]
pub(super) struct TimedBuffer {
    pub(super) buf: Vec<u8>,
    /// Latest possible end time of each buffered byte (ns).
    pub(super) end: Vec<u64>,
    /// Silence known to precede each buffered byte (lower bound, ns).
    pub(super) gap_lb: Vec<u64>,
    /// Silence that may at most precede each buffered byte (upper bound, ns; `u64::MAX` unknown).
    pub(super) gap_ub: Vec<u64>,
    /// First live (undecided) byte.
    pub(super) head: usize,
    /// End time of the last byte received.
    pub(super) last_end: Option<u64>,
    /// Time of the last read.
    pub(super) last_read: u64,
    /// Where the last read's bytes start, and the read's before it (0 before there were two):
    /// a frame inside one of them holds no boundary between reads — the common case, one frame
    /// per read, decided when the next read shows the silence after it — and needs no look at
    /// its bytes' gaps.
    last_read_start: usize,
    prev_read_start: usize,
}

impl TimedBuffer {
    pub(super) fn new() -> Self {
        Self {
            buf: Vec::with_capacity(4 * RTU_MAX_LEN),
            end: Vec::with_capacity(4 * RTU_MAX_LEN),
            gap_lb: Vec::with_capacity(4 * RTU_MAX_LEN),
            gap_ub: Vec::with_capacity(4 * RTU_MAX_LEN),
            head: 0,
            last_end: None,
            last_read: 0,
            last_read_start: 0,
            prev_read_start: 0,
        }
    }

    /// Whether bytes `a..b` are known to lie in one read (no read starts after `a` and before
    /// `b`); `false` when that is not known (the read holding `a` is older than the last two).
    pub(super) fn in_one_read(&self, a: usize, b: usize) -> bool {
        a >= self.last_read_start || (a >= self.prev_read_start && b <= self.last_read_start)
    }

    /// Bytes waiting for a decision.
    pub(super) fn live_len(&self) -> usize {
        self.buf.len() - self.head
    }

    /// Appends one read's `bytes`, returned at `t`, on a line of `c` ns per character, read
    /// through an observer that may deliver up to `latency` ns late.
    pub(super) fn append(&mut self, bytes: &[u8], t: u64, c: u64, latency: u64) {
        let n = bytes.len();
        if n > 0 {
            // Bytes in one chunk are taken as sent back to back, the last ending when the read
            // returned; and bytes cannot overlap on the wire, so each ends at least a character
            // after the one before. Both make the end times a run of step `c` from `e0`.
            let behind = u64::try_from(n - 1).unwrap_or(u64::MAX).saturating_mul(c);
            let mut e0 = t.saturating_sub(behind);
            let (lb, ub) = match self.last_end {
                Some(prev) => {
                    e0 = e0.max(prev.saturating_add(c));
                    let start = e0.saturating_sub(c);
                    (
                        start.saturating_sub(latency).saturating_sub(prev),
                        start.saturating_sub(prev.saturating_sub(latency)),
                    )
                }
                None => (u64::MAX, u64::MAX),
            };
            // Two stores per read: on a per-byte line every byte is one.
            self.prev_read_start = self.last_read_start;
            self.last_read_start = self.buf.len();
            if let [b] = bytes {
                // One byte per read (per-byte timestamps, a slow line): four pushes.
                self.buf.push(*b);
                self.end.push(e0);
                self.gap_lb.push(lb);
                self.gap_ub.push(ub);
                self.last_end = Some(e0);
                self.last_read = self.last_read.max(t);
                return;
            }
            self.buf.extend_from_slice(bytes);
            // The run of end times, by addition (this is per byte of every read: the
            // replay speed); saturating, so a clock at its end cannot wrap.
            let mut e = e0;
            self.end.reserve(n);
            for _ in 0..n {
                self.end.push(e);
                e = e.saturating_add(c);
            }
            self.gap_lb.push(lb);
            self.gap_ub.push(ub);
            self.gap_lb.extend(std::iter::repeat_n(0, n - 1));
            self.gap_ub.extend(std::iter::repeat_n(u64::MAX, n - 1));
            self.last_end = self.end.last().copied();
        }
        self.last_read = self.last_read.max(t);
    }

    /// Drops the decided bytes when all are decided or enough have gathered; how many were
    /// dropped (absolute indices kept elsewhere move down by as many).
    pub(super) fn compact(&mut self) -> Option<usize> {
        let head = self.head;
        if head == 0 || (head != self.buf.len() && head < COMPACT_AT) {
            return None;
        }
        self.buf.drain(..head);
        self.end.drain(..head);
        self.gap_lb.drain(..head);
        self.gap_ub.drain(..head);
        self.head = 0;
        self.last_read_start = self.last_read_start.saturating_sub(head);
        self.prev_read_start = self.prev_read_start.saturating_sub(head);
        Some(head)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fast path of a frame's inner silence (a frame in one read needs no look
    /// at its bytes' gaps) rests on this: where `in_one_read` says so, no byte after the first
    /// starts a read — its gap is unbounded and none is proven — through reads of every size
    /// and compactions.
    #[test]
    fn bytes_said_to_be_in_one_read_hold_no_read_boundary() {
        let mut t = TimedBuffer::new();
        // A fixed pseudo-random walk of read sizes (1–12 bytes) and decisions.
        let mut x = 0x2545_F491_u32;
        let mut said = 0;
        for round in 0..3000u64 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let n = 1 + (x % 12) as usize;
            t.append(&vec![0x11; n], 1_000_000 * (round + 1), 1_000, 0);
            let len = t.buf.len();
            for a in t.head..len {
                for b in a + 1..=len {
                    if t.in_one_read(a, b) {
                        said += 1;
                        assert!(t.gap_ub[a + 1..b].iter().all(|&g| g == u64::MAX), "{a}..{b} of {len}");
                        assert!(t.gap_lb[a + 1..b].iter().all(|&g| g == 0), "{a}..{b} of {len}");
                    }
                }
            }
            // Decide some bytes now and then; compact as the framer does.
            if x.is_multiple_of(3) {
                t.head = len - (x as usize % 4).min(len);
                let _ = t.compact();
            }
        }
        assert!(said > 10_000, "the fast path was taken {said} times");
    }
}
