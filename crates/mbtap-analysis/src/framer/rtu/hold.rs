//! Twins held until the line tells their length: a frame that checks at two lengths (CRC-16's
//! shift property: a frame ending in `00`, or one followed by a `00` glitch) which nothing yet
//! decides — the first vendor requests of a unit, before any of its frames was unambiguous —
//! is held with everything after it, until a later frame of the same unit and function teaches
//! its length (devices send a vendor function at one length all day) or a bound passes; then
//! it goes out at the length the line taught, the other kept as `alt_len`.
//!
//! Why wait: where a quarter of a device's CRCs end in `00` and the master leaves a `00` after
//! three requests in ten, "frame ending in `00`" and "one byte shorter plus the master's
//! glitch" are nearly as likely (0.7 × 0.25 against 0.3), and a batching adapter shows nothing
//! else: the odds alone put the wrong length first four times in ten. What the line does next
//! does tell. The wait is bounded by bus time and by bytes, so a live view is held back at most
//! [`HOLD_NS`] once per unit's vendor function, and memory stays bounded; order is kept (what
//! came after the twin is held behind it).

use crate::chunk::Timestamp;
use crate::framer::event::{Frame, FrameEvent, Noise};
use crate::framer::glitch::Sender;
use crate::framer::lengths::LearnedLengths;

/// The longest a twin is held by default, in bus time: long enough for a unit polled every few
/// seconds to send its vendor function again (on a real line a unit that never answers is
/// asked again 10–20 s later), once per unit's function, at a live view's first sight of it.
pub const HOLD_NS: u64 = 20_000_000_000;
/// The most bytes held behind a twin (a bound on memory whatever the line does).
pub const MAX_HELD_BYTES: usize = 64 * 1024;

/// One held event, its bytes in [`TwinHold::bytes`].
#[derive(Debug, Clone, Copy)]
enum Held {
    /// A frame, its `bytes` field empty (they are at `at..at + len` in the store).
    Frame {
        frame: Frame<'static>,
        at: usize,
        len: usize,
    },
    Noise {
        noise: Noise<'static>,
        at: usize,
        len: usize,
        glitch: bool,
    },
}

/// The events held behind an undecided twin, in order.
#[derive(Debug)]
pub(crate) struct TwinHold {
    events: Vec<Held>,
    bytes: Vec<u8>,
    /// How long a twin is held (bus time, ns); 0: never, every event goes straight out.
    bound_ns: u64,
}

/// Is this a frame the framer read at one of two lengths without anything deciding?
fn undecided(f: &Frame<'_>) -> bool {
    f.check_ok && f.alt_len.is_some()
}

