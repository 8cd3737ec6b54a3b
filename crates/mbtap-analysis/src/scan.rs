//! Line-settings detection: which baud rate, parity, stop bits and mode make the bytes of a bus
//! into valid Modbus frames. Each candidate is scored by the frames the analyzer rebuilds with a
//! valid CRC/LRC, less what it had to call garbage. Pure: the caller supplies what a receiver at
//! each candidate's settings heard (a live port reopened per setting, or the UART model of
//! `mbtap_sim::scan_line` for simulated lines).
//!
//! Ties: a sender with two stop bits is heard perfectly by a one-stop-bit receiver (the second
//! stop bit is idle line), so the stop bits cannot always be told apart by frames alone; when
//! they tie, one stop bit ranks first — what the meters and devices on these buses are set to
//! without parity at the factory (Eastron, Carlo Gavazzi, Chint: 8N1), where Serial Line v1.02
//! §2.5.1 prescribes two — and the description names both ([`tied_stop_bits`]).

use std::collections::BTreeSet;

use crate::analyzer::{Analyzer, AnalyzerConfig, Event, SerialMode};
use crate::chunk::{Chunk, PortId, Timestamp};
use crate::framer::{FramerConfig, LineSettings, Parity};

/// Baud rates tried: the common ones plus 14400, 56000, 128000 and 256000, which the MK4 offers.
pub const BAUDS: [u32; 13] =
    [1200, 2400, 4800, 9600, 14_400, 19_200, 38_400, 56_000, 57_600, 115_200, 128_000, 230_400, 256_000];

/// Settings to try.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Candidate {
    pub mode: SerialMode,
    pub line: LineSettings,
}

/// How well a candidate decoded the bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Score {
    pub candidate: Candidate,
    pub valid_frames: u64,
    pub bad_frames: u64,
    pub noise_bytes: u64,
    /// Units heard in valid frames.
    pub units: BTreeSet<u8>,
}

impl Score {
    /// Valid frames, less a penalty for garbage (one frame per failed frame or 8 noise bytes).
    #[must_use]
    pub fn value(&self) -> i64 {
        let good = i64::try_from(self.valid_frames).unwrap_or(i64::MAX);
        let bad = i64::try_from(self.bad_frames + self.noise_bytes / 8).unwrap_or(i64::MAX);
        good.saturating_sub(bad)
    }
}

/// Every combination tried: RTU with 8 data bits, ASCII with 7 (and 8), each parity, 1 or 2
/// stop bits, every baud rate in [`BAUDS`].
#[must_use]
pub fn candidates() -> Vec<Candidate> {
    let mut out = Vec::new();
    for &baud in &BAUDS {
        for (mode, data_bits) in [(SerialMode::Rtu, 8), (SerialMode::Ascii, 7), (SerialMode::Ascii, 8)] {
            for parity in [Parity::Even, Parity::None, Parity::Odd] {
                for stop_bits in [1, 2] {
                    out.push(Candidate { mode, line: LineSettings { baud, data_bits, parity, stop_bits } });
                }
            }
        }
    }
    out
}

/// Scores what a receiver at `candidate`'s settings heard: `(arrival ns, bytes)` chunks.
#[must_use]
pub fn score(candidate: Candidate, heard: &[(u64, Vec<u8>)]) -> Score {
    let mut s = Score { candidate, valid_frames: 0, bad_frames: 0, noise_bytes: 0, units: BTreeSet::new() };
    count(&mut s, candidate.mode, FramerConfig::new(candidate.line, 0), heard);
    s
}

/// Adds what the analyzer makes of `heard` in `mode` to `s`.
fn count(s: &mut Score, mode: SerialMode, framer: FramerConfig, heard: &[(u64, Vec<u8>)]) {
    let mut analyzer = Analyzer::new(AnalyzerConfig { mode, framer, ..AnalyzerConfig::default() });
    let mut sink = |e: &Event<'_>| match e {
        Event::Frame { frame, unit, .. } if frame.check_ok => {
            s.valid_frames += 1;
            s.units.extend(*unit);
        }
        Event::Frame { .. } => s.bad_frames += 1,
        Event::Noise(n) => s.noise_bytes += n.bytes.len() as u64,
        // A glitch sits after a frame: it says nothing about the settings on its own.
        Event::Glitch(_) | Event::Transaction(_) => {}
    };
    for (t, bytes) in heard {
        analyzer.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes }, &mut sink);
    }
    analyzer.finish(&mut sink);
}

/// Best first, ties broken as the module says.
pub fn rank(scores: &mut [Score]) {
    let preference = |s: &Score| {
        let c = s.candidate;
        let stop_rule = i32::from(c.line.stop_bits == 1);
        // Even parity is the serial line's default (Serial Line v1.02 §2.5.1).
        (s.value(), stop_rule, i32::from(c.line.parity == Parity::Even), i32::from(c.line.data_bits == 8))
    };
    scores.sort_by_key(|s| std::cmp::Reverse(preference(s)));
}

