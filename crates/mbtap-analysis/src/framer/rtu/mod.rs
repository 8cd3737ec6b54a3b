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
//!
//! Modules: `state` (the framer's state), `buffer` (the timed buffer of undecided bytes),
//! `candidates` (the frames a position allows), `emit` (what goes out), `twins` and `hold` (CRC
//! twins: which length, and holding them until the line tells), `unknown_length` (frames their
//! structure does not fix), `learning` (what each valid frame teaches).

mod buffer;
mod candidates;
mod emit;
mod expect;
mod glitches;
mod hold;
mod learning;
mod state;
mod twins;
mod unknown_length;

use self::buffer::TimedBuffer;
use self::candidates::Try;
use self::expect::{Expect, MAX_ADDRESS, Reading};
use self::glitches::GlitchState;
use self::hold::TwinHold;
pub use self::hold::{HOLD_NS, MAX_HELD_BYTES};
use self::state::{LastEmitted, LineTiming, Search};
use crate::chunk::{Chunk, PortId, Timestamp};
use crate::framer::LineSettings;
use crate::framer::event::FrameEvent;
use crate::framer::lengths::LearnedLengths;
use crate::framer::observer::{ObserverEstimate, ObserverLearner};
use mbtap_proto::rtu::{RTU_MAX_LEN, RTU_MIN_LEN};

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
    /// How long (bus time, ns) a frame that checks at two lengths nothing decides yet is held,
    /// with what follows it, for the line to teach its length (see [`hold`]; default
    /// [`HOLD_NS`]); 0: never held, frames go out as they come.
    pub hold_twins_ns: u64,
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
            hold_twins_ns: HOLD_NS,
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

/// How many bytes a candidate frame start may wait behind it for what decides it (a silence, a
/// confirming frame, the end of a vendor frame). No RTU frame is longer than [`RTU_MAX_LEN`]
/// (Serial Line v1.02 §2.5.1), so a candidate with this many bytes after it and still undecided
/// is not a frame: on a line that never falls silent (a babbling device, a wrong baud rate) the
/// bytes are decided by structure and the rest counted as noise, and what is held stays bounded
/// (it grew by ~25 bytes of memory per byte heard).
const MAX_WAIT: usize = 4 * RTU_MAX_LEN;

/// The most bytes the framer holds undecided after any push or tick: the garbage before a
/// candidate and what the candidate waits for.
pub const MAX_PENDING: usize = MAX_GARBAGE + MAX_WAIT;

/// The RTU framer for one port.
#[derive(Debug)]
pub struct RtuFramer {
    port: PortId,
    /// The highest address a frame may start with: 247, or 255 for pasted frames.
    max_address: u8,
    /// Pasted frames (see [`FramerConfig::pasted`]).
    pasted: bool,
    timing: LineTiming,
    /// The bytes not yet decided, with what their timing proves.
    timed: TimedBuffer,
    search: Search,
    last: LastEmitted,
    /// Addresses seen in frames with a valid CRC: a failed piece that starts with one is a
    /// corrupted frame even when the corruption hit its function code.
    known_units: [bool; 256],
    /// What the next frame should be.
    expect: Expect,
    /// What the line's turnaround glitches have shown.
    glitches: GlitchState,
    /// What the valid frames show of this observer's reads.
    learner: ObserverLearner,
    /// Lengths each unit's vendor functions were seen with.
    lengths: LearnedLengths,
    /// Undecided twins held until the line tells their length.
    hold: TwinHold,
}