/// `f` without its bytes, to be kept past the framer's buffer.
const fn detach(f: &Frame<'_>) -> Frame<'static> {
    Frame {
        port: f.port,
        bytes: &[],
        t_start: f.t_start,
        t_end: f.t_end,
        check_ok: f.check_ok,
        gap_violation_ns: f.gap_violation_ns,
        short_gap_before_ns: f.short_gap_before_ns,
        gap_before_known: f.gap_before_known,
        gap_tolerance_ns: f.gap_tolerance_ns,
        short_gap_tolerance_ns: f.short_gap_tolerance_ns,
        resolution_ns: f.resolution_ns,
        bad_chars: f.bad_chars,
        alt_len: f.alt_len,
    }
}

impl TwinHold {
    pub(crate) fn new(bound_ns: u64) -> Self {
        Self { events: Vec::new(), bytes: Vec::new(), bound_ns }
    }

    /// Bytes held.
    pub(crate) fn held(&self) -> usize {
        self.bytes.len()
    }

    /// When the first held event began, if any: nothing after it has reached the consumer.
    pub(crate) fn since(&self) -> Option<Timestamp> {
        self.events.first().map(|h| match h {
            Held::Frame { frame, .. } => frame.t_start,
            Held::Noise { noise, .. } => noise.t_start,
        })
    }

    /// An event the framer decided: out at once, unless a twin is held (then behind it) or it
    /// is an undecided twin (then the hold begins). Every event of a replay passes here: the
    /// common case is one test, inlined, and the event goes out where it was built.
    // Measured: with `#[inline]` alone it stayed a call, and the event a copy, per event (31 M
    // instructions of a 2 000 M replay).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    pub(crate) fn pass<F: FnMut(FrameEvent<'_>)>(&mut self, e: FrameEvent<'_>, emit: &mut F) {
        if self.events.is_empty() && (self.bound_ns == 0 || !matches!(&e, FrameEvent::Frame(f) if undecided(f))) {
            emit(e);
        } else {
            self.keep(&e);
        }
    }

    /// Keeps `e` behind the held twin (or as the twin a hold begins with).
    #[cold]
    #[inline(never)]
    fn keep(&mut self, e: &FrameEvent<'_>) {
        let at = self.bytes.len();
        let len = e.bytes().len();
        self.bytes.extend_from_slice(e.bytes());
        self.events.push(match e {
            FrameEvent::Frame(f) => Held::Frame { frame: detach(f), at, len },
            FrameEvent::Noise(n) | FrameEvent::Glitch(n) => Held::Noise {
                noise: Noise { port: n.port, bytes: &[], t_start: n.t_start, t_end: n.t_end },
                at,
                len,
                glitch: matches!(e, FrameEvent::Glitch(_)),
            },
        });
    }

    /// The time is `now` (bus time; `None`: the input ended): each held twin whose length the
    /// line has taught goes out at that length, and so does one held past the bounds, at the
    /// length the odds chose; each with what follows it, up to the next twin still undecided.
    /// `char_ns`: one character's time on this line.
    #[inline]
    pub(crate) fn settle<F: FnMut(FrameEvent<'_>)>(
        &mut self,
        lengths: &LearnedLengths,
        now: Option<u64>,
        char_ns: u64,
        emit: &mut F,
    ) {
        if !self.events.is_empty() {
            self.settle_held(lengths, now, char_ns, emit);
        }
    }

    #[inline(never)]
    fn settle_held<F: FnMut(FrameEvent<'_>)>(
        &mut self,
        lengths: &LearnedLengths,
        now: Option<u64>,
        char_ns: u64,
        emit: &mut F,
    ) {
        let mut i = 0;
        while let Some(&h) = self.events.get(i) {
            // A hold begins with a twin and is cut only before one: `h` is one.
            let Held::Frame { frame, at, len } = h else {
                self.emit_held(h, emit);
                i += 1;
                continue;
            };
            let taught = taught_len(lengths, &self.bytes[at..at + len], frame.alt_len);
            let expired = now.is_none_or(|t| t.saturating_sub(frame.t_end.0) >= self.bound_ns)
                || self.bytes.len() - at > MAX_HELD_BYTES;
            if taught.is_none() && !expired {
                break;
            }
            i = self.release_twin(i, taught, char_ns, emit);
            while let Some(&h) = self.events.get(i) {
                if matches!(h, Held::Frame { frame, .. } if undecided(&frame)) {
                    break;
                }
                self.emit_held(h, emit);
                i += 1;
            }
        }
        self.events.drain(..i);
        // What went out leaves the store: it holds what is still held, and no more.
        let kept = match self.events.first() {
            Some(Held::Frame { at, .. } | Held::Noise { at, .. }) => *at,
            None => self.bytes.len(),
        };
        if kept > 0 {
            self.bytes.drain(..kept);
            for h in &mut self.events {
                let (Held::Frame { at, .. } | Held::Noise { at, .. }) = h;
                *at -= kept;
            }
        }
    }

    /// Sends out the twin at `i` at the length `taught` (if any, and if its bytes allow; else
    /// as it was read), and returns the index of the first event after it.
    fn release_twin<F: FnMut(FrameEvent<'_>)>(
        &self,
        i: usize,
        taught: Option<usize>,
        char_ns: u64,
        emit: &mut F,
    ) -> usize {
        let Some(&Held::Frame { frame, at, len }) = self.events.get(i) else { return i };
        let b = &self.bytes;
        match (taught, self.events.get(i + 1)) {
            // Read long, taught short: the frame without its last byte, which was a glitch.
            (Some(n), _) if n + 1 == len => {
                let glitch_start = frame.t_end.0.saturating_sub(char_ns).max(frame.t_start.0);
                let short: Frame<'_> = frame;
                emit(FrameEvent::Frame(Frame {
                    bytes: &b[at..at + n],
                    t_end: Timestamp(glitch_start),
                    alt_len: Some(len),
                    ..short
                }));
                emit(FrameEvent::Glitch(Noise {
                    port: frame.port,
                    bytes: &b[at + n..at + len],
                    t_start: Timestamp(glitch_start),
                    t_end: frame.t_end,
                }));
                i + 1
            }
            // Read short, taught long: the `00` glitch after it was its CRC's high byte.
            (Some(n), Some(Held::Noise { noise, len: 1, glitch: true, .. }))
                if n == len + 1 && b.get(at + len) == Some(&0) =>
            {
                let long: Frame<'_> = frame;
                emit(FrameEvent::Frame(Frame {
                    bytes: &b[at..at + n],
                    t_end: noise.t_end,
                    alt_len: Some(len),
                    ..long
                }));
                i + 2
            }
            // Taught as read, not taught, or the bytes do not allow the other reading.
            _ => {
                self.emit_held(self.events[i], emit);
                i + 1
            }
        }
    }

    fn emit_held<F: FnMut(FrameEvent<'_>)>(&self, h: Held, emit: &mut F) {
        match h {
            Held::Frame { frame, at, len } => {
                let frame: Frame<'_> = frame;
                emit(FrameEvent::Frame(Frame { bytes: &self.bytes[at..at + len], ..frame }));
            }
            Held::Noise { noise, at, len, glitch } => {
                let noise: Noise<'_> = noise;
                let n = Noise { bytes: &self.bytes[at..at + len], ..noise };
                emit(if glitch { FrameEvent::Glitch(n) } else { FrameEvent::Noise(n) });
            }
        }
    }
}

