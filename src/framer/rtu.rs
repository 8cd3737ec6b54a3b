//! The RTU framer: chunks in, frames and noise out.
//!
//! Open sniffers cut frames on silence alone, which breaks when a USB adapter or UART FIFO
//! delivers bytes in batches: the timestamps lie about where frames begin and end. This framer
//! trusts the protocol first — the length a frame must have given its function code and
//! direction (`proto::length`), confirmed by the CRC — and uses timing where timing is
//! evidence: to split bytes that form no valid frame, to end frames whose length the structure
//! cannot tell (user-defined codes), to flag t1.5 gaps inside frames, and to flush when the
//! line falls silent.
//!
//! Timing model: bytes in one chunk are taken as sent back to back, ending when the read
//! returned; the read may return up to `latency_ns` after its last byte arrived (the adapter's
//! latency timer or FIFO timeout). A silence is *known* only when it exceeds what that latency
//! could explain.
//!
//! A corrupted frame is reported with its boundaries (it ends where the next valid frame
//! begins, where its structural length ends, or at a known silence), with `check_ok = false`.

use super::event::{Frame, FrameEvent, Noise};
use super::timing::LineSettings;
use crate::chunk::{Chunk, PortId, Timestamp};
use crate::proto::checksum::{crc16, crc16_update};
use crate::proto::function::{EXCEPTION_FLAG, FunctionCode};
use crate::proto::length::{PduLength, request_len, response_len};
use crate::proto::rtu::{RTU_MAX_LEN, RTU_MIN_LEN};
use crate::proto::{DirectionHint, PduDecode, decode_pdu};

/// Framer settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FramerConfig {
    pub line: LineSettings,
    /// Longest time between a byte arriving and the read that delivers it returning
    /// (0 for per-byte timestamps; 16 ms for an FTDI adapter at its default latency timer).
    pub latency_ns: u64,
    /// How long a frame whose structure says more bytes must follow is waited for after the
    /// line falls silent. Slow slaves pause inside their frames far beyond t1.5 and even t3.5;
    /// cutting at t3.5 (as gap-only sniffers do) breaks such a frame in two.
    pub incomplete_timeout_ns: u64,
}

/// Default for [`FramerConfig::incomplete_timeout_ns`]: 50 ms.
pub const DEFAULT_INCOMPLETE_TIMEOUT_NS: u64 = 50_000_000;

impl Default for FramerConfig {
    fn default() -> Self {
        Self { line: LineSettings::default(), latency_ns: 0, incomplete_timeout_ns: DEFAULT_INCOMPLETE_TIMEOUT_NS }
    }
}

impl FramerConfig {
    /// Settings for `line` read with delivery latency `latency_ns`, other values default.
    #[must_use]
    pub fn new(line: LineSettings, latency_ns: u64) -> Self {
        Self { line, latency_ns, ..Self::default() }
    }
}

/// How much a silence lets the framer decide.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flush {
    /// Nothing new is known: decide what the bytes alone decide.
    No,
    /// The line was silent longer than t3.5: bytes known to be garbage can go out now.
    Garbage,
    /// Silent longer than the incomplete-frame timeout (or end of input): decide everything.
    All,
}

/// Bytes of garbage kept before the oldest are given up as noise, to bound memory.
const MAX_GARBAGE: usize = 2 * RTU_MAX_LEN;

enum Try {
    Found(usize),
    NotHere,
    NeedMore,
}

/// The RTU framer for one port.
#[derive(Debug)]
pub struct RtuFramer {
    port: PortId,
    char_ns: u64,
    t15: u64,
    t35: u64,
    latency: u64,
    incomplete_timeout: u64,
    buf: Vec<u8>,
    /// Latest possible end time of each buffered byte (ns).
    end: Vec<u64>,
    /// Silence known to precede each buffered byte (lower bound, ns).
    gap_lb: Vec<u64>,
    /// Silence that may at most precede each buffered byte (upper bound, ns; `u64::MAX` unknown).
    gap_ub: Vec<u64>,
    /// First live byte.
    head: usize,
    /// Live bytes from `head` known not to start a valid frame.
    garbage: usize,
    /// End time and read time of the last byte received.
    last_end: Option<u64>,
    last_read: u64,
    /// The last event emitted was a frame (for the inter-frame gap check).
    after_frame: bool,
}

