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
//!
//! Direction and expectation: on a half-duplex bus the next frame is nearly always determined —
//! after an answer or a broadcast, a request; after a request, that unit's answer, whose length
//! the request fixes (`proto::answer_len`). When two readings of the same bytes both pass the
//! CRC (a frame F ending in `00` also validates one byte shorter, and F followed by a `00`
//! glitch validates one byte longer — CRC-16/MODBUS's shift property), the expected one wins;
//! only when nothing is expected do structure and timing decide.
//!
//! Turnaround glitches: RS-485 transceivers on a line without fail-safe biasing leave one
//! garbage byte when their driver switches off (`00` with a framing error after the master,
//! `FE`/`FF` after a slave), within a character of the frame's last byte. A lone byte right
//! after a frame that begins no frame is reported as a [`FrameEvent::Glitch`], never as part of
//! the frame, a frame of its own, or noise.

use super::event::{Frame, FrameEvent, Noise};
use super::glitch::{Sender, TurnaroundStats};
use super::lengths::LearnedLengths;
use super::observer::{ObserverEstimate, ObserverLearner, SampleSender};
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
    /// Whether the latency may be raised by what valid frames show of this observer's reads
    /// (see [`super::observer`]); off when the user gave it (`--latency-ms`).
    pub learn_latency: bool,
    /// Frames pasted from logs (`decode`) rather than heard on a line: they may start with a
    /// reserved address (248–255, Serial Line v1.02 §2.2) — devices configured at 254 or 255,
    /// which many answer as a "whoever is connected" address, are cut like any other unit's —
    /// and an exception may carry function 0 (`80`, shown with a finding). On a line both are
    /// far likelier a glitch or garbage, so it is off there.
    pub pasted: bool,
    /// Whether the lengths each unit's vendor functions were seen with decide CRC-`00` twins
    /// (see [`super::lengths`]); off only to measure what it does.
    pub learn_lengths: bool,
}

/// Default for [`FramerConfig::incomplete_timeout_ns`]: 50 ms.
pub const DEFAULT_INCOMPLETE_TIMEOUT_NS: u64 = 50_000_000;

impl Default for FramerConfig {
    fn default() -> Self {
        Self {
            line: LineSettings::default(),
            latency_ns: 0,
            incomplete_timeout_ns: DEFAULT_INCOMPLETE_TIMEOUT_NS,
            learn_latency: true,
            pasted: false,
            learn_lengths: true,
        }
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

/// How a valid frame was read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reading {
    Request,
    Response,
    /// Both readings, at the same length (echo shapes: 05, 06, 08, 0F, 10 answers).
    Either,
    /// Neither reading fixes the length (vendor codes): the CRC and what follows ended it.
    Unknown,
}

impl Reading {
    /// The reading of one direction.
    fn of(is_request: bool) -> Self {
        if is_request { Self::Request } else { Self::Response }
    }
}

/// Does `pdu`, read in this direction, decode as one PDU without findings (no absurd quantity,
/// no byte count its quantity contradicts)?
fn decodes_clean(pdu: &[u8], is_request: bool) -> bool {
    let hint = if is_request { DirectionHint::Request } else { DirectionHint::Response };
    matches!(decode_pdu(pdu, hint), PduDecode::One(d) if d.findings.is_empty())
}

/// What the next frame on the bus should be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    /// Nothing known yet (start of input, after damage nobody can place).
    Unknown,
    /// A request: the last transaction is complete.
    Request,
    /// The answer of `unit` to `fc`: `len` bytes (RTU ADU) when the request fixes it; an
    /// exception answer is 5 bytes whatever the request.
    Response { unit: u8, fc: u8, len: Option<usize> },
}

/// The highest unicast address (Modbus over Serial Line v1.02 §2.2: 1–247; 0 broadcast).
const MAX_ADDRESS: u8 = 247;

/// Frames after the last glitch for which the line still counts as glitch-prone.
const GLITCHY_FOR: u32 = 64;

enum Try {
    /// A frame of this length, read so; with another length that checks too and that nothing
    /// but the odds on this line ruled out (see [`Frame::alt_len`]).
    Found(usize, Reading, Option<usize>),
    NotHere,
    /// Nothing can change until this many bytes (from the candidate start) are buffered.
    NeedMore(usize),
}