/// The length the line has since taught for the held twin `b` (read at `b.len()`, the other
/// reading `alt`): what this unit's function was seen with — surely, or at every sighting at
/// one of the two lengths.
fn taught_len(lengths: &LearnedLengths, b: &[u8], alt: Option<usize>) -> Option<usize> {
    let (&[unit, fc, ..], Some(alt)) = (b, alt) else { return None };
    let short = b.len().min(alt);
    lengths.choose(unit, fc, Sender::Unknown, short).or_else(|| lengths.lean(unit, fc, Sender::Unknown, short))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chunk::PortId;
    use crate::framer::lengths::After;

    const MS: u64 = 1_000_000;
    /// Unit 5's vendor request (function 0x41) as the framer read it: 5 bytes, CRC `6A`-ended…
    const SHORT: [u8; 5] = [0x05, 0x41, 0x5B, 0x10, 0x6A];
    /// …and the `00` after it, which it took for the master's turnaround glitch.
    const ZERO: [u8; 1] = [0x00];
    /// The same request read whole: 6 bytes, its CRC's high byte `00`.
    const LONG: [u8; 6] = [0x05, 0x41, 0x5B, 0x10, 0x6A, 0x00];
    /// A later request of unit 5's function 0x41 that nothing else reads: 6 bytes, last not `00`.
    const CERTAIN: [u8; 6] = [0x05, 0x41, 0xC3, 0x11, 0xC0, 0x17];
    /// Another unit's read request after it (unit 1, FC 03).
    const OTHER: [u8; 8] = [0x01, 0x03, 0x00, 0x8A, 0x00, 0x08, 0x65, 0xE6];

    fn frame(bytes: &[u8], t_end_ms: u64, alt_len: Option<usize>) -> Frame<'_> {
        Frame {
            port: PortId(0),
            bytes,
            t_start: Timestamp(t_end_ms * MS - MS),
            t_end: Timestamp(t_end_ms * MS),
            check_ok: true,
            gap_violation_ns: None,
            short_gap_before_ns: None,
            gap_before_known: true,
            gap_tolerance_ns: None,
            short_gap_tolerance_ns: None,
            resolution_ns: 0,
            bad_chars: false,
            alt_len,
        }
    }

    fn glitch(t_end_ms: u64) -> FrameEvent<'static> {
        FrameEvent::Glitch(Noise {
            port: PortId(0),
            bytes: &ZERO,
            t_start: Timestamp(t_end_ms * MS - MS),
            t_end: Timestamp(t_end_ms * MS),
        })
    }

    /// (kind, hex, alt_len) of each event let out.
    fn shown<'o>(out: &'o mut Vec<(&'static str, Vec<u8>, Option<usize>)>) -> impl for<'e> FnMut(FrameEvent<'e>) + 'o {
        move |e: FrameEvent<'_>| {
            out.push(match e {
                FrameEvent::Frame(f) => ("frame", f.bytes.to_vec(), f.alt_len),
                FrameEvent::Noise(n) => ("noise", n.bytes.to_vec(), None),
                FrameEvent::Glitch(n) => ("glitch", n.bytes.to_vec(), None),
            });
        }
    }

    /// The twin read short with its `00` as a glitch, then another unit's frame: all held.
    fn held_short_twin(hold: &mut TwinHold, out: &mut Vec<(&'static str, Vec<u8>, Option<usize>)>) {
        let mut emit = shown(out);
        hold.pass(FrameEvent::Frame(frame(&SHORT, 10, Some(6))), &mut emit);
        hold.pass(glitch(11), &mut emit);
        hold.pass(FrameEvent::Frame(frame(&OTHER, 30, None)), &mut emit);
    }

    #[test]
    fn nothing_is_held_without_an_undecided_twin() {
        let (mut hold, mut out) = (TwinHold::new(HOLD_NS), Vec::new());
        hold.pass(FrameEvent::Frame(frame(&OTHER, 30, None)), &mut shown(&mut out));
        assert_eq!(out, [("frame", OTHER.to_vec(), None)]);
        assert_eq!(hold.held(), 0);
    }

    /// The line's next request of that unit's function has 6 bytes — the twin goes out
    /// whole, its `00` the CRC's, the short reading kept as the other; order kept.
    #[test]
    fn a_twin_read_short_goes_out_at_the_length_the_line_taught() {
        let (mut hold, mut out) = (TwinHold::new(HOLD_NS), Vec::new());
        let mut lengths = LearnedLengths::new(true);
        held_short_twin(&mut hold, &mut out);
        hold.settle(&lengths, Some(40 * MS), MS, &mut shown(&mut out));
        assert!(out.is_empty(), "let out before its length was known: {out:?}");
        assert_eq!(hold.held(), SHORT.len() + 1 + OTHER.len());
        lengths.record(&CERTAIN, After::Silence, Sender::Master);
        hold.settle(&lengths, Some(900 * MS), MS, &mut shown(&mut out));
        assert_eq!(out, [("frame", LONG.to_vec(), Some(5)), ("frame", OTHER.to_vec(), None)]);
        assert_eq!(hold.held(), 0);
    }

    /// Read whole, taught short: the frame without its last byte, and that byte a glitch.
    #[test]
    fn a_twin_read_long_is_split_when_the_line_teaches_the_shorter_length() {
        let (mut hold, mut out) = (TwinHold::new(HOLD_NS), Vec::new());
        let mut lengths = LearnedLengths::new(true);
        hold.pass(FrameEvent::Frame(frame(&LONG, 10, Some(5))), &mut shown(&mut out));
        lengths.record(&[0x05, 0x41, 0x01, 0x02, 0x03], After::Silence, Sender::Master);
        hold.settle(&lengths, Some(20 * MS), MS, &mut shown(&mut out));
        assert_eq!(out, [("frame", SHORT.to_vec(), Some(6)), ("glitch", ZERO.to_vec(), None)]);
    }

    /// Nothing taught within the bound: out as the odds read it, nothing lost.
    #[test]
    fn an_untaught_twin_goes_out_as_read_when_the_bound_passes_or_the_input_ends() {
        for now in [Some(10 * MS + HOLD_NS), None] {
            let (mut hold, mut out) = (TwinHold::new(HOLD_NS), Vec::new());
            held_short_twin(&mut hold, &mut out);
            hold.settle(&LearnedLengths::new(true), now.map(|t| t - 1), MS, &mut shown(&mut out));
            assert_eq!(out.is_empty(), now.is_some(), "{now:?}");
            hold.settle(&LearnedLengths::new(true), now, MS, &mut shown(&mut out));
            let want =
                [("frame", SHORT.to_vec(), Some(6)), ("glitch", ZERO.to_vec(), None), ("frame", OTHER.to_vec(), None)];
            assert_eq!(out, want, "{now:?}");
            assert_eq!(hold.held(), 0);
        }
    }

    /// Memory stays bounded whatever follows a twin: past [`MAX_HELD_BYTES`] it goes out.
    #[test]
    fn what_is_held_behind_a_twin_is_bounded_in_bytes() {
        let (mut hold, mut out) = (TwinHold::new(HOLD_NS), Vec::new());
        held_short_twin(&mut hold, &mut out);
        let noise = [0xAA; 256];
        let lengths = LearnedLengths::new(true);
        for i in 0..400 {
            let n = Noise { port: PortId(0), bytes: &noise, t_start: Timestamp(0), t_end: Timestamp(0) };
            hold.pass(FrameEvent::Noise(n), &mut shown(&mut out));
            hold.settle(&lengths, Some(40 * MS), MS, &mut shown(&mut out));
            assert!(hold.held() <= MAX_HELD_BYTES, "{} held after {i} bursts", hold.held());
        }
        let let_out: usize = out.iter().map(|(_, b, _)| b.len()).sum();
        assert_eq!(let_out, SHORT.len() + 1 + OTHER.len() + 400 * 256);
    }

    #[test]
    fn a_hold_that_is_off_lets_a_twin_straight_out() {
        let (mut hold, mut out) = (TwinHold::new(0), Vec::new());
        held_short_twin(&mut hold, &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(hold.held(), 0);
    }
}