/// Whether the runner-up scored the same as the best and differs from it only in its stop bits:
/// a listener cannot tell those apart, and the result must say both.
#[must_use]
pub fn tied_stop_bits(ranked: &[Score]) -> Option<u8> {
    let (best, next) = (ranked.first()?, ranked.get(1)?);
    let (a, b) = (best.candidate, next.candidate);
    (best.value() == next.value()
        && a.mode == b.mode
        && a.line.stop_bits != b.line.stop_bits
        && LineSettings { stop_bits: b.line.stop_bits, ..a.line } == b.line)
        .then_some(b.line.stop_bits)
}

/// What the eighth bit of stored characters says about a 7-bit (ASCII) line recorded as
/// 8 data bits: the receiver took the parity bit (or the first stop bit) for data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EighthBit {
    /// Always 0: 7-bit characters (parity, if any, removed by the receiver) or 8-bit ASCII.
    Zero,
    /// Even parity of the seven data bits: a 7E1 line recorded at 8N1.
    Even,
    /// Odd parity: a 7O1 line recorded at 8N1.
    Odd,
    /// Always 1: the first stop bit of a 7N2 line recorded at 8N1.
    One,
    /// None of those.
    Mixed,
}

/// What the eighth bits of `bytes` are, judged on the characters that can be in an ASCII
/// frame (Serial Line v1.02 §2.5.2: ':', hex digits, CR, LF); `None` with too few of them.
#[must_use]
pub fn eighth_bit(bytes: &[u8]) -> Option<EighthBit> {
    let ascii = |b: u8| matches!(b & 0x7F, b':' | b'0'..=b'9' | b'A'..=b'F' | b'\r' | b'\n');
    let (mut n, mut zero, mut one, mut even, mut odd) = (0u64, 0u64, 0u64, 0u64, 0u64);
    for &b in bytes.iter().filter(|&&b| ascii(b)) {
        n += 1;
        let high = b & 0x80 != 0;
        zero += u64::from(!high);
        one += u64::from(high);
        // The eighth bit makes the number of ones even (even parity) or odd.
        even += u64::from(b.count_ones() % 2 == 0);
        odd += u64::from(b.count_ones() % 2 == 1);
    }
    if n < 16 {
        return None;
    }
    // Allow a few damaged characters.
    let most = |k: u64| k * 100 >= n * 95;
    Some(if most(zero) {
        EighthBit::Zero
    } else if most(one) {
        EighthBit::One
    } else if most(even) {
        EighthBit::Even
    } else if most(odd) {
        EighthBit::Odd
    } else {
        EighthBit::Mixed
    })
}

/// A reading of stored bytes (a capture or a raw dump): the mode, and whether the eighth bit
/// was stripped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoredScore {
    pub mode: SerialMode,
    /// For a 7-bit reading: what the stripped eighth bit was.
    pub seven_bit: Option<EighthBit>,
    pub score: Score,
}

/// Scores stored bytes — `(time ns, bytes)` chunks as recorded at `recorded` settings — as
/// RTU, as ASCII, and as ASCII with the eighth bit stripped (a 7-bit line recorded as 8 bits).
/// Stored bytes cannot be re-sampled at other baud rates or parities: the bits a wrong
/// receiver lost are gone; only the mode and the character size can still be told. Ranked,
/// best first. Untimed input (a raw dump) is framed by structure and check alone.
#[must_use]
pub fn scan_stored(chunks: &[(u64, Vec<u8>)], recorded: LineSettings) -> Vec<StoredScore> {
    let all: Vec<u8> = chunks.iter().flat_map(|(_, b)| b.iter().copied()).collect();
    let eighth = eighth_bit(&all);
    let mut readings = vec![(SerialMode::Rtu, None), (SerialMode::Ascii, None)];
    if eighth.is_some_and(|e| e != EighthBit::Zero) {
        readings.push((SerialMode::Ascii, eighth));
    }
    let mut out: Vec<StoredScore> = readings
        .into_iter()
        .map(|(mode, seven_bit)| {
            let stripped: Vec<(u64, Vec<u8>)>;
            let heard = if seven_bit.is_some() {
                stripped = chunks.iter().map(|(t, b)| (*t, b.iter().map(|&c| c & 0x7F).collect())).collect();
                &stripped
            } else {
                chunks
            };
            let candidate = Candidate { mode, line: recorded };
            let mut score = Score { candidate, valid_frames: 0, bad_frames: 0, noise_bytes: 0, units: BTreeSet::new() };
            count(&mut score, mode, FramerConfig::new(recorded, 0), heard);
            StoredScore { mode, seven_bit, score }
        })
        .collect();
    out.sort_by_key(|s| std::cmp::Reverse(s.score.value()));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_candidate_is_distinct_and_the_mk4_rates_are_in() {
        let c = candidates();
        assert_eq!(c.len(), BAUDS.len() * 3 * 3 * 2);
        for baud in [14_400, 56_000, 128_000, 256_000] {
            assert!(c.iter().any(|x| x.line.baud == baud));
        }
    }
}
