//! What the framers produce: frames (good or failed check, with their timing), noise, and
//! turnaround glitches.

use crate::chunk::{PortId, Timestamp};

/// A frame as it was on the wire, borrowed from the framer's buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    pub port: PortId,
    /// The bytes exactly as on the wire (RTU with its CRC; ASCII as its characters).
    pub bytes: &'a [u8],
    /// Estimated start of the first character.
    pub t_start: Timestamp,
    /// Estimated end of the last character.
    pub t_end: Timestamp,
    /// CRC / LRC valid.
    pub check_ok: bool,
    /// The longest silence inside the frame known to exceed t1.5 (RTU) or the 1 s
    /// inter-character timeout (ASCII), in ns; `None` when none is known.
    pub gap_violation_ns: Option<u64>,
    /// The silence before this frame, known to be shorter than t3.5 after the previous frame, in ns.
    pub short_gap_before_ns: Option<u64>,
    /// The silence before this frame is bounded by the reads' timing: its first byte began a
    /// read after an earlier one. False when it came in the same read as the bytes before it —
    /// then nobody can say when it started, and a latency measured to it would be invented.
    pub gap_before_known: bool,
    /// How far the longest apparent silence inside the frame (between two reads, taken at face
    /// value) exceeds t1.5, in ns; `None` when none reached t1.5. Through delayed reads an
    /// apparent silence may be the observer's delay: a report counts the pause as proven only
    /// where this is at least the observer's resolution (`resolution_ns`, or what the port
    /// finally learned).
    pub gap_tolerance_ns: Option<u64>,
    /// How far the apparent silence before the frame (taken at face value) fell short of t3.5
    /// after the previous frame, in ns; `None` when it did not, or is unknown. Judged likewise.
    pub short_gap_tolerance_ns: Option<u64>,
    /// The shortest timing fault the framer's reads could prove when it emitted this frame
    /// (ns; 0 with per-byte timestamps): its observer latency plus one character.
    pub resolution_ns: u64,
    /// ASCII only: characters that are not hex digits where digits belong.
    pub bad_chars: bool,
    /// RTU only: another length of these bytes that checks too and that neither structure,
    /// timing nor what follows could rule out — one byte more (the `00` after the frame was its
    /// CRC's high byte, not a turnaround glitch) or one byte less (the frame's last `00` was a
    /// glitch). CRC-16/MODBUS's shift property makes both pass; the framer took the likelier on
    /// this line and says so, rather than pass a guess off as certain.
    pub alt_len: Option<usize>,
}

impl<'a> Frame<'a> {
    /// The frame's unit and PDU: RTU's split from its address and CRC (the framer checked the
    /// CRC already), ASCII's decoded from its hex into `scratch`. `None` when the bytes are too
    /// short to hold both, or not ASCII hex. The one place a frame's bytes are split: pairing,
    /// reports, annotation and the UI read the PDU that comes with the frame and its transaction.
    #[inline]
    pub fn unit_pdu<'s>(&self, scratch: &'s mut Vec<u8>) -> Option<(u8, &'s [u8])>
    where
        'a: 's,
    {
        if self.bytes.first() == Some(&b':') {
            let a = mbtap_proto::parse_ascii(self.bytes).ok()?;
            scratch.clear();
            scratch.push(a.unit());
            scratch.extend_from_slice(a.pdu());
            return scratch.split_first().map(|(u, p)| (*u, p));
        }
        match self.bytes {
            [unit, pdu @ .., _, _] if !pdu.is_empty() => Some((*unit, pdu)),
            _ => None,
        }
    }
}

/// Bytes that belong to no frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Noise<'a> {
    pub port: PortId,
    pub bytes: &'a [u8],
    pub t_start: Timestamp,
    pub t_end: Timestamp,
}

/// One framer output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameEvent<'a> {
    Frame(Frame<'a>),
    Noise(Noise<'a>),
    /// One byte right after a frame, with no silence between: the garbage a transceiver
    /// leaves when its driver switches off on a line without fail-safe biasing. Not part of
    /// the frame, not a frame of its own, not interference.
    Glitch(Noise<'a>),
}

impl FrameEvent<'_> {
    /// The bytes of the event.
    #[must_use]
    pub const fn bytes(&self) -> &[u8] {
        match self {
            Self::Frame(f) => f.bytes,
            Self::Noise(n) | Self::Glitch(n) => n.bytes,
        }
    }
}
