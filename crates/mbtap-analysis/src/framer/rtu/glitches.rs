//! Turnaround glitches: the lone byte a transceiver leaves when its driver switches off, told
//! from a frame's start or end, counted by value and by sender.

use super::RtuFramer;
use crate::chunk::Timestamp;
use crate::framer::event::{FrameEvent, Noise};
use crate::framer::glitch::{Sender, TurnaroundStats};

/// Frames after the last glitch for which the line still counts as glitch-prone.
pub(super) const GLITCHY_FOR: u32 = 64;

/// What this line's turnaround glitches have shown: how recently one was seen, the values they
/// take, and after whom (`00` after the master, `FE`/`FF` after slaves, on most transceivers).
#[derive(Debug)]
pub(super) struct GlitchState {
    /// Frames since the last glitch (`u32::MAX`: none seen).
    since: u32,
    /// How often each byte value was a glitch; see [`Self::value`].
    counts: [u32; 256],
    /// The count of the commonest glitch value.
    top: u32,
    /// How often the master's and the slaves' frames are followed by a `00` glitch.
    pub(super) turn: TurnaroundStats,
}

impl GlitchState {
    pub(super) fn new() -> Self {
        Self { since: u32::MAX, counts: [0; 256], top: 0, turn: TurnaroundStats::default() }
    }

    /// Has this line shown turnaround glitches lately?
    pub(super) fn glitchy(&self) -> bool {
        self.since < GLITCHY_FOR
    }

    /// Is `v` a value this line's glitches take? A transceiver leaves the same one or two values
    /// again and again; a byte taken for a glitch by mistake is a value seen now and then.
    /// Counted values become glitch values from the fourth time, and only while they are at
    /// least an eighth as common as the commonest.
    pub(super) fn value(&self, v: u8) -> bool {
        let n = self.counts[usize::from(v)];
        n >= 4 && n.saturating_mul(8) >= self.top
    }

    /// Is `v` a value the driver of `sender` leaves (the line's values when nobody can say who
    /// sent the frame, or the sender was never seen to glitch)?
    pub(super) fn value_after(&self, sender: Sender, v: u8) -> bool {
        self.turn.sender_value(sender, v).unwrap_or_else(|| self.value(v))
    }

    /// A frame went out (valid or not): one more since the last glitch.
    pub(super) fn frame(&mut self) {
        self.since = self.since.saturating_add(1);
    }

    /// A glitch of value `v`; `after` the sender whose driver left it, when it came right
    /// after that sender's frame.
    pub(super) fn glitch(&mut self, v: u8, after: Option<Sender>) {
        self.since = 0;
        if let Some(sender) = after {
            self.turn.glitch(sender, v);
        }
        let n = &mut self.counts[usize::from(v)];
        *n = n.saturating_add(1);
        self.top = self.top.max(*n);
    }
}

impl RtuFramer {
    /// Is the live byte at absolute `a` where a turnaround glitch would be: right after a
    /// frame, not known to be separated from it by 1.5 characters of silence?
    pub(super) fn at_glitch(&self, a: usize) -> bool {
        self.last.glitch_at == Some(a) && self.timed.gap_lb.get(a).is_some_and(|&g| g < self.timing.t15)
    }

    /// On a line that glitches, is the byte at live index `i` one of its glitch values, with a
    /// frame of a known unit (not a broadcast, which a glitch `00` would fake) starting after it?
    pub(super) fn glitch_then_start(&self, i: usize) -> bool {
        let live = &self.timed.buf[self.timed.head..];
        self.glitches.glitchy()
            && live.get(i).is_some_and(|&v| self.glitches.value(v))
            && live.get(i + 1).is_some_and(|&a| a != 0)
            && self.looks_like_frame_start(i + 1)
    }

    /// Is the byte at live index `i` a lone byte — a frame's turnaround glitch — with a known
    /// silence, a valid frame or the end of what has arrived right after it? (Not known to be
    /// separated from the frame by 1.5 characters of silence.)
    pub(super) fn glitch_then_end(&self, i: usize) -> bool {
        i < self.timed.live_len()
            && self.timed.gap_lb[self.timed.head + i] < self.timing.t15
            && (self.boundary_at(i + 1) || self.exact_frame_at(i + 1))
    }

    /// Emits the live byte at absolute `a` (`== self.timed.head`) as a turnaround glitch.
    pub(super) fn emit_glitch<F: FnMut(FrameEvent<'_>)>(&mut self, a: usize, emit: &mut F) {
        self.hold.pass(
            FrameEvent::Glitch(Noise {
                port: self.port,
                bytes: &self.timed.buf[a..=a],
                t_start: Timestamp(self.timed.end[a].saturating_sub(self.timing.char_ns)),
                t_end: Timestamp(self.timed.end[a]),
            }),
            emit,
        );
        let after = (self.last.glitch_at == Some(a)).then_some(self.last.last_sender);
        self.glitches.glitch(self.timed.buf[a], after);
        self.last.glitch_at = None;
        self.timed.head = a + 1;
        self.search.wait_at = usize::MAX;
    }
}
