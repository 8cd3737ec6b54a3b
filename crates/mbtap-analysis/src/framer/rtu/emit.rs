//! What the framer emits: valid frames with their timing evidence, damaged frames and noise
//! split at known silences (CRC twins in `twins.rs`, what a frame teaches in `learning.rs`).

use super::RtuFramer;
use super::expect::{Expect, MAX_ADDRESS, Reading, next_expect, sender_of};
use crate::chunk::{Chunk, Timestamp};
use crate::framer::event::{Frame, FrameEvent, Noise};
use crate::framer::glitch::Sender;
use crate::framer::lengths::After;
use mbtap_proto::function::EXCEPTION_FLAG;
use mbtap_proto::rtu::RTU_MIN_LEN;

impl RtuFramer {
    /// Emits a chunk that [`Self::whole_frame`] accepted, with the same timing the buffered
    /// path would give it.
    pub(super) fn emit_whole_chunk<F: FnMut(FrameEvent<'_>)>(
        &mut self,
        chunk: &Chunk<'_>,
        reading: Reading,
        emit: &mut F,
    ) {
        let c = self.timing.char_ns;
        let n = u64::try_from(chunk.bytes.len()).unwrap_or(u64::MAX);
        let mut e0 = chunk.t.0.saturating_sub((n - 1).saturating_mul(c));
        let ub = match self.timed.last_end {
            Some(prev) => {
                e0 = e0.max(prev.saturating_add(c));
                e0.saturating_sub(c).saturating_sub(prev.saturating_sub(self.timing.latency))
            }
            None => u64::MAX,
        };
        let t_end = e0.saturating_add((n - 1).saturating_mul(c));
        let apparent_before = (ub != u64::MAX).then(|| ub.saturating_sub(self.timing.latency));
        self.hold.pass(
            FrameEvent::Frame(Frame {
                port: self.port,
                bytes: chunk.bytes,
                t_start: Timestamp(e0.saturating_sub(c)),
                t_end: Timestamp(t_end),
                check_ok: true,
                gap_violation_ns: None,
                short_gap_before_ns: (self.last.after_frame && ub < self.timing.t35).then_some(ub),
                gap_tolerance_ns: None,
                short_gap_tolerance_ns: self.short_tolerance(apparent_before),
                resolution_ns: self.learner.estimate.resolution_ns(),
                gap_before_known: ub != u64::MAX,
                bad_chars: false,
                alt_len: None,
            }),
            emit,
        );
        self.known_units[usize::from(chunk.bytes[0])] = true;
        self.last.last_sender = sender_of(self.expect, chunk.bytes, Some(reading));
        self.last.after_damage = false;
        self.glitches.turn.frame(self.last.last_sender);
        self.learner.frame();
        self.timed.last_end = Some(t_end);
        self.timed.last_read = self.timed.last_read.max(chunk.t.0);
        self.last.after_frame = true;
        self.search.wait_at = usize::MAX;
        self.expect = next_expect(self.expect, chunk.bytes, Some(reading));
        self.glitches.frame();
        // The next byte buffered lands at the end of the (empty) live buffer.
        self.last.glitch_at = Some(self.timed.buf.len());
    }

    /// Emits the first `n` live bytes, known to form no valid frame, split at known silences:
    /// each piece a failed frame if it looks like one, else noise.
    pub(super) fn emit_garbage<F: FnMut(FrameEvent<'_>)>(&mut self, n: usize, emit: &mut F) {
        let stop = self.timed.head + n;
        let mut a = self.timed.head;
        while a < stop {
            let mut b = a + 1;
            while b < stop && self.timed.gap_lb[b] < self.timing.t35 {
                b += 1;
            }
            // A slow slave pauses inside its frame: when the structure says the frame goes on
            // past this silence, and it ends at a silence or at the end of the garbage, follow it.
            if let Some(l) = self.structural_len(a, stop)
                && a + l > b
                && (a + l == stop || self.timed.gap_lb[a + l] >= self.timing.t35)
                && self.timed.gap_lb[a + 1..a + l].iter().all(|&g| g < self.timing.incomplete_timeout)
            {
                b = a + l;
            }
            self.emit_piece(a, b, emit);
            a = b;
        }
        self.search.garbage = self.search.garbage.saturating_sub(n);
    }

