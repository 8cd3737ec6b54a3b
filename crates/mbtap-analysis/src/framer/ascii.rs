//! The ASCII framer: ':' starts a frame, CR LF ends it (Modbus over Serial Line v1.02
//! §2.5.2.1); a new ':' inside a frame restarts it, as the spec tells receivers to do; an
//! inter-character silence over 1 s is flagged. Anything outside a frame is noise.

use super::event::{Frame, FrameEvent, Noise};
use crate::chunk::{Chunk, PortId, Timestamp};
use mbtap_proto::ascii::{ASCII_MAX_LEN, parse_ascii};

/// Inter-character timeout: "1 second by default" (Modbus over Serial Line v1.02 §2.5.2.1).
pub const ASCII_CHAR_TIMEOUT_NS: u64 = 1_000_000_000;

/// The ASCII framer for one port.
#[derive(Debug)]
pub struct AsciiFramer {
    port: PortId,
    char_ns: u64,
    buf: Vec<u8>,
    noise: Vec<u8>,
    t_start: u64,
    t_last: u64,
    noise_start: u64,
    max_gap: u64,
}

impl AsciiFramer {
    #[must_use]
    pub fn new(port: PortId, line: super::LineSettings) -> Self {
        Self {
            port,
            char_ns: line.char_ns(),
            buf: Vec::with_capacity(ASCII_MAX_LEN),
            noise: Vec::new(),
            t_start: 0,
            t_last: 0,
            noise_start: 0,
            max_gap: 0,
        }
    }

    /// Feeds one chunk.
    pub fn push<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, emit: &mut F) {
        let n = chunk.bytes.len();
        for (i, &b) in chunk.bytes.iter().enumerate() {
            let behind = u64::try_from(n - 1 - i).unwrap_or(u64::MAX).saturating_mul(self.char_ns);
            let t = chunk.t.0.saturating_sub(behind).max(self.t_last);
            self.byte(b, t, emit);
        }
    }

    fn byte<F: FnMut(FrameEvent<'_>)>(&mut self, b: u8, t: u64, emit: &mut F) {
        if b == b':' {
            // A ':' always starts a new frame; whatever was open is incomplete.
            self.flush_open(emit);
            self.flush_noise(emit);
            self.buf.push(b);
            self.t_start = t.saturating_sub(self.char_ns);
            self.t_last = t;
            self.max_gap = 0;
            return;
        }
        if self.buf.is_empty() {
            if self.noise.is_empty() {
                self.noise_start = t.saturating_sub(self.char_ns);
            }
            self.noise.push(b);
            self.t_last = t;
            return;
        }
        self.max_gap = self.max_gap.max(t.saturating_sub(self.t_last).saturating_sub(self.char_ns));
        self.buf.push(b);
        self.t_last = t;
        if self.buf.ends_with(b"\r\n") || self.buf.len() > 2 * ASCII_MAX_LEN {
            self.emit_open(emit);
        }
    }

    fn emit_open<F: FnMut(FrameEvent<'_>)>(&mut self, emit: &mut F) {
        let parsed = parse_ascii(&self.buf);
        let check_ok = parsed.as_ref().is_ok_and(|f| f.check_ok() && f.terminated);
        let bad_chars = matches!(parsed, Err(mbtap_proto::AduError::BadCharacter { .. }));
        emit(FrameEvent::Frame(Frame {
            port: self.port,
            bytes: &self.buf,
            t_start: Timestamp(self.t_start),
            t_end: Timestamp(self.t_last),
            check_ok,
            gap_violation_ns: (self.max_gap > ASCII_CHAR_TIMEOUT_NS).then_some(self.max_gap),
            short_gap_before_ns: None,
            // A 1 s timeout dwarfs any observer's delay: the pause is taken as it was seen.
            gap_tolerance_ns: self.max_gap.checked_sub(ASCII_CHAR_TIMEOUT_NS).filter(|&g| g > 0),
            short_gap_tolerance_ns: None,
            resolution_ns: 0,
            // ASCII frames are cut at their ':' and CR LF; the read time of the ':' bounds the start.
            gap_before_known: true,
            bad_chars,
            alt_len: None,
        }));
        self.buf.clear();
    }

    fn flush_open<F: FnMut(FrameEvent<'_>)>(&mut self, emit: &mut F) {
        if !self.buf.is_empty() {
            self.emit_open(emit);
        }
    }

    fn flush_noise<F: FnMut(FrameEvent<'_>)>(&mut self, emit: &mut F) {
        if !self.noise.is_empty() {
            emit(FrameEvent::Noise(Noise {
                port: self.port,
                bytes: &self.noise,
                t_start: Timestamp(self.noise_start),
                t_end: Timestamp(self.t_last),
            }));
            self.noise.clear();
        }
    }

    /// Time passes with nothing received: a frame open longer than the 1 s timeout is closed.
    pub fn tick<F: FnMut(FrameEvent<'_>)>(&mut self, now: Timestamp, emit: &mut F) {
        if now.0.saturating_sub(self.t_last) > ASCII_CHAR_TIMEOUT_NS {
            self.flush_open(emit);
            self.flush_noise(emit);
        }
    }

    /// End of input.
    pub fn finish<F: FnMut(FrameEvent<'_>)>(&mut self, emit: &mut F) {
        self.flush_open(emit);
        self.flush_noise(emit);
    }
}