/// The RTU framer for one port.
#[derive(Debug)]
pub struct RtuFramer {
    port: PortId,
    /// The highest address a frame may start with: 247, or 255 for pasted frames.
    max_address: u8,
    /// Pasted frames (see [`FramerConfig::pasted`]).
    pasted: bool,
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
    /// The candidate start last found waiting (`garbage` then), and how many bytes from it
    /// must be buffered before trying it again is worth it: skips re-parsing on every byte.
    wait_at: usize,
    wait_for: usize,
    /// Addresses seen in frames with a valid CRC: a failed piece that starts with one is a
    /// corrupted frame even when the corruption hit its function code.
    known_units: [bool; 256],
    /// What the next frame should be.
    expect: Expect,
    /// Absolute buffer index right after the last frame: a lone byte there is a glitch.
    glitch_at: Option<usize>,
    /// Frames since the last glitch (`u32::MAX`: none seen).
    since_glitch: u32,
    /// How often each byte value was a glitch (`00`, `FE`, `FF` on most transceivers); see
    /// [`Self::glitch_value`].
    glitch_counts: [u32; 256],
    /// The count of the commonest glitch value.
    glitch_top: u32,
    /// While the garbage before a found frame goes out: where that frame starts (a lone byte
    /// glued to its start is the sender's driver switching on).
    frame_next_at: Option<usize>,
    /// How often the master's and the slaves' frames are followed by a `00` glitch.
    turn: TurnaroundStats,
    /// Who sent the last frame emitted (whose glitch the next lone byte would be).
    last_sender: Sender,
    /// The other length of the frame about to be emitted, if any (see [`Frame::alt_len`]).
    next_alt: Option<usize>,
    /// What the valid frames show of this observer's reads.
    learner: ObserverLearner,
    /// Lengths each unit's vendor functions were seen with (issue 25).
    lengths: LearnedLengths,
    /// The last thing emitted (glitches aside) was a failed frame or noise: nothing is
    /// expected, and a CRC match right after damage must be confirmed by what follows.
    after_damage: bool,
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
            wait_at: usize::MAX,
            wait_for: 0,
            known_units: [false; 256],
            expect: Expect::Unknown,
            glitch_at: None,
            since_glitch: u32::MAX,
            glitch_counts: [0; 256],
            glitch_top: 0,
            frame_next_at: None,
            turn: TurnaroundStats::default(),
            last_sender: Sender::Unknown,
            next_alt: None,
            after_damage: false,
            learner: ObserverLearner::new(config.latency_ns, config.learn_latency, config.line.char_ns()),
            lengths: LearnedLengths::new(config.learn_lengths),
            max_address: if config.pasted { u8::MAX } else { MAX_ADDRESS },
            pasted: config.pasted,
        }
    }

    /// Has this line shown turnaround glitches lately?
    fn glitchy(&self) -> bool {
        self.since_glitch < GLITCHY_FOR
    }

    /// Is `v` a value this line's glitches take? A transceiver leaves the same one or two values
    /// again and again; a byte taken for a glitch by mistake is a value seen now and then.
    /// Counted values become glitch values from the fourth time, and only while they are at
    /// least an eighth as common as the commonest.
    fn glitch_value(&self, v: u8) -> bool {
        let n = self.glitch_counts[usize::from(v)];
        n >= 4 && n.saturating_mul(8) >= self.glitch_top
    }

    /// Is `v` a value the driver of `sender` leaves (the line's values when nobody can say who
    /// sent the frame, or the sender was never seen to glitch)?
    fn glitch_value_after(&self, sender: Sender, v: u8) -> bool {
        self.turn.sender_value(sender, v).unwrap_or_else(|| self.glitch_value(v))
    }

    /// Is `n` bytes the length a damaged frame at absolute `a` (`== self.head`) must have: the
    /// awaited answer's (an exception's 5), or — a request awaited — its own structure's?
    fn expected_len_at(&self, a: usize, n: usize) -> bool {
        match self.expect {
            Expect::Response { unit, fc, len: Some(l) } if self.buf[a] == unit => {
                n == if self.buf.get(a + 1) == Some(&(fc | EXCEPTION_FLAG)) { 5 } else { l }
            }
            Expect::Request => {
                let f = &self.buf[a..a + n];
                f.len() >= 2
                    && f[1] & EXCEPTION_FLAG == 0
                    && matches!(request_len(&f[1..]), PduLength::Exact(k) if k + 3 == n)
            }
            _ => false,
        }
    }

    /// What the bus expects of a frame at live index `g`: bytes before it that are not a lone
    /// glitch are damage nobody can read — one frame or several, requests or answers: after
    /// them nothing is expected.
    fn expect_at(&self, g: usize) -> Expect {
        if g == 0 || (g == 1 && self.at_glitch(self.head)) { self.expect } else { Expect::Unknown }
    }

    /// Does reading `l` bytes at live index `g` as `reading` give what the bus expects next?
    fn expected(&self, g: usize, l: usize, reading: Reading) -> bool {
        let s = &self.buf[self.head + g..];
        match self.expect_at(g) {
            Expect::Unknown => false,
            Expect::Request => reading == Reading::Request,
            Expect::Response { unit, fc, len } => {
                reading == Reading::Response
                    && s.first() == Some(&unit)
                    && match s.get(1) {
                        Some(&f) if f == fc => len.is_none_or(|n| n == l),
                        // Exception: unit, function | 0x80, code, CRC (MAP v1.1b3 §7).
                        Some(&f) => f == fc | EXCEPTION_FLAG && l == 5,
                        None => false,
                    }
            }
        }
    }

    /// What this framer learned about its observer's reads.
    #[must_use]
    pub fn observer(&self) -> ObserverEstimate {
        self.learner.estimate
    }

    /// What the session that recorded the input learned about its reads (the capture says so
    /// at its end): shown beside what this run learned.
    pub fn set_recorded_latency(&mut self, ns: u64) {
        self.learner.estimate.recorded_latency_ns = Some(ns);
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
        if n > 0 {
            self.learner.read(n);
        }
        let c = self.char_ns;
        if self.pending() == 0
            && let Some(reading) = Self::whole_frame(chunk.bytes)
        {
            self.emit_whole_chunk(chunk, reading, emit);
            return;
        }
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
                        start.saturating_sub(self.latency).saturating_sub(prev),
                        start.saturating_sub(prev.saturating_sub(self.latency)),
                    )
                }
                None => (u64::MAX, u64::MAX),
            };
            let at = self.buf.len();
            self.buf.extend_from_slice(chunk.bytes);
            self.end.extend((0..n as u64).map(|i| e0.saturating_add(i.saturating_mul(c))));
            self.gap_lb.resize(at + n, 0);
            self.gap_ub.resize(at + n, u64::MAX);
            self.gap_lb[at] = lb;
            self.gap_ub[at] = ub;
            self.last_end = self.end.last().copied();
        }
        self.last_read = self.last_read.max(t);
        self.process(Flush::No, emit);
    }

    /// Feeds a chunk known to be exactly one frame — bytes this program wrote itself (the
    /// bridge's requests and answers, for `--monitor`): what was buffered on this port is
    /// complete before it, and it goes out whole at once, whatever its function code (a vendor
    /// frame need not wait for the silence after it). A chunk that fails its CRC takes the
    /// general path.
    pub fn push_whole<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, emit: &mut F) {
        if chunk.bytes.len() < RTU_MIN_LEN || !Self::crc_ok(chunk.bytes) {
            self.push(chunk, emit);
            return;
        }
        if self.pending() > 0 {
            self.process(Flush::All, emit);
        }
        let reading = Self::whole_frame(chunk.bytes).unwrap_or(Reading::Unknown);
        self.emit_whole_chunk(chunk, reading, emit);
    }

    /// Is `bytes` exactly one frame that the general path would accept at once: every reading
    /// of its structure resolved within it, exactly one with a valid CRC, and that one the
    /// whole chunk? (Gap-cutting sniffers write one frame per packet; this skips buffering.)
    /// The reading it was, if so.
    fn whole_frame(bytes: &[u8]) -> Option<Reading> {
        let [_, fc, ..] = *bytes else { return None };
        let pdu = &bytes[1..];
        let req = if fc & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        let mut found = [false; 2];
        for (slot, cand) in [req, response_len(pdu)].into_iter().enumerate() {
            match cand {
                PduLength::Exact(k) if k + 3 <= RTU_MAX_LEN => match bytes.get(..k + 3) {
                    Some(f) if Self::crc_ok(f) => {
                        if f.len() != bytes.len() {
                            return None;
                        }
                        found[slot] = true;
                    }
                    Some(_) => {}
                    None => return None,
                },
                PduLength::Exact(_) => {}
                // An exception's request reading is no reading at all.
                PduLength::Unknown if fc & EXCEPTION_FLAG != 0 => {}
                PduLength::AtLeast(_) | PduLength::Unknown => return None,
            }
        }
        match found {
            // An echo shape validates both ways at the same length: still one frame.
            [true, true] => Some(Reading::Either),
            [true, false] => Some(Reading::Request),
            [false, true] => Some(Reading::Response),
            [false, false] => None,
        }
    }

    /// Emits a chunk that [`Self::whole_frame`] accepted, with the same timing the buffered
    /// path would give it.
    fn emit_whole_chunk<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, reading: Reading, emit: &mut F) {
        let c = self.char_ns;
        let n = u64::try_from(chunk.bytes.len()).unwrap_or(u64::MAX);
        let mut e0 = chunk.t.0.saturating_sub((n - 1).saturating_mul(c));
        let ub = match self.last_end {
            Some(prev) => {
                e0 = e0.max(prev.saturating_add(c));
                e0.saturating_sub(c).saturating_sub(prev.saturating_sub(self.latency))
            }
            None => u64::MAX,
        };
        let t_end = e0.saturating_add((n - 1).saturating_mul(c));
        let apparent_before = (ub != u64::MAX).then(|| ub.saturating_sub(self.latency));
        emit(FrameEvent::Frame(Frame {
            port: self.port,
            bytes: chunk.bytes,
            t_start: Timestamp(e0.saturating_sub(c)),
            t_end: Timestamp(t_end),
            check_ok: true,
            gap_violation_ns: None,
            short_gap_before_ns: (self.after_frame && ub < self.t35).then_some(ub),
            gap_tolerance_ns: None,
            short_gap_tolerance_ns: self.short_tolerance(apparent_before),
            resolution_ns: self.learner.estimate.resolution_ns(),
            gap_before_known: ub != u64::MAX,
            bad_chars: false,
            alt_len: None,
        }));
        self.known_units[usize::from(chunk.bytes[0])] = true;
        self.last_sender = sender_of(self.expect, chunk.bytes, Some(reading));
        self.after_damage = false;
        self.turn.frame(self.last_sender);
        self.learner.frame();
        self.last_end = Some(t_end);
        self.last_read = self.last_read.max(chunk.t.0);
        self.after_frame = true;
        self.wait_at = usize::MAX;
        self.expect = next_expect(self.expect, chunk.bytes, Some(reading));
        self.since_glitch = self.since_glitch.saturating_add(1);
        // The next byte buffered lands at the end of the (empty) live buffer.
        self.glitch_at = Some(self.buf.len());
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
        let [addr, fc, ..] = *s else { return if flushing { Try::NotHere } else { Try::NeedMore(2) } };
        // Addresses 248–255 are reserved (Modbus over Serial Line v1.02 §2.2): no frame on a line
        // starts with one, whatever its CRC says (pasted frames may: `FramerConfig::pasted`).
        if addr > self.max_address {
            return Try::NotHere;
        }
        // While resynchronising through garbage, a chance CRC match (1 in 65 536 per
        // candidate) is likelier than the first frame of a never-seen unit with no silence
        // before it — unless what follows confirms it too (a silence, another valid frame, its
        // glitch): then a damaged start does not hide the valid frames after it. Right after a
        // frame's glitch byte a frame may start anyway.
        let after_glitch = g == 1 && self.at_glitch(self.head);
        let unconfirmed_start = g > 0 && !self.known_units[usize::from(addr)] && !self.boundary_at(g) && !after_glitch;
        // Inside damage, a never-seen unit's frame must at least carry a function code with a
        // public layout: checked before any CRC is computed, so a stream of garbage costs a
        // byte comparison per position, not a CRC over every length.
        if unconfirmed_start && FunctionCode::from(fc & !EXCEPTION_FLAG).name().is_none() {
            return Try::NotHere;
        }
        let pdu = &s[1..];
        // Address 0 is a broadcast: a request, of a write, never answered (Serial Line v1.02
        // §2.1) — no other reading of it is worth waiting for.
        let broadcast = addr == 0;
        if !sane_header(s, self.pasted) {
            return Try::NotHere;
        }
        let resp = if broadcast { PduLength::Unknown } else { response_len(pdu) };
        let req = if fc & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        let mut need_more = false;
        let mut need = usize::MAX;
        let mut unknown = false;
        // Whether a reading still waiting for bytes could be a well-formed frame at all.
        let mut wait_worth = false;
        // Both readings are tried: a frame whose CRC ends in 0x00 also validates one byte
        // shorter (the CRC's shift property), and a next frame starting with 0x00 validates
        // one byte longer; the structure decides between them (see `best`).
        let mut found: [Option<(usize, bool)>; 2] = [None, None];
        let mut exact: [(usize, usize, bool); 2] = [(usize::MAX, 0, false); 2];
        for (slot, (cand, is_request)) in [(req, true), (resp, false)].into_iter().enumerate() {
            match cand {
                PduLength::Exact(k) => {
                    let l = k + 3;
                    if l > RTU_MAX_LEN {
                        continue;
                    }
                    if l > s.len() {
                        need_more = true;
                        need = need.min(l);
                        wait_worth |= consistent(pdu, is_request);
                    } else {
                        exact[slot] = (l, slot, is_request);
                    }
                }
                PduLength::AtLeast(k) => {
                    need_more = true;
                    need = need.min(k + 1);
                    wait_worth = true;
                }
                PduLength::Unknown => unknown = true,
            }
        }
        // Shorter candidate first, so one running CRC serves both.
        exact.sort_unstable_by_key(|e| e.0);
        let (mut crc, mut done) = (crate::proto::checksum::CRC16_INIT, 0usize);
        for (l, slot, is_request) in exact {
            if l == usize::MAX {
                continue;
            }
            if l < RTU_MIN_LEN {
                continue;
            }
            crc = crc16_update(crc, &s[done..l - 2]);
            done = l - 2;
            if crc == u16::from_le_bytes([s[l - 2], s[l - 1]]) {
                found[slot] = Some((l, is_request));
            }
        }
        let reading_of = Reading::of;
        let clean = |l: usize, is_request: bool| decodes_clean(&s[1..l - 2], is_request);
        let answer_expected = (g == 0 || after_glitch) && matches!(self.expect, Expect::Response { .. });
        // Bytes before `g` that are not a lone glitch are damage too, not yet emitted.
        let inside_damage = g > 0 && !after_glitch;
        for slot in &mut found {
            if let Some((l, is_request)) = *slot
                // A reading whose byte count its own quantity contradicts is no frame, whatever
                // its CRC says: valid frames glued together check as one (each leaves the CRC at
                // zero), and a chance match over damage does in 1 of 65 536.
                && (!consistent(&s[1..l - 2], is_request)
                    // While an answer is awaited, a reading that is not it must at least be well
                    // formed: a damaged answer ending in `00` checks one byte shorter, as a
                    // request with an absurd quantity. Inside damage too: a CRC matching by
                    // chance over a damaged byte count gives absurd quantities.
                    || ((inside_damage || (answer_expected && !self.expected(g, l, reading_of(is_request))))
                        && !clean(l, is_request)))
            {
                *slot = None;
            }
        }
        // Right after damage nothing is expected, and a damaged byte count can make a shorter
        // frame whose CRC matches by chance (1 in 65 536): what follows must confirm it.
        let after_damage = self.after_damage && (g == 0 || after_glitch) && found.iter().any(Option::is_some);
        if unconfirmed_start || after_damage {
            // Confirmed by what follows, and well formed: no findings in its decode.
            let confirmed = |(l, is_request): (usize, bool)| {
                (self.ends_at(g + l) || self.glitch_then_end(g + l) || (flushing && g + l == live.len()))
                    && consistent(&s[1..l - 2], is_request)
                    && clean(l, is_request)
            };
            let found_any = found.iter().any(Option::is_some);
            for slot in &mut found {
                if slot.is_some_and(|r| !confirmed(r)) {
                    *slot = None;
                }
            }
            return match found {
                [Some((a, _)), Some((b, _))] if a == b => Try::Found(a, Reading::Either, None),
                [Some(a), Some(b)] => {
                    let (l, r) = self.best(g, a, b);
                    Try::Found(l, reading_of(r), None)
                }
                [Some((l, r)), None] | [None, Some((l, r))] => Try::Found(l, reading_of(r), None),
                // Not yet confirmed: wait for what follows, unless nothing more can come.
                [None, None] if !flushing && (need_more || found_any) => Try::NeedMore(s.len() + 1),
                [None, None] => Try::NotHere,
            };
        }
        match found {
            // A valid reading need not wait for another reading that could only be malformed
            // (a 0x10 response read as a request: its byte count disagrees with its quantity),
            // nor for one the bus does not expect now.
            [Some((l, r)), None] | [None, Some((l, r))]
                if !need_more || flushing || !wait_worth || self.expected(g, l, reading_of(r)) =>
            {
                return Try::Found(l, reading_of(r), None);
            }
            // Echo shapes (05, 06, 08, 15, 16) read the same length both ways: one frame.
            [Some(a), Some(b)] if a.0 == b.0 => return Try::Found(a.0, Reading::Either, None),
            [Some(a), Some(b)] => {
                let (l, r) = self.best(g, a, b);
                return Try::Found(l, reading_of(r), None);
            }
            [Some(_), None] | [None, Some(_)] => return Try::NeedMore(need),
            [None, None] => {}
        }
        if unknown && fc & EXCEPTION_FLAG == 0 {
            match self.unknown_length_at(g, flushing) {
                Try::NeedMore(n) => {
                    need_more = true;
                    need = need.min(n);
                }
                t @ Try::Found(..) => return t,
                Try::NotHere => {}
            }
        }
        if need_more && !flushing { Try::NeedMore(need.max(s.len() + 1)) } else { Try::NotHere }
    }

    /// Two readings with valid CRCs (the CRC shift property makes a valid frame followed by
    /// 0x00 validate one byte longer too): prefer the one the bus expects, then the one that
    /// fits its function's structure without findings, then the one the next bytes confirm (a
    /// silence, a valid frame, or a lone glitch byte before either), then the shorter.
    fn best(&self, g: usize, a: (usize, bool), b: (usize, bool)) -> (usize, bool) {
        let score = |(l, is_request): (usize, bool)| {
            let confirmed = self.ends_at(g + l) || self.glitch_then_end(g + l);
            let s = &self.buf[self.head + g..self.head + g + l];
            let clean = decodes_clean(&s[1..l - 2], is_request);
            (self.expected(g, l, Reading::of(is_request)), clean, confirmed, std::cmp::Reverse(l))
        };
        if score(b) > score(a) { b } else { a }
    }

    /// Who sends the frame starting at live index `g`, as far as the expectation says.
    fn sender_at(&self, g: usize) -> Sender {
        sender_of(self.expect_at(g), &self.buf[self.head + g..], None)
    }

    /// Does a frame end before live index `i`: a known silence or a valid frame starts there?
    fn ends_at(&self, i: usize) -> bool {
        self.boundary_at(i) || self.exact_frame_at(i)
    }

    /// On a line that glitches, is the byte at live index `i` one of its glitch values, with a
    /// frame of a known unit (not a broadcast, which a glitch `00` would fake) starting after it?
    fn glitch_then_start(&self, i: usize) -> bool {
        let live = &self.buf[self.head..];
        self.glitchy()
            && live.get(i).is_some_and(|&v| self.glitch_value(v))
            && live.get(i + 1).is_some_and(|&a| a != 0)
            && self.looks_like_frame_start(i + 1)
    }

    /// Is the byte at live index `i` a lone byte — a frame's turnaround glitch — with a known
    /// silence, a valid frame or the end of what has arrived right after it? (Not known to be
    /// separated from the frame by 1.5 characters of silence.)
    fn glitch_then_end(&self, i: usize) -> bool {
        i < self.buf.len() - self.head
            && self.gap_lb[self.head + i] < self.t15
            && (self.boundary_at(i + 1) || self.exact_frame_at(i + 1))
    }

    /// The structure cannot say where this frame ends: accept a CRC match only where something
    /// confirms an end — a known silence, the end of input, or a valid frame after it. Public
    /// and user-defined codes may pause inside a frame (slow slaves), so for them only a
    /// silence longer than the incomplete-frame timeout bounds the search.
    fn unknown_length_at(&self, g: usize, flushing: bool) -> Try {
        let live_len = self.buf.len() - self.head;
        let s = &self.buf[self.head + g..];
        let base = FunctionCode::from(s[1]);
        let lenient = (base.name().is_some() || base.is_user_defined()) && self.known_units[usize::from(s[0])];
        // A code with no public layout from an address never seen before is far more likely
        // garbage than a vendor frame; such frames are still reported, with their boundaries,
        // once a silence or a valid frame ends them (`emit_piece`).
        if s[0] > self.max_address
            || !(base.name().is_some() || base.is_user_defined() || self.known_units[usize::from(s[0])])
        {
            return Try::NotHere;
        }
        // After damage (bytes before `g` that are not a lone glitch), a known unit's frame must
        // carry a public or user-defined code too: there a 4-byte "frame" of any code is a CRC
        // matching by chance as often as not.
        let after_glitch = g == 1 && self.at_glitch(self.head);
        if g > 0 && !after_glitch && !(base.name().is_some() || base.is_user_defined()) {
            return Try::NotHere;
        }
        // Broadcasts carry writes only (Modbus over Serial Line v1.02 §2.1), and every write has
        // a fixed layout: address 0 with a length the structure cannot tell is garbage.
        if s[0] == 0 || !sane_header(s, self.pasted) {
            return Try::NotHere;
        }
        let max = s.len().min(RTU_MAX_LEN);
        let mut bounded = false;
        let mut crc = 0;
        let mut first_match = true;
        for l in RTU_MIN_LEN..=max {
            // `crc` covers the body s[..l - 2], one byte more each step.
            crc = if l == RTU_MIN_LEN { crc16(&s[..2]) } else { crc16_update(crc, &s[l - 3..l - 2]) };
            let received = u16::from_le_bytes([s[l - 2], s[l - 1]]);
            if crc == received {
                let at_end = g + l == live_len;
                // The first CRC match is taken when a frame plausibly starts right after it
                // (request and response of the same vendor code follow each other); later
                // matches need stronger evidence, because over hundreds of lengths a chance
                // match becomes likely.
                let next_starts = !at_end && self.looks_like_frame_start(g + l);
                // A lone byte and then a silence or a frame: this frame's turnaround glitch.
                // Only on a line seen to glitch: elsewhere a CRC match with one stray byte after it
                // is a chance match inside damage (1 in 65 536 per length tried) as often as not.
                let glitch_after = self.glitchy()
                    && (self.glitch_then_end(g + l) || (flushing && g + l + 1 == live_len))
                    || self.glitch_then_start(g + l);
                if self.boundary_at(g + l)
                    || (flushing && at_end)
                    || self.exact_frame_at(g + l)
                    || (first_match && next_starts)
                    || glitch_after
                {
                    // CRC shift property: a frame whose CRC high byte is 0x00 also validates
                    // one byte shorter. When the byte after this match is 0x00 and the longer
                    // frame validates too, take the longer unless only the shorter is followed
                    // by something that looks like a frame.
                    if s.get(l) == Some(&0) && l < RTU_MAX_LEN && s.len() > l && Self::crc_ok(&s[..=l]) {
                        // Diagnostics data is N × 2 bytes (MAP v1.1b3 §6.8): its structure
                        // decides where the CRC can.
                        if let Some(even) = diagnostics_even_len(s, l) {
                            return Try::Found(even, Reading::Unknown, None);
                        }
                        // The lengths this unit's function was seen with unambiguously decide.
                        if let Some(len) = self.lengths.choose(s[0], s[1], self.sender_at(g), l) {
                            return Try::Found(len, Reading::Unknown, None);
                        }
                        // What follows the longer frame decides below: wait until its start
                        // (two bytes) has arrived, unless nothing more can come.
                        if !flushing && s.len() < l + 3 && !self.boundary_at(g + l + 1) {
                            return Try::NeedMore(l + 3);
                        }
                        // The longer frame followed by its own glitch byte is the longer frame —
                        // a byte taking a glitch's value: a lone other byte before a silence is
                        // as likely a slow slave pausing after its answer's first byte.
                        let glitch_like =
                            s.get(l + 1).is_some_and(|&v| self.glitch_value(v) || matches!(v, 0x00 | 0xFE | 0xFF));
                        let longer_glitch =
                            (glitch_like && self.glitch_then_end(g + l + 1)) || self.glitch_then_start(g + l + 1);
                        let longer_ok = g + l + 1 == live_len
                            || self.boundary_at(g + l + 1)
                            || self.exact_frame_at(g + l + 1)
                            || self.looks_like_frame_start(g + l + 1)
                            || longer_glitch;
                        let evidence = self.boundary_at(g + l) || self.exact_frame_at(g + l) || longer_glitch;
                        // Nothing else decides: whether this sender's `00` glitch is likelier
                        // than a CRC ending in `00` (1 in 256).
                        let odds = self.turn.zero_tail(self.sender_at(g));
                        let shorter_strong = self.boundary_at(g + l)
                            || self.exact_frame_at(g + l)
                            || (odds.glitch_likelier && !longer_glitch);
                        // A lone `00` between two silences is noise after the frame, or its CRC's
                        // high byte after a slave paused longer than t3.5 inside it: both check.
                        let lone_zero = self.boundary_at(g + l) && self.boundary_at(g + l + 1);
                        let alt =
                            |other: usize| (longer_ok && ((!evidence && odds.ambiguous) || lone_zero)).then_some(other);
                        if longer_ok && !shorter_strong {
                            return Try::Found(l + 1, Reading::Unknown, alt(l));
                        }
                        return Try::Found(l, Reading::Unknown, alt(l + 1));
                    }
                    return Try::Found(l, Reading::Unknown, None);
                }
                first_match = false;
            }
            // A whole valid frame starting inside this one means this one ended before it (or
            // was never a frame): over hundreds of lengths, running past it invites a chance
            // CRC match further on.
            if !lenient && l < s.len() && self.exact_frame_at(g + l) {
                bounded = true;
                break;
            }
            if l < s.len() {
                let gap = self.gap_lb[self.head + g + l];
                // Even a slow slave's frame cannot hold a whole valid frame after a silence.
                if gap >= self.incomplete_timeout || (gap >= self.t35 && (!lenient || self.exact_frame_at(g + l))) {
                    bounded = true;
                    break;
                }
            }
        }
        if !bounded && !flushing && s.len() < RTU_MAX_LEN { Try::NeedMore(s.len() + 1) } else { Try::NotHere }
    }

    fn process<F: FnMut(FrameEvent<'_>)>(&mut self, flush: Flush, emit: &mut F) {
        let flushing = flush == Flush::All;
        loop {
            let live_len = self.buf.len() - self.head;
            if self.garbage >= live_len {
                break;
            }
            if !flushing && self.wait_at == self.garbage && live_len - self.garbage < self.wait_for {
                break;
            }
            match self.try_frame_at(self.garbage, flushing) {
                Try::Found(len, reading, alt) => {
                    self.frame_next_at = Some(self.head + self.garbage);
                    self.emit_garbage(self.garbage, emit);
                    self.frame_next_at = None;
                    self.next_alt = alt;
                    self.emit_frame(len, Some(reading), emit);
                }
                Try::NotHere => {
                    self.garbage += 1;
                    if self.garbage >= MAX_GARBAGE {
                        self.emit_garbage(RTU_MAX_LEN, emit);
                    }
                }
                Try::NeedMore(n) => {
                    self.wait_at = self.garbage;
                    self.wait_for = n;
                    break;
                }
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
            self.glitch_at = self.glitch_at.and_then(|g| g.checked_sub(self.head));
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
            // A slow slave pauses inside its frame: when the structure says the frame goes on
            // past this silence, and it ends at a silence or at the end of the garbage, follow it.
            if let Some(l) = self.structural_len(a, stop)
                && a + l > b
                && (a + l == stop || self.gap_lb[a + l] >= self.t35)
                && self.gap_lb[a + 1..a + l].iter().all(|&g| g < self.incomplete_timeout)
            {
                b = a + l;
            }
            self.emit_piece(a, b, emit);
            a = b;
        }
        self.garbage = self.garbage.saturating_sub(n);
    }

    /// The exact length the structure gives a frame starting at absolute `a`, if it fits
    /// before `stop`.
    fn structural_len(&self, a: usize, stop: usize) -> Option<usize> {
        let f = &self.buf[a..stop];
        if !self.looks_like_frame(f) {
            return None;
        }
        let pdu = &f[1..];
        let req = if f[1] & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        [response_len(pdu), req].into_iter().find_map(|c| match c {
            PduLength::Exact(k) if k + 3 <= f.len() => Some(k + 3),
            _ => None,
        })
    }

    /// A failed-check piece is reported as a frame when it could be one: 4 to 256 bytes
    /// starting with a unicast or broadcast address and either a public, user-defined or
    /// exception function code, or an address already seen in valid frames.
    fn looks_like_frame(&self, piece: &[u8]) -> bool {
        let [addr, fc, ..] = *piece else { return false };
        let base = FunctionCode::from(fc & !EXCEPTION_FLAG);
        (RTU_MIN_LEN..=RTU_MAX_LEN).contains(&piece.len())
            && addr <= self.max_address
            && ((fc != 0 && (base.name().is_some() || base.is_user_defined())) || self.known_units[usize::from(addr)])
    }

    /// Do the two bytes at live index `i` look like the start of a frame: an address already
    /// seen in valid frames and a public, user-defined or exception function code?
    fn looks_like_frame_start(&self, i: usize) -> bool {
        let (Some(&addr), Some(&fc)) = (self.buf.get(self.head + i), self.buf.get(self.head + i + 1)) else {
            return false;
        };
        let base = FunctionCode::from(fc & !EXCEPTION_FLAG);
        if addr == 0 {
            // Broadcasts carry writes only (Modbus over Serial Line v1.02 §2.1).
            return self.known_units[0] && matches!(fc, 0x05 | 0x06 | 0x0F | 0x10 | 0x15 | 0x16);
        }
        self.known_units[usize::from(addr)] && fc != 0 && (base.name().is_some() || base.is_user_defined())
    }

    /// A whole frame: it looks like one, its CRC holds, and its length is one its structure allows.
    fn plausible_frame(&self, f: &[u8]) -> bool {
        // A code with no public layout that is not a user-defined one either (MAP v1.1b3 §5):
        // from garbage, a chance CRC match is likelier than such a frame.
        let base = FunctionCode::from(f.get(1).map_or(0, |fc| fc & !EXCEPTION_FLAG));
        if !self.looks_like_frame(f)
            || !sane_header(f, self.pasted)
            || !(base.name().is_some() || base.is_user_defined())
            || !Self::crc_ok(f)
        {
            return false;
        }
        let pdu = &f[1..];
        let fits = |c: PduLength| match c {
            PduLength::Exact(k) => k + 3 == f.len(),
            PduLength::AtLeast(_) => false,
            PduLength::Unknown => true,
        };
        fits(response_len(pdu)) || (f[1] & EXCEPTION_FLAG == 0 && fits(request_len(pdu)))
    }

    /// Emits bytes `a..b` (absolute, `a == self.head`) that no silence divides. A frame whose
    /// end the structure could not confirm in time (a user-defined code followed by another)
    /// lands here whole, with a valid CRC; a valid frame glued to a corrupted one or to noise
    /// is split off when its CRC and structure agree. The rest is a failed frame or noise.
    fn emit_piece<F: FnMut(FrameEvent<'_>)>(&mut self, mut a: usize, b: usize, emit: &mut F) {
        while a < b {
            let piece = &self.buf[a..b];
            // A frame of a length the structure cannot tell with its `00` glitch also passes the
            // CRC (the shift property): Diagnostics' structure decides, else the odds on this line.
            if piece.len() > RTU_MIN_LEN && piece.last() == Some(&0) && self.plausible_frame(&piece[..piece.len() - 1])
            {
                let n = piece.len();
                if self.twin_len(a, n, self.sender_at(a - self.head)) < n {
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
            if let Some(e) = (RTU_MIN_LEN..piece.len()).find(|&e| {
                self.known_units[usize::from(piece[0])]
                    && self.plausible_frame(&piece[..e])
                    && self.looks_like_frame(&piece[e..])
            }) {
                // The shift property again: when the frame checks one byte longer too (its next
                // byte a `00`) and a frame starts after that byte as well, the odds on this line
                // decide whether the `00` is a glitch or the CRC's high byte.
                let twin = piece.get(e) == Some(&0)
                    && e + 1 < piece.len()
                    && self.plausible_frame(&piece[..=e])
                    && self.looks_like_frame(&piece[e + 1..]);
                let e = if twin { self.twin_len(a, e + 1, self.sender_at(a - self.head)) } else { e };
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

    /// The `n` bytes at absolute `at` end in `00` and check one byte shorter too (CRC-16's shift
    /// property): the length to take — Diagnostics' structure decides where it can, else the
    /// odds that `sender` leaves a `00` glitch — with the other length kept for the frame event
    /// (see [`Frame::alt_len`]) when it is not negligible.
    fn twin_len(&mut self, at: usize, n: usize, sender: Sender) -> usize {
        if let Some(even) = diagnostics_even_len(&self.buf[at..], n - 1) {
            self.next_alt = None;
            return even;
        }
        if let Some(len) = self.lengths.choose(self.buf[at], self.buf[at + 1], sender, n - 1) {
            self.next_alt = None;
            return len;
        }
        let odds = self.turn.zero_tail(sender);
        let (take, other) = if odds.glitch_likelier { (n - 1, n) } else { (n, n - 1) };
        self.next_alt = odds.ambiguous.then_some(other);
        take
    }

    /// Where a damaged frame at absolute `a` ends inside `a..b`, if its structure says so and a
    /// frame of a known unit plausibly starts there.
    fn split_damaged(&self, a: usize, b: usize) -> Option<usize> {
        // With timing that can show a t3.5 silence, frames were already cut at their silences;
        // a damaged byte count would only mislead. This is for adapters whose latency hides them.
        if self.latency < self.t35 {
            return None;
        }
        let piece = &self.buf[a..b];
        if !self.looks_like_frame(piece) {
            return None;
        }
        let pdu = &piece[1..];
        let req = if piece[1] & EXCEPTION_FLAG == 0 { request_len(pdu) } else { PduLength::Unknown };
        let mut cands: Vec<usize> = [req, response_len(pdu)]
            .into_iter()
            .filter_map(|c| match c {
                PduLength::Exact(k) if k + 3 >= RTU_MIN_LEN && k + 3 + 2 <= piece.len() => Some(k + 3),
                _ => None,
            })
            .collect();
        // The expected reading first (a request after a completed transaction), then the shorter.
        let expected_request = self.expect == Expect::Request && a == self.head;
        let req_len = match req {
            PduLength::Exact(k) => Some(k + 3),
            _ => None,
        };
        cands.sort_unstable_by_key(|&l| (!(expected_request && Some(l) == req_len), l));
        // Only when the rest starts like a frame of a known unit: a short rest is as likely the
        // tail of this frame read with the wrong reading (a request's response reading is 5
        // bytes) as noise that followed it.
        cands.into_iter().find(|&l| self.looks_like_frame_start(a - self.head + l))
    }

    /// Bytes `a..b` that hold no valid frame: a failed frame if they look like one, else noise;
    /// a lone byte right after a frame is its turnaround glitch.
    fn emit_unframed<F: FnMut(FrameEvent<'_>)>(&mut self, a: usize, b: usize, emit: &mut F) {
        // Glued to what follows (no silence seen between them), the glitch is split off when it
        // cannot start a frame, takes a value this line's glitches take, or the bytes start like
        // a frame of a known unit only after it.
        let i = a - self.head;
        let v = self.buf[a];
        // A lone byte glued to the start of a frame, after a silence: the glitch of the driver
        // switching on (seen as a `00` before answers on real lines).
        if b - a == 1
            && self.frame_next_at == Some(b)
            && self.gap_lb[b] < self.t15
            && self.gap_lb[a] >= self.t35
            && (matches!(v, 0x00 | 0xFE | 0xFF) || self.glitch_value(v))
            && !self.at_glitch(a)
        {
            // The silence before the glitch is the silence before the frame.
            self.gap_lb[b] = self.gap_lb[a];
            self.gap_ub[b] = self.gap_ub[a];
            self.emit_glitch(a, emit);
            return;
        }
        if self.at_glitch(a)
            && (b - a == 1
                // A reserved address starts no frame (Serial Line v1.02 §2.2); before this line
                // is known to glitch, only the values drivers leave (`FE`, `FF`) count.
                || (v > MAX_ADDRESS && (self.glitchy() || v >= 0xFE))
                || (self.glitchy() && self.glitch_value_after(self.last_sender, v))
                || ((self.glitchy() || matches!(v, 0x00 | 0xFE | 0xFF))
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
            && self.glitchy()
            && self.glitch_value_after(self.sender_at(a - self.head), self.buf[b - 1])
            && !self.expected_len_at(a, b - a)
        {
            self.emit_frame(b - a - 1, None, emit);
            self.emit_unframed(b - 1, b, emit);
            return;
        }
        // The awaited answer, damaged, with more after it: the request fixed its length
        // (an exception's is 5), whatever its damaged byte count says.
        if let Expect::Response { unit, fc, len: Some(n) } = self.expect
            && self.buf[a] == unit
        {
            let n = if self.buf.get(a + 1) == Some(&(fc | EXCEPTION_FLAG)) { 5 } else { n };
            if b - a > n && self.latency >= self.t35 {
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
        if self.looks_like_frame(&self.buf[a..b]) {
            self.emit_frame(b - a, None, emit);
        } else {
            emit(FrameEvent::Noise(Noise {
                port: self.port,
                bytes: &self.buf[a..b],
                t_start: Timestamp(self.end[a].saturating_sub(self.char_ns)),
                t_end: Timestamp(self.end[b - 1]),
            }));
            self.head = b;
            self.wait_at = usize::MAX;
            self.after_frame = false;
            self.after_damage = true;
        }
    }

    /// Emits the first `len` live bytes as a frame: valid, read as `reading`, or failed (`None`).
    fn emit_frame<F: FnMut(FrameEvent<'_>)>(&mut self, len: usize, reading: Option<Reading>, emit: &mut F) {
        let check_ok = reading.is_some();
        let a = self.head;
        let b = a + len;
        let inner_gap = self.gap_lb[a + 1..b].iter().copied().max().unwrap_or(0);
        let ub = self.gap_ub[a];
        let short_gap_before_ns = (self.after_frame && ub < self.t35).then_some(ub);
        let apparent_before = (ub != u64::MAX).then(|| ub.saturating_sub(self.latency));
        let (every_silence, evidence_silence) = self.apparent_inner_silence(a, b);
        let gap_tolerance_ns = evidence_silence.and_then(|s| s.checked_sub(self.t15));
        emit(FrameEvent::Frame(Frame {
            port: self.port,
            bytes: &self.buf[a..b],
            t_start: Timestamp(self.end[a].saturating_sub(self.char_ns)),
            t_end: Timestamp(self.end[b - 1]),
            check_ok,
            gap_violation_ns: (inner_gap >= self.t15).then_some(inner_gap),
            short_gap_before_ns,
            gap_tolerance_ns,
            short_gap_tolerance_ns: self.short_tolerance(apparent_before),
            resolution_ns: self.learner.estimate.resolution_ns(),
            gap_before_known: ub != u64::MAX,
            bad_chars: false,
            alt_len: self.next_alt.take().filter(|_| check_ok),
        }));
        self.last_sender = sender_of(self.expect, &self.buf[a..b], reading);
        self.after_damage = !check_ok;
        if check_ok {
            self.lengths.record(&self.buf[a..b], self.buf.get(b).copied(), self.last_sender);
            self.known_units[usize::from(self.buf[a])] = true;
            self.turn.frame(self.last_sender);
            self.learn_from(a, every_silence);
        }
        self.expect = next_expect(self.expect, &self.buf[a..b], reading);
        self.since_glitch = self.since_glitch.saturating_add(1);
        self.glitch_at = Some(b);
        self.head = b;
        self.wait_at = usize::MAX;
        self.after_frame = true;
    }

    /// A valid frame at absolute `a`, `delay` the longest apparent silence between two of its
    /// reads (`None`: it came in one): its bytes were sent back to back, so that silence is the
    /// observer's delay.
    fn learn_from(&mut self, a: usize, delay: Option<u64>) {
        self.learner.frame();
        let sender = match self.last_sender {
            Sender::Master => SampleSender::Master,
            Sender::Slave | Sender::Unknown => SampleSender::Unit(self.buf[a]),
        };
        if let Some(d) = delay
            && self.learner.sample(sender, d).is_some()
        {
            self.latency = self.learner.estimate.effective_latency_ns();
        }
    }

    /// The longest apparent silence between two reads inside absolute `a..b`, taken at face
    /// value (no latency allowed for); `None` when the bytes came in one read.
    ///
    /// A read's bytes are placed back to back before its timestamp; where the frame's last read
    /// also holds bytes of the next frame, the silence between the two frames is hidden inside
    /// that read and its first bytes look later than they were — by up to that silence. That
    /// read's boundary says nothing about the observer or the sender and is left out (issue 25:
    /// through a 16550 FIFO, which holds the tail of one frame with the head of the next, it
    /// made healthy frames look paused). For learning the observer's delay it is kept (the
    /// first of the pair returned): that errs high, towards fewer findings, and a glitchy
    /// line's frames always share their last read with their glitch. One pass over the frame
    /// gives both: `(every boundary, the boundaries the gap evidence may use)`.
    fn apparent_inner_silence(&self, a: usize, b: usize) -> (Option<u64>, Option<u64>) {
        let c = self.char_ns;
        // A read began at `i` where the gap before it is bounded (inside a read it is unknown
        // and set to `u64::MAX`).
        let starts_read = |i: usize| self.gap_ub.get(i).is_some_and(|&g| g != u64::MAX);
        let (mut before_last, mut last) = (None::<u64>, None::<u64>);
        for i in (a + 1..b).filter(|&i| starts_read(i)) {
            before_last = before_last.max(last);
            last = Some(self.end[i].saturating_sub(c).saturating_sub(self.end[i - 1]));
        }
        let every = before_last.max(last);
        let last_read_spills = b < self.buf.len() && !starts_read(b);
        (every, if last_read_spills { before_last } else { every })
    }

    /// How far an apparent silence before a frame fell short of t3.5 after the previous frame.
    fn short_tolerance(&self, apparent_before: Option<u64>) -> Option<u64> {
        apparent_before.filter(|_| self.after_frame).and_then(|g| self.t35.checked_sub(g)).filter(|&t| t > 0)
    }

    /// Emits the live byte at absolute `a` (`== self.head`) as a turnaround glitch.
    fn emit_glitch<F: FnMut(FrameEvent<'_>)>(&mut self, a: usize, emit: &mut F) {
        emit(FrameEvent::Glitch(Noise {
            port: self.port,
            bytes: &self.buf[a..=a],
            t_start: Timestamp(self.end[a].saturating_sub(self.char_ns)),
            t_end: Timestamp(self.end[a]),
        }));
        self.since_glitch = 0;
        if self.glitch_at == Some(a) {
            self.turn.glitch(self.last_sender, self.buf[a]);
        }
        let n = &mut self.glitch_counts[usize::from(self.buf[a])];
        *n = n.saturating_add(1);
        self.glitch_top = self.glitch_top.max(*n);
        self.glitch_at = None;
        self.head = a + 1;
        self.wait_at = usize::MAX;
    }

    /// Is the live byte at absolute `a` where a turnaround glitch would be: right after a
    /// frame, not known to be separated from it by 1.5 characters of silence?
    fn at_glitch(&self, a: usize) -> bool {
        self.glitch_at == Some(a) && self.gap_lb.get(a).is_some_and(|&g| g < self.t15)
    }
}

/// Could the PDU, read in this direction, be well formed? Only the byte-count fields that a
/// quantity fixes are checked (MAP v1.1b3 §6): enough to rule out the wrong reading of most
/// frames without waiting for bytes that would only make a malformed frame.
fn consistent(pdu: &[u8], is_request: bool) -> bool {
    let u16_at = |i: usize| pdu.get(i..i + 2).map(|b| usize::from(u16::from_be_bytes([b[0], b[1]])));
    let byte = |i: usize| pdu.get(i).map(|&b| usize::from(b));
    let Some(&fc) = pdu.first() else { return true };
    if is_request {
        match fc {
            0x0F => u16_at(3).zip(byte(5)).is_none_or(|(q, bc)| bc == q.div_ceil(8)),
            0x10 => u16_at(3).zip(byte(5)).is_none_or(|(q, bc)| bc == 2 * q),
            0x17 => u16_at(7).zip(byte(9)).is_none_or(|(q, bc)| bc == 2 * q),
            _ => true,
        }
    } else {
        match fc {
            0x01 | 0x02 => byte(1).is_none_or(|bc| bc >= 1),
            0x03 | 0x04 | 0x17 => byte(1).is_none_or(|bc| bc >= 2 && bc % 2 == 0),
            0x0C => byte(1).is_none_or(|bc| bc >= 6),
            _ => true,
        }
    }
}

/// For a Diagnostics frame `s` (function 08, not an exception) that checks both `l` and `l + 1`
/// bytes long: the length whose data after the sub-function is N × 2 bytes (MAP v1.1b3 §6.8).
fn diagnostics_even_len(s: &[u8], l: usize) -> Option<usize> {
    // unit, function, sub-function (2), data, CRC (2)
    let data = l.checked_sub(6)?;
    (s.get(1) == Some(&0x08)).then_some(if data % 2 == 0 { l } else { l + 1 })
}

/// Who sent frame `f`, read as `reading` (valid) or failed (`None`), given what was expected.
fn sender_of(expect: Expect, f: &[u8], reading: Option<Reading>) -> Sender {
    match (reading, expect, f) {
        (Some(Reading::Request), ..) | (Some(Reading::Either | Reading::Unknown) | None, Expect::Request, _) => {
            Sender::Master
        }
        (Some(Reading::Response), ..) => Sender::Slave,
        (_, Expect::Response { unit, fc, .. }, [u, f, ..]) if *u == unit && (*f == fc || *f == fc | EXCEPTION_FLAG) => {
            Sender::Slave
        }
        _ => Sender::Unknown,
    }
}

/// The expectation after a frame `f` read as `reading` (valid) or failed (`None`), given what
/// was expected before it.
fn next_expect(expect: Expect, f: &[u8], reading: Option<Reading>) -> Expect {
    let as_request = |f: &[u8]| {
        let [unit, fc, ..] = *f else { return Expect::Unknown };
        if unit == 0 {
            // Broadcasts are not answered (Serial Line v1.02 §2.1).
            return Expect::Request;
        }
        let pdu = &f[1..f.len().saturating_sub(2).max(1)];
        let len = match crate::proto::answer_len(pdu) {
            PduLength::Exact(k) => k.checked_add(3),
            _ => None,
        };
        Expect::Response { unit, fc, len }
    };
    let answers_pending = |e: Expect| match (e, f) {
        (Expect::Response { unit, fc, .. }, [u, f, ..]) => *u == unit && (*f == fc || *f == fc | EXCEPTION_FLAG),
        _ => false,
    };
    match reading {
        // A failed frame ends the transaction it answered; otherwise nobody can say.
        None if matches!(expect, Expect::Response { .. }) => Expect::Request,
        Some(Reading::Request) => as_request(f),
        Some(Reading::Response) => Expect::Request,
        Some(Reading::Either | Reading::Unknown) if answers_pending(expect) => Expect::Request,
        Some(Reading::Either | Reading::Unknown) if expect == Expect::Request => as_request(f),
        None | Some(_) => Expect::Unknown,
    }
}

/// Could a frame start with these bytes at all? Function code 0 does not exist (MAP v1.1b3
/// §5: codes 1–127), nor its exception 0x80; a broadcast (address 0) carries a write only
/// (Serial Line v1.02 §2.1); an exception carries a code from 01 (MAP v1.1b3 §7). A CRC that
/// matches by chance over damage (1 in 65 536) is taken only where the header is possible.
fn sane_header(f: &[u8], pasted: bool) -> bool {
    match *f {
        // Function 0 does not exist (MAP v1.1b3 §5.1); its exception `80` is kept only in pasted
        // text, where a slave answering for an absent one has been seen to send it.
        [_, 0x80, ..] if pasted => true,
        [_, fc, ..] if fc & !EXCEPTION_FLAG == 0 => false,
        // Exception codes start at 01 (MAP v1.1b3 §7): an "exception 00" is a chance match.
        [_, fc, 0, ..] if fc & EXCEPTION_FLAG != 0 => false,
        [0, fc, ..] => matches!(fc, 0x05 | 0x06 | 0x0F | 0x10 | 0x15 | 0x16),
        _ => true,
    }
}