    /// Emits bytes `a..b` (absolute, `a == self.timed.head`) that no silence divides. A frame whose
    /// end the structure could not confirm in time (a user-defined code followed by another)
    /// lands here whole, with a valid CRC; a valid frame glued to a corrupted one or to noise
    /// is split off when its CRC and structure agree. The rest is a failed frame or noise.
    pub(super) fn emit_piece<F: FnMut(FrameEvent<'_>)>(&mut self, mut a: usize, b: usize, emit: &mut F) {
        while a < b {
            let piece = &self.timed.buf[a..b];
            // A frame of a length the structure cannot tell with its `00` glitch also passes the
            // CRC (the shift property): Diagnostics' structure decides, else the odds on this line.
            if piece.len() > RTU_MIN_LEN && piece.last() == Some(&0) && self.plausible_frame(&piece[..piece.len() - 1])
            {
                let n = piece.len();
                if self.twin_len(a, n, self.sender_at(a - self.timed.head)) < n {
                    self.emit_frame(n - 1, Some(Reading::Unknown), emit);
                    self.emit_unframed(b - 1, b, emit);
                } else {
                    self.emit_frame(n, Some(Reading::Unknown), emit);
                }
                return;
            }
            if self.plausible_frame(piece) {
                self.emit_frame(b - a, Some(Reading::Unknown), emit);
                return;
            }
            let sender = self.sender_at(a - self.timed.head);
            if let Some((e, twin)) = (RTU_MIN_LEN..piece.len()).find_map(|e| self.frame_in_piece(piece, e, sender)) {
                let e = if twin { self.twin_len(a, e + 1, sender) } else { e };
                self.emit_frame(e, Some(Reading::Unknown), emit);
                a += e;
                continue;
            }
            if let Some(s) = (1..piece.len().saturating_sub(RTU_MIN_LEN - 1))
                .find(|&s| self.known_units[usize::from(piece[s])] && self.plausible_frame(&piece[s..]))
            {
                // With its `00` glitch the frame passes the CRC too: trim it where Diagnostics'
                // structure or the odds on this line say the `00` is a glitch.
                let n = piece.len() - s;
                let both = piece.last() == Some(&0) && self.plausible_frame(&piece[s..piece.len() - 1]);
                self.emit_unframed(a, a + s, emit);
                if both && self.twin_len(a + s, n, Sender::Unknown) < n {
                    self.emit_frame(n - 1, Some(Reading::Unknown), emit);
                    self.emit_unframed(b - 1, b, emit);
                } else {
                    self.emit_frame(n, Some(Reading::Unknown), emit);
                }
                return;
            }
            self.emit_unframed(a, b, emit);
            return;
        }
    }

    /// A known unit's frame at the start of `piece`, checking at `e` bytes: the length to take
    /// and whether it is a CRC-`00` twin the odds on this line decide (`twin_len`).
    ///
    /// Every `00` after a checking frame makes a longer one that checks too (CRC-16's shift
    /// property): the lengths this unit's function was seen with decide among them (
    /// noise right after a vendor answer whose CRC ends in `00` left its 1-byte-shorter twin
    /// reported valid, the learned lengths never asked). Otherwise the frame must stand by
    /// itself — a length the unit's function has, and what follows looking like a frame — and
    /// when it also checks one byte longer with a frame after that, the odds decide.
    fn frame_in_piece(&self, piece: &[u8], e: usize, sender: Sender) -> Option<(usize, bool)> {
        if !self.known_units[usize::from(piece[0])] || !self.plausible_shape(&piece[..e]) {
            return None;
        }
        let mut lengths = vec![e];
        while let Some(&l) = lengths.last()
            && piece.get(l) == Some(&0)
            && self.plausible_shape(&piece[..=l])
        {
            lengths.push(l + 1);
        }
        if lengths.len() > 1
            && let Some(len) = self.lengths.choose_among(piece[0], piece[1], sender, &lengths)
        {
            return Some((len, false));
        }
        // A run of `00`s after it: a frame ending in `00` and its `00` glitch are the last two
        // readings — a sender leaves one glitch byte, not several (else a vendor request ending
        // in `00` followed by the master's `00` glitch is taken 1 byte short).
        let e = if lengths.len() > 2 { lengths[lengths.len() - 2] } else { e };
        if !self.plausible_frame(&piece[..e]) || !self.looks_like_frame(&piece[e..]) {
            return None;
        }
        let twin = piece.get(e) == Some(&0)
            && e + 1 < piece.len()
            && self.plausible_frame(&piece[..=e])
            && self.looks_like_frame(&piece[e + 1..]);
        Some((e, twin))
    }

