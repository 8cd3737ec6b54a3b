//! Turnaround glitches: the lone byte a transceiver leaves when its driver switches off, told
//! from a frame's start or end, counted by value and by sender.

use super::RtuFramer;
use crate::chunk::Timestamp;
use crate::framer::event::{FrameEvent, Noise};
use crate::framer::glitch::Sender;

/// Frames after the last glitch for which the line still counts as glitch-prone.
pub(super) const GLITCHY_FOR: u32 = 64;

impl RtuFramer {
    /// Has this line shown turnaround glitches lately?
    pub(super) fn glitchy(&self) -> bool {
        self.since_glitch < GLITCHY_FOR
    }

    /// Is `v` a value this line's glitches take? A transceiver leaves the same one or two values
    /// again and again; a byte taken for a glitch by mistake is a value seen now and then.
    /// Counted values become glitch values from the fourth time, and only while they are at
    /// least an eighth as common as the commonest.
    pub(super) fn glitch_value(&self, v: u8) -> bool {
        let n = self.glitch_counts[usize::from(v)];
        n >= 4 && n.saturating_mul(8) >= self.glitch_top
    }

    /// Is `v` a value the driver of `sender` leaves (the line's values when nobody can say who
    /// sent the frame, or the sender was never seen to glitch)?
    pub(super) fn glitch_value_after(&self, sender: Sender, v: u8) -> bool {
        self.turn.sender_value(sender, v).unwrap_or_else(|| self.glitch_value(v))
    }

    /// Is the live byte at absolute `a` where a turnaround glitch would be: right after a
    /// frame, not known to be separated from it by 1.5 characters of silence?
    pub(super) fn at_glitch(&self, a: usize) -> bool {
        self.glitch_at == Some(a) && self.gap_lb.get(a).is_some_and(|&g| g < self.t15)
    }

    /// On a line that glitches, is the byte at live index `i` one of its glitch values, with a
    /// frame of a known unit (not a broadcast, which a glitch `00` would fake) starting after it?
    pub(super) fn glitch_then_start(&self, i: usize) -> bool {
        let live = &self.buf[self.head..];
        self.glitchy()
            && live.get(i).is_some_and(|&v| self.glitch_value(v))
            && live.get(i + 1).is_some_and(|&a| a != 0)
            && self.looks_like_frame_start(i + 1)
    }

    /// Is the byte at live index `i` a lone byte — a frame's turnaround glitch — with a known
    /// silence, a valid frame or the end of what has arrived right after it? (Not known to be
    /// separated from the frame by 1.5 characters of silence.)
    pub(super) fn glitch_then_end(&self, i: usize) -> bool {
        i < self.buf.len() - self.head
            && self.gap_lb[self.head + i] < self.t15
            && (self.boundary_at(i + 1) || self.exact_frame_at(i + 1))
    }

    /// Emits the live byte at absolute `a` (`== self.head`) as a turnaround glitch.
    pub(super) fn emit_glitch<F: FnMut(FrameEvent<'_>)>(&mut self, a: usize, emit: &mut F) {
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
}