impl RtuFramer {
    #[must_use]
    pub fn new(port: PortId, config: FramerConfig) -> Self {
        Self {
            port,
            char_ns: config.line.char_ns(),
            t15: config.line.t15_ns(),
            t35: config.line.t35_ns(),
            latency: config.latency_ns,
            incomplete_timeout: config.incomplete_timeout_ns,
            buf: Vec::with_capacity(4 * RTU_MAX_LEN),
            end: Vec::with_capacity(4 * RTU_MAX_LEN),
            gap_lb: Vec::with_capacity(4 * RTU_MAX_LEN),
            gap_ub: Vec::with_capacity(4 * RTU_MAX_LEN),
            head: 0,
            garbage: 0,
            last_end: None,
            last_read: 0,
            after_frame: false,
        }
    }

    /// Bytes waiting for a decision.
    #[must_use]
    pub fn pending(&self) -> usize {
        self.buf.len() - self.head
    }

    /// Feeds one chunk; emits every event it decides.
    pub fn push<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, emit: &mut F) {
        let t = chunk.t.0;
        // What the silence before this chunk decides is decided first, exactly as a `tick` in
        // that silence would have: live and replayed input give the same events.
        if let Some(first_end) = self.first_end_estimate(chunk) {
            self.tick(Timestamp(first_end.saturating_sub(self.char_ns)), emit);
        }
        let n = chunk.bytes.len();
        let c = self.char_ns;
        for (i, &b) in chunk.bytes.iter().enumerate() {
            let behind = u64::try_from(n - 1 - i).unwrap_or(u64::MAX).saturating_mul(c);
            let mut e = t.saturating_sub(behind);
            let (lb, ub) = match self.last_end {
                // Bytes cannot overlap on the wire: a later byte ends at least a character later.
                Some(prev) => {
                    e = e.max(prev.saturating_add(c));
                    if i == 0 {
                        let start = e - c;
                        let lb = start.saturating_sub(self.latency).saturating_sub(prev);
                        let ub = start.saturating_sub(prev.saturating_sub(self.latency));
                        (lb, ub)
                    } else {
                        (0, u64::MAX)
                    }
                }
                None => (u64::MAX, u64::MAX),
            };
            self.buf.push(b);
            self.end.push(e);
            self.gap_lb.push(lb);
            self.gap_ub.push(ub);
            self.last_end = Some(e);
        }
        self.last_read = self.last_read.max(t);
        self.process(Flush::No, emit);
    }

    fn first_end_estimate(&self, chunk: &Chunk<'_>) -> Option<u64> {
        let n = u64::try_from(chunk.bytes.len()).ok()?;
        if n == 0 {
            return None;
        }
        Some(chunk.t.0.saturating_sub((n - 1) * self.char_ns))
    }

    /// Tells the framer the time is `now` with nothing new received: if the line has been
    /// silent longer than t3.5 (plus latency), pending bytes are decided.
    pub fn tick<F: FnMut(FrameEvent<'_>)>(&mut self, now: Timestamp, emit: &mut F) {
        let Some(last) = self.last_end else { return };
        if self.pending() == 0 {
            return;
        }
        let silence = now.0.saturating_sub(last).saturating_sub(self.latency);
        if silence >= self.incomplete_timeout {
            self.process(Flush::All, emit);
        } else if silence >= self.t35 && self.garbage > 0 {
            self.process(Flush::Garbage, emit);
        }
    }

    /// End of input: decides everything pending.
    pub fn finish<F: FnMut(FrameEvent<'_>)>(&mut self, emit: &mut F) {
        self.process(Flush::All, emit);
    }

    fn crc_ok(frame: &[u8]) -> bool {
        let [body @ .., lo, hi] = frame else { return false };
        crc16(body) == u16::from_le_bytes([*lo, *hi])
    }

    /// Is there a known silence (≥ t3.5) before live index `i`?
    fn boundary_at(&self, i: usize) -> bool {
        self.gap_lb.get(self.head + i).is_some_and(|&g| g >= self.t35)
    }

    /// Does a valid frame of structurally exact length start at live index `i`?
    fn exact_frame_at(&self, i: usize) -> bool {
        let s = &self.buf[self.head + i..];
        if s.len() < RTU_MIN_LEN {
            return false;
        }
        let pdu = &s[1..];
        let resp = response_len(pdu);
        let req = if s[1] & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        [req, resp].into_iter().any(|c| match c {
            PduLength::Exact(k) => s.get(..k + 3).is_some_and(Self::crc_ok),
            _ => false,
        })
    }

    fn try_frame_at(&self, g: usize, flushing: bool) -> Try {
        let live = &self.buf[self.head..];
        let s = &live[g..];
        let [_, fc, ..] = *s else { return if flushing { Try::NotHere } else { Try::NeedMore } };
        let pdu = &s[1..];
        let resp = response_len(pdu);
        let req = if fc & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        let mut need_more = false;
        let mut unknown = false;
        // Both readings are tried: a frame whose CRC ends in 0x00 also validates one byte
        // shorter (the CRC's shift property), and a next frame starting with 0x00 validates
        // one byte longer; the structure decides between them (see `best`).
        let mut found: [Option<(usize, bool)>; 2] = [None, None];
        for (slot, (cand, is_request)) in [(req, true), (resp, false)].into_iter().enumerate() {
            match cand {
                PduLength::Exact(k) => {
                    let l = k + 3;
                    if l > RTU_MAX_LEN {
                        continue;
                    }
                    match s.get(..l) {
                        Some(f) if Self::crc_ok(f) => found[slot] = Some((l, is_request)),
                        Some(_) => {}
                        None => need_more = true,
                    }
                }
                PduLength::AtLeast(_) => need_more = true,
                PduLength::Unknown => unknown = true,
            }
        }
        match found {
            [Some((l, _)), None] | [None, Some((l, _))] if !need_more || flushing => return Try::Found(l),
            [Some(a), Some(b)] => return Try::Found(self.best(g, a, b)),
            [Some(_), None] | [None, Some(_)] => return Try::NeedMore,
            [None, None] => {}
        }
        if unknown && fc & EXCEPTION_FLAG == 0 {
            match self.unknown_length_at(g, flushing) {
                Try::NeedMore => need_more = true,
                t @ Try::Found(_) => return t,
                Try::NotHere => {}
            }
        }
        if need_more && !flushing { Try::NeedMore } else { Try::NotHere }
    }

    /// Two readings with valid CRCs: prefer the one the next bytes confirm, then the one that
    /// fits its function's structure without findings, then the shorter.
    fn best(&self, g: usize, a: (usize, bool), b: (usize, bool)) -> usize {
        let score = |(l, is_request): (usize, bool)| {
            let confirmed = self.boundary_at(g + l) || self.exact_frame_at(g + l);
            let s = &self.buf[self.head + g..self.head + g + l];
            let hint = if is_request { DirectionHint::Request } else { DirectionHint::Response };
            let clean = matches!(decode_pdu(&s[1..l - 2], hint), PduDecode::One(d) if d.findings.is_empty());
            (confirmed, clean, std::cmp::Reverse(l))
        };
        if score(b) > score(a) { b.0 } else { a.0 }
    }

    /// The structure cannot say where this frame ends: accept a CRC match only where something
    /// confirms an end — a known silence, the end of input, or a valid frame after it. Public
    /// and user-defined codes may pause inside a frame (slow slaves), so for them only a
    /// silence longer than the incomplete-frame timeout bounds the search.
    fn unknown_length_at(&self, g: usize, flushing: bool) -> Try {
        let live_len = self.buf.len() - self.head;
        let s = &self.buf[self.head + g..];
        let base = FunctionCode::from(s[1]);
        let lenient = base.name().is_some() || base.is_user_defined();
        let max = s.len().min(RTU_MAX_LEN);
        let mut bounded = false;
        let mut crc = 0;
        for l in RTU_MIN_LEN..=max {
            // `crc` covers the body s[..l - 2], one byte more each step.
            crc = if l == RTU_MIN_LEN { crc16(&s[..2]) } else { crc16_update(crc, &s[l - 3..l - 2]) };
            let received = u16::from_le_bytes([s[l - 2], s[l - 1]]);
            if crc == received
                && (self.boundary_at(g + l) || (flushing && g + l == live_len) || self.exact_frame_at(g + l))
            {
                return Try::Found(l);
            }
            if l < s.len() {
                let gap = self.gap_lb[self.head + g + l];
                if gap >= self.incomplete_timeout || (!lenient && gap >= self.t35) {
                    bounded = true;
                    break;
                }
            }
        }
        if !bounded && !flushing && s.len() < RTU_MAX_LEN { Try::NeedMore } else { Try::NotHere }
    }

    fn process<F: FnMut(FrameEvent<'_>)>(&mut self, flush: Flush, emit: &mut F) {
        let flushing = flush == Flush::All;
        loop {
            let live_len = self.buf.len() - self.head;
            if self.garbage >= live_len {
                break;
            }
            match self.try_frame_at(self.garbage, flushing) {
                Try::Found(len) => {
                    self.emit_garbage(self.garbage, emit);
                    self.emit_frame(len, true, emit);
                }
                Try::NotHere => {
                    self.garbage += 1;
                    if self.garbage >= MAX_GARBAGE {
                        self.emit_garbage(RTU_MAX_LEN, emit);
                    }
                }
                Try::NeedMore => break,
            }
        }
        match flush {
            Flush::All => {
                let g = self.garbage;
                self.emit_garbage(g, emit);
            }
            // Only whole pieces: garbage that ends at a known silence. The bytes after the
            // last such silence may still continue into the next undecided byte.
            Flush::Garbage => {
                if let Some(b) = (1..=self.garbage).rev().find(|&b| self.boundary_at(b)) {
                    self.emit_garbage(b, emit);
                }
            }
            Flush::No => {}
        }
        self.compact();
    }

    fn compact(&mut self) {
        if self.head > 0 && (self.head == self.buf.len() || self.head >= 8192) {
            self.buf.drain(..self.head);
            self.end.drain(..self.head);
            self.gap_lb.drain(..self.head);
            self.gap_ub.drain(..self.head);
            self.head = 0;
        }
    }

    /// Emits the first `n` live bytes, known to form no valid frame, split at known silences:
    /// each piece a failed frame if it looks like one, else noise.
    fn emit_garbage<F: FnMut(FrameEvent<'_>)>(&mut self, n: usize, emit: &mut F) {
        let stop = self.head + n;
        let mut a = self.head;
        while a < stop {
            let mut b = a + 1;
            while b < stop && self.gap_lb[b] < self.t35 {
                b += 1;
            }
            // Every emission below advances `self.head` to `b`.
            if looks_like_frame(&self.buf[a..b]) {
                self.emit_frame(b - a, false, emit);
            } else {
                emit(FrameEvent::Noise(Noise {
                    port: self.port,
                    bytes: &self.buf[a..b],
                    t_start: Timestamp(self.end[a].saturating_sub(self.char_ns)),
                    t_end: Timestamp(self.end[b - 1]),
                }));
                self.head = b;
                self.after_frame = false;
            }
            a = b;
        }
        self.garbage = self.garbage.saturating_sub(n);
    }

    /// Emits the first `len` live bytes as a frame.
    fn emit_frame<F: FnMut(FrameEvent<'_>)>(&mut self, len: usize, check_ok: bool, emit: &mut F) {
        let a = self.head;
        let b = a + len;
        let inner_gap = self.gap_lb[a + 1..b].iter().copied().max().unwrap_or(0);
        let ub = self.gap_ub[a];
        let short_gap_before_ns = (self.after_frame && ub < self.t35).then_some(ub);
        emit(FrameEvent::Frame(Frame {
            port: self.port,
            bytes: &self.buf[a..b],
            t_start: Timestamp(self.end[a].saturating_sub(self.char_ns)),
            t_end: Timestamp(self.end[b - 1]),
            check_ok,
            gap_violation_ns: (inner_gap >= self.t15).then_some(inner_gap),
            short_gap_before_ns,
            bad_chars: false,
        }));
        self.head = b;
        self.after_frame = true;
    }
}

/// A failed-check piece is reported as a frame when it could be one: 4 to 256 bytes starting
/// with a unicast or broadcast address and a public, user-defined or exception function code.
fn looks_like_frame(piece: &[u8]) -> bool {
    let [addr, fc, ..] = *piece else { return false };
    let base = FunctionCode::from(fc & !EXCEPTION_FLAG);
    (RTU_MIN_LEN..=RTU_MAX_LEN).contains(&piece.len())
        && addr <= 247
        && (base.name().is_some() || base.is_user_defined())
        && fc != 0
}
