//! Scoring a framer against the generator's ground truth, and the plain gap-cutting baseline
//! that open sniffers use, for comparison.

use std::collections::HashMap;
use std::ops::Range;

use super::generate::{TruthKind, Wire};
use super::observe::ChunkSpan;
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FrameEvent, FramerConfig, RtuFramer};
use mbtap_proto::crc16;

/// One decided stretch: bytes `range` of the wire, a frame (with its check), noise or a
/// turnaround glitch.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Decided {
    pub range: Range<usize>,
    pub frame: bool,
    pub check_ok: bool,
    pub glitch: bool,
    /// A valid frame's other length that checks too, reported beside it (`Frame::alt_len`).
    pub alt_len: Option<usize>,
}

/// How well a framer did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Score {
    pub good_total: usize,
    pub good_recovered: usize,
    /// Frames reported valid, without doubt, that were not one frame on the wire.
    pub false_valid: usize,
    /// Valid frames reported with two lengths (`Frame::alt_len`: CRC-16's shift property, both
    /// readings possible on this line), and of those, the ones whose first reading was the
    /// wrong one (the frame on the wire was the other length).
    pub ambiguous: usize,
    pub ambiguous_wrong: usize,
    pub corrupted_total: usize,
    pub corrupted_exact: usize,
    /// Turnaround glitch bytes on the wire, and those reported as glitches.
    pub glitch_total: usize,
    pub glitch_reported: usize,
}

impl Score {
    /// Share of good frames recovered byte-exact.
    #[must_use]
    pub fn good_ratio(&self) -> f64 {
        ratio(self.good_recovered, self.good_total)
    }

    /// Share of corrupted frames reported with exact boundaries and a failed check.
    #[must_use]
    pub fn corrupted_ratio(&self) -> f64 {
        ratio(self.corrupted_exact, self.corrupted_total)
    }
}

fn ratio(a: usize, b: usize) -> f64 {
    #[allow(clippy::cast_precision_loss)]
    if b == 0 { 1.0 } else { a as f64 / b as f64 }
}

/// Compares decided stretches with the truth.
#[must_use]
pub fn score(wire: &Wire, decided: &[Decided]) -> Score {
    let truth: HashMap<(usize, usize), TruthKind> = wire.truth.iter().map(|t| ((t.start, t.end), t.kind)).collect();
    let mut s = Score {
        good_total: wire.truth.iter().filter(|t| t.kind == TruthKind::Good).count(),
        corrupted_total: wire.truth.iter().filter(|t| t.kind == TruthKind::Corrupted).count(),
        glitch_total: wire.truth.iter().filter(|t| t.kind == TruthKind::Glitch).count(),
        ..Score::default()
    };
    s.glitch_reported = decided
        .iter()
        .filter(|d| d.glitch && truth.get(&(d.range.start, d.range.end)) == Some(&TruthKind::Glitch))
        .count();
    for d in decided.iter().filter(|d| d.frame) {
        let t = truth.get(&(d.range.start, d.range.end)).copied();
        if d.check_ok && d.alt_len.is_some() {
            s.ambiguous += 1;
        }
        let alt_good =
            d.alt_len.is_some_and(|n| truth.get(&(d.range.start, d.range.start + n)) == Some(&TruthKind::Good));
        match (d.check_ok, t) {
            (true, Some(TruthKind::Good)) => s.good_recovered += 1,
            (true, _) if alt_good => s.ambiguous_wrong += 1,
            (true, _) => s.false_valid += 1,
            (false, Some(TruthKind::Corrupted)) => s.corrupted_exact += 1,
            (false, _) => {}
        }
    }
    s
}

/// Runs mbtap's RTU framer over the chunks and returns what it decided.
#[must_use]
pub fn run_framer(wire: &Wire, chunks: &[ChunkSpan], config: FramerConfig) -> Vec<Decided> {
    let mut framer = RtuFramer::new(PortId(0), config);
    let mut out = Vec::new();
    let mut offset = 0usize;
    let mut emit = |e: FrameEvent<'_>| {
        let n = e.bytes().len();
        let (frame, check_ok, glitch, alt_len) = match e {
            FrameEvent::Frame(f) => (true, f.check_ok, false, f.alt_len),
            FrameEvent::Noise(_) => (false, false, false, None),
            FrameEvent::Glitch(_) => (false, false, true, None),
        };
        out.push(Decided { range: offset..offset + n, frame, check_ok, glitch, alt_len });
        offset += n;
    };
    for (t, r) in chunks {
        framer.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes: &wire.bytes[r.clone()] }, &mut emit);
    }
    framer.finish(&mut emit);
    out
}

/// The baseline: cut a frame wherever the reads suggest a silence of t3.5 or more, as
/// gap-only sniffers do; a piece is valid when its CRC holds.
#[must_use]
pub fn run_gap_cutter(wire: &Wire, chunks: &[ChunkSpan], config: FramerConfig) -> Vec<Decided> {
    let char_ns = config.line.char_ns();
    let t35 = config.line.t35_ns();
    let mut out = Vec::new();
    let mut start = 0usize;
    let mut last_t: Option<u64> = None;
    let close = |start: usize, end: usize, out: &mut Vec<Decided>| {
        if end > start {
            let b = &wire.bytes[start..end];
            let ok = b.len() >= 4 && crc16(&b[..b.len() - 2]) == u16::from_le_bytes([b[b.len() - 2], b[b.len() - 1]]);
            out.push(Decided { range: start..end, frame: true, check_ok: ok, glitch: false, alt_len: None });
        }
    };
    for (t, r) in chunks {
        let n = (r.end - r.start) as u64;
        if let Some(prev) = last_t
            && t.saturating_sub(n * char_ns).saturating_sub(prev) >= t35
        {
            close(start, r.start, &mut out);
            start = r.start;
        }
        last_t = Some(*t);
    }
    close(start, wire.bytes.len(), &mut out);
    out
}