    /// Bytes `a..b` that hold no valid frame: a failed frame if they look like one, else noise;
    /// a lone byte right after a frame is its turnaround glitch.
    pub(super) fn emit_unframed<F: FnMut(FrameEvent<'_>)>(&mut self, a: usize, b: usize, emit: &mut F) {
        // Glued to what follows (no silence seen between them), the glitch is split off when it
        // cannot start a frame, takes a value this line's glitches take, or the bytes start like
        // a frame of a known unit only after it.
        let i = a - self.timed.head;
        let v = self.timed.buf[a];
        // A lone byte glued to the start of a frame, after a silence: the glitch of the driver
        // switching on (seen as a `00` before answers on real lines).
        if b - a == 1
            && self.last.frame_next_at == Some(b)
            && self.timed.gap_lb[b] < self.timing.t15
            && self.timed.gap_lb[a] >= self.timing.t35
            && (matches!(v, 0x00 | 0xFE | 0xFF) || self.glitches.value(v))
            && !self.at_glitch(a)
        {
            // The silence before the glitch is the silence before the frame.
            self.timed.gap_lb[b] = self.timed.gap_lb[a];
            self.timed.gap_ub[b] = self.timed.gap_ub[a];
            self.emit_glitch(a, emit);
            return;
        }
        // A lone byte right after a frame, before the next frame's start, a silence or the end
        // of what has arrived (emitted on a timeout: a request nobody answers, a broadcast),
        // taking a value this sender's driver leaves or one any driver leaves (`00`, `FE`, `FF`:
        // before this sender's own are counted), on a line seen to glitch: its glitch, whatever
        // silence the reads seem to show before it — behind a USB timer that silence is a lower
        // bound computed with a latency learned short of the timer's (46 glitches in
        // 6 000 frames were reported as noise behind a 16 ms timer at 19200; then 5, a slave's
        // first `FE` and `00`s after unanswered requests).
        if b - a == 1
            && self.last.glitch_at == Some(a)
            && (self.last.frame_next_at == Some(b)
                || b == self.timed.buf.len()
                || self.timed.gap_lb.get(b).is_some_and(|&g| g >= self.timing.t35))
            && self.glitches.glitchy()
            && (self.glitches.value_after(self.last.last_sender, v) || matches!(v, 0x00 | 0xFE | 0xFF))
        {
            self.emit_glitch(a, emit);
            return;
        }
        if self.at_glitch(a)
            && (b - a == 1
                // A reserved address starts no frame (Serial Line v1.02 §2.2); before this line
                // is known to glitch, only the values drivers leave (`FE`, `FF`) count.
                || (v > MAX_ADDRESS && (self.glitches.glitchy() || v >= 0xFE))
                || (self.glitches.glitchy() && self.glitches.value_after(self.last.last_sender, v))
                || ((self.glitches.glitchy() || matches!(v, 0x00 | 0xFE | 0xFF))
                    && !self.looks_like_frame_start(i)
                    && self.looks_like_frame_start(i + 1)))
        {
            self.emit_glitch(a, emit);
            if b > a + 1 {
                self.emit_unframed(a + 1, b, emit);
            }
            return;
        }
        // A damaged frame with its turnaround glitch, on a line that glitches: the last byte
        // takes a value this line's glitches take.
        if b - a > RTU_MIN_LEN
            && self.glitches.glitchy()
            && self.glitches.value_after(self.sender_at(a - self.timed.head), self.timed.buf[b - 1])
            && !self.expected_len_at(a, b - a)
        {
            self.emit_frame(b - a - 1, None, emit);
            self.emit_unframed(b - 1, b, emit);
            return;
        }
        // The awaited answer, damaged, with more after it: the request fixed its length
        // (an exception's is 5), whatever its damaged byte count says.
        if let Expect::Response { unit, fc, len: Some(n) } = self.expect
            && self.timed.buf[a] == unit
        {
            let n = if self.timed.buf.get(a + 1) == Some(&(fc | EXCEPTION_FLAG)) { 5 } else { n };
            if b - a > n && self.timing.latency >= self.timing.t35 {
                self.emit_frame(n, None, emit);
                self.emit_unframed(a + n, b, emit);
                return;
            }
        }
        // Two damaged frames back to back (no silence between them to go by): cut the first
        // at its structural length when what follows starts like a frame of a known unit.
        if let Some(l) = self.split_damaged(a, b) {
            self.emit_frame(l, None, emit);
            self.emit_unframed(a + l, b, emit);
            return;
        }
        if self.looks_like_frame(&self.timed.buf[a..b]) {
            self.emit_frame(b - a, None, emit);
        } else {
            self.hold.pass(
                FrameEvent::Noise(Noise {
                    port: self.port,
                    bytes: &self.timed.buf[a..b],
                    t_start: Timestamp(self.timed.end[a].saturating_sub(self.timing.char_ns)),
                    t_end: Timestamp(self.timed.end[b - 1]),
                }),
                emit,
            );
            self.timed.head = b;
            self.search.wait_at = usize::MAX;
            self.last.after_frame = false;
            self.last.after_damage = true;
        }
    }