impl RtuFramer {
    #[must_use]
    pub fn new(port: PortId, config: FramerConfig) -> Self {
        Self {
            port,
            timing: LineTiming::new(&config),
            timed: TimedBuffer::new(),
            search: Search::new(),
            last: LastEmitted::new(),
            known_units: [false; 256],
            expect: Expect::Unknown,
            glitches: GlitchState::new(),
            learner: ObserverLearner::new(config.latency_ns, config.learn_latency, config.line.char_ns()),
            lengths: LearnedLengths::new(config.learn_lengths),
            hold: TwinHold::new(config.hold_twins_ns),
            max_address: if config.pasted { u8::MAX } else { MAX_ADDRESS },
            pasted: config.pasted,
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

    /// A vendor function's frame length a device profile declares (see
    /// [`crate::framer::lengths`]): `unit`'s function `fc`, its requests (`request`) or answers.
    pub fn declare_length(&mut self, unit: u8, fc: u8, request: bool, len: u16) {
        self.lengths.declare(unit, fc, request, len);
    }

    /// Bytes waiting for a decision.
    #[must_use]
    pub fn pending(&self) -> usize {
        self.timed.live_len()
    }

    /// Bytes of decided events held behind an undecided twin (see [`hold`]).
    #[must_use]
    pub fn held(&self) -> usize {
        self.hold.held()
    }

    /// When the first event held behind an undecided twin began (see [`hold`]): whoever times
    /// out what waits for a frame must not judge past it — the frame may be in the hold.
    #[must_use]
    pub fn held_since(&self) -> Option<Timestamp> {
        self.hold.since()
    }

    /// Feeds one chunk; emits every event it decides (in order; behind an undecided twin, when
    /// the line tells its length or the hold's bound passes).
    pub fn push<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, emit: &mut F) {
        // What the bound lets out goes first, as a tick before this chunk would have (live
        // and replayed input give the same events).
        self.hold.settle(&self.lengths, Some(chunk.t.0), self.timing.char_ns, emit);
        self.push_events(chunk, emit);
        self.hold.settle(&self.lengths, Some(chunk.t.0), self.timing.char_ns, emit);
    }

    /// Feeds a chunk known to be exactly one frame; see [`Self::push_events_whole`].
    pub fn push_whole<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, emit: &mut F) {
        self.hold.settle(&self.lengths, Some(chunk.t.0), self.timing.char_ns, emit);
        self.push_events_whole(chunk, emit);
        self.hold.settle(&self.lengths, Some(chunk.t.0), self.timing.char_ns, emit);
    }

    /// Tells the framer the time is `now` with nothing new received; see [`Self::tick_events`].
    pub fn tick<F: FnMut(FrameEvent<'_>)>(&mut self, now: Timestamp, emit: &mut F) {
        self.tick_events(now, emit);
        self.hold.settle(&self.lengths, Some(now.0), self.timing.char_ns, emit);
    }

    /// End of input: decides everything pending, and lets out everything held.
    pub fn finish<F: FnMut(FrameEvent<'_>)>(&mut self, emit: &mut F) {
        self.process(Flush::All, emit);
        self.hold.settle(&self.lengths, None, self.timing.char_ns, emit);
    }

