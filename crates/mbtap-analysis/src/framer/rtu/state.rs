//! The framer's state, owned by what it is about (21 fields changed from six files):
//! the line's timing, where the search for the next frame stands, and what was emitted last.
//! The timed buffer ([`super::buffer::TimedBuffer`]), the glitch evidence
//! ([`super::glitches::GlitchState`]), the expectation, the observer learner and the
//! learned lengths are sub-states of their own already.

use crate::framer::FramerConfig;
use crate::framer::glitch::Sender;

/// The line's timing (Modbus over Serial Line v1.02 §2.5.1.1) and the observer's latency the
/// framer judges silences with.
#[derive(Debug, Clone, Copy)]
pub(super) struct LineTiming {
    pub(super) char_ns: u64,
    pub(super) t15: u64,
    pub(super) t35: u64,
    /// The latency in effect: the configured one, then what the learner learned. A copy of the
    /// learner's figure, set in one place (`learning.rs`) when it changes: read on every
    /// silence, it costs 1.5 % of the per-byte replay's instructions to ask the learner instead.
    pub(super) latency: u64,
    pub(super) incomplete_timeout: u64,
}

impl LineTiming {
    pub(super) fn new(config: &FramerConfig) -> Self {
        Self {
            char_ns: config.line.char_ns(),
            t15: config.line.t15_ns(),
            t35: config.line.t35_ns(),
            latency: config.latency_ns,
            incomplete_timeout: config.incomplete_timeout_ns,
        }
    }
}

/// Where the search for the next frame stands in the buffer.
#[derive(Debug, Clone, Copy)]
pub(super) struct Search {
    /// Live bytes from `timed.head` known not to start a valid frame.
    pub(super) garbage: usize,
    /// The candidate start last found waiting (`garbage` then), and how many bytes from it
    /// must be buffered before trying it again is worth it: skips re-parsing on every byte.
    pub(super) wait_at: usize,
    pub(super) wait_for: usize,
    /// Everything pending is being decided because the line fell silent after it (a tick past
    /// the incomplete-frame timeout): the last frame of it was followed by nothing.
    pub(super) silent_after: bool,
}

impl Search {
    pub(super) const fn new() -> Self {
        Self { garbage: 0, wait_at: usize::MAX, wait_for: 0, silent_after: false }
    }
}

/// What was emitted last: what the next bytes are judged against.
#[derive(Debug, Clone, Copy)]
pub(super) struct LastEmitted {
    /// The last event emitted was a frame (for the inter-frame gap check).
    pub(super) after_frame: bool,
    /// The last thing emitted (glitches aside) was a failed frame or noise: nothing is
    /// expected, and a CRC match right after damage must be confirmed by what follows.
    pub(super) after_damage: bool,
    /// Absolute buffer index right after the last frame: a lone byte there is a glitch.
    pub(super) glitch_at: Option<usize>,
    /// While the garbage before a found frame goes out: where that frame starts (a lone byte
    /// glued to its start is the sender's driver switching on).
    pub(super) frame_next_at: Option<usize>,
    /// Who sent the last frame emitted (whose glitch the next lone byte would be).
    pub(super) last_sender: Sender,
    /// The other length of the frame about to be emitted, if any (see
    /// [`crate::framer::Frame::alt_len`]).
    pub(super) next_alt: Option<usize>,
}

impl LastEmitted {
    pub(super) const fn new() -> Self {
        Self {
            after_frame: false,
            after_damage: false,
            glitch_at: None,
            frame_next_at: None,
            last_sender: Sender::Unknown,
            next_alt: None,
        }
    }
}