    /// Emits the first `len` live bytes as a frame: valid, read as `reading`, or failed (`None`).
    pub(super) fn emit_frame<F: FnMut(FrameEvent<'_>)>(&mut self, len: usize, reading: Option<Reading>, emit: &mut F) {
        let check_ok = reading.is_some();
        let a = self.timed.head;
        let b = a + len;
        let ub = self.timed.gap_ub[a];
        let short_gap_before_ns = (self.last.after_frame && ub < self.timing.t35).then_some(ub);
        let apparent_before = (ub != u64::MAX).then(|| ub.saturating_sub(self.timing.latency));
        let (inner_gap, every_silence, evidence_silence) = self.apparent_inner_silence(a, b);
        let gap_tolerance_ns = evidence_silence.and_then(|s| s.checked_sub(self.timing.t15));
        self.hold.pass(
            FrameEvent::Frame(Frame {
                port: self.port,
                bytes: &self.timed.buf[a..b],
                t_start: Timestamp(self.timed.end[a].saturating_sub(self.timing.char_ns)),
                t_end: Timestamp(self.timed.end[b - 1]),
                check_ok,
                gap_violation_ns: (inner_gap >= self.timing.t15).then_some(inner_gap),
                short_gap_before_ns,
                gap_tolerance_ns,
                short_gap_tolerance_ns: self.short_tolerance(apparent_before),
                resolution_ns: self.learner.estimate.resolution_ns(),
                gap_before_known: ub != u64::MAX,
                bad_chars: false,
                alt_len: self.last.next_alt.take().filter(|_| check_ok),
            }),
            emit,
        );
        self.last.last_sender = sender_of(self.expect, &self.timed.buf[a..b], reading);
        self.last.after_damage = !check_ok;
        if check_ok {
            let after = match self.timed.buf.get(b) {
                Some(&v) => After::Byte(v),
                None if self.search.silent_after => After::Silence,
                None => After::Unknown,
            };
            // Only a frame whose length no reading fixed teaches one: a request or answer read
            // at its protocol length (`Request`, `Response`, `Either`) is one the learner would
            // parse again only to find that length exact and leave it (a mispredicted
            // function-code dispatch per frame).
            if reading == Some(Reading::Unknown) {
                self.lengths.record(&self.timed.buf[a..b], after, self.last.last_sender);
            }
            self.known_units[usize::from(self.timed.buf[a])] = true;
            self.glitches.turn.frame(self.last.last_sender);
            self.learn_from(a, every_silence);
        }
        self.expect = next_expect(self.expect, &self.timed.buf[a..b], reading);
        self.glitches.frame();
        self.last.glitch_at = Some(b);
        self.timed.head = b;
        self.search.wait_at = usize::MAX;
        self.last.after_frame = true;
    }
}