    // Kept out of line: with the hold's two checks around it inlined into one function, a
    // per-frame replay measured 0.6 % slower in wall time (0.2557 s against 0.2541 s).
    #[inline(never)]
    fn push_events<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, emit: &mut F) {
        let t = chunk.t.0;
        // What the silence before this chunk decides is decided first, exactly as a `tick` in
        // that silence would have: live and replayed input give the same events.
        if let Some(first_end) = self.first_end_estimate(chunk) {
            self.tick_events(Timestamp(first_end.saturating_sub(self.timing.char_ns)), emit);
        }
        let n = chunk.bytes.len();
        if n > 0 {
            self.learner.read(n);
        }
        let c = self.timing.char_ns;
        if self.pending() == 0
            && let Some(reading) = Self::whole_frame(chunk.bytes)
        {
            self.emit_whole_chunk(chunk, reading, emit);
            return;
        }
        self.timed.append(chunk.bytes, t, c, self.timing.latency);
        self.process(Flush::No, emit);
    }

    /// Feeds a chunk known to be exactly one frame — bytes this program wrote itself (the
    /// bridge's requests and answers, for `--monitor`): what was buffered on this port is
    /// complete before it, and it goes out whole at once, whatever its function code (a vendor
    /// frame need not wait for the silence after it). A chunk that fails its CRC takes the
    /// general path.
    fn push_events_whole<F: FnMut(FrameEvent<'_>)>(&mut self, chunk: &Chunk<'_>, emit: &mut F) {
        if chunk.bytes.len() < RTU_MIN_LEN || !Self::crc_ok(chunk.bytes) {
            self.push_events(chunk, emit);
            return;
        }
        if self.pending() > 0 {
            self.process(Flush::All, emit);
        }
        let reading = Self::whole_frame(chunk.bytes).unwrap_or(Reading::Unknown);
        self.emit_whole_chunk(chunk, reading, emit);
    }

    fn first_end_estimate(&self, chunk: &Chunk<'_>) -> Option<u64> {
        let n = u64::try_from(chunk.bytes.len()).ok()?;
        if n == 0 {
            return None;
        }
        Some(chunk.t.0.saturating_sub((n - 1) * self.timing.char_ns))
    }

    /// Tells the framer the time is `now` with nothing new received: if the line has been
    /// silent longer than t3.5 (plus latency), pending bytes are decided.
    fn tick_events<F: FnMut(FrameEvent<'_>)>(&mut self, now: Timestamp, emit: &mut F) {
        let Some(last) = self.timed.last_end else { return };
        if self.pending() == 0 {
            return;
        }
        let silence = now.0.saturating_sub(last).saturating_sub(self.timing.latency);
        if silence >= self.timing.incomplete_timeout {
            self.search.silent_after = true;
            self.process(Flush::All, emit);
            self.search.silent_after = false;
        } else if silence >= self.timing.t35 && self.search.garbage > 0 {
            self.process(Flush::Garbage, emit);
        }
    }

    fn process<F: FnMut(FrameEvent<'_>)>(&mut self, flush: Flush, emit: &mut F) {
        let flushing = flush == Flush::All;
        loop {
            let live_len = self.timed.live_len();
            if self.search.garbage >= live_len {
                break;
            }
            if !flushing
                && self.search.wait_at == self.search.garbage
                && live_len - self.search.garbage < self.search.wait_for
            {
                break;
            }
            let decided = match self.try_frame_at(self.search.garbage, flushing) {
                Try::NeedMore(_) if live_len - self.search.garbage > MAX_WAIT => Try::NotHere,
                t => t,
            };
            match decided {
                Try::Found(len, reading, alt) => {
                    self.last.frame_next_at = Some(self.timed.head + self.search.garbage);
                    self.emit_garbage(self.search.garbage, emit);
                    self.last.frame_next_at = None;
                    self.last.next_alt = alt;
                    self.emit_frame(len, Some(reading), emit);
                }
                Try::NotHere => {
                    self.search.garbage += 1;
                    if self.search.garbage >= MAX_GARBAGE {
                        self.emit_garbage(RTU_MAX_LEN, emit);
                    }
                }
                Try::NeedMore(n) => {
                    self.search.wait_at = self.search.garbage;
                    self.search.wait_for = n;
                    break;
                }
            }
        }
        match flush {
            Flush::All => {
                let g = self.search.garbage;
                self.emit_garbage(g, emit);
            }
            // Only whole pieces: garbage that ends at a known silence. The bytes after the
            // last such silence may still continue into the next undecided byte.
            Flush::Garbage => {
                if let Some(b) = (1..=self.search.garbage).rev().find(|&b| self.boundary_at(b)) {
                    self.emit_garbage(b, emit);
                }
            }
            Flush::No => {}
        }
        self.compact();
    }

    fn compact(&mut self) {
        if let Some(dropped) = self.timed.compact() {
            self.last.glitch_at = self.last.glitch_at.and_then(|g| g.checked_sub(dropped));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random bytes with no silence the framer can know (64 KiB reads 1 ms apart, a 16 ms adapter
    /// latency) stay bounded in what is held (holding every byte would cost ~25 bytes of memory per
    /// byte), and every byte still comes out exactly once.
    #[test]
    fn a_line_that_never_falls_silent_is_held_bounded() {
        let mut framer = RtuFramer::new(PortId(0), FramerConfig::new(LineSettings::default(), 16_000_000));
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let (mut fed, mut out, mut most) = (0usize, 0usize, 0usize);
        for i in 0..32u64 {
            let bytes: Vec<u8> = (0..65_536)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    x.to_le_bytes()[0]
                })
                .collect();
            fed += bytes.len();
            let chunk = Chunk { port: PortId(0), t: Timestamp((i + 1) * 1_000_000), bytes: &bytes };
            framer.push(&chunk, &mut |e: FrameEvent<'_>| out += e.bytes().len());
            most = most.max(framer.pending());
        }
        assert!(most <= MAX_PENDING, "held {most} bytes undecided");
        framer.finish(&mut |e: FrameEvent<'_>| out += e.bytes().len());
        assert_eq!(fed, out);
    }
}
