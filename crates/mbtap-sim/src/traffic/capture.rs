//! Synthetic traffic written as a line capture (the work of `mbtap generate`).

use std::io::Write;

use crate::traffic::generate::{Truth, TruthKind};
use crate::traffic::{Observation, TrafficConfig, Wire, generate, observe};
use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::capture::PcapNgWriter;
use mbtap_analysis::chunk::Timestamp;
use mbtap_analysis::framer::LineSettings;
use mbtap_analysis::line_args::LineOverrides;

/// Transactions generated at a time: memory stays bounded however long the capture.
const BATCH: usize = 100_000;

/// Writes `cfg`'s traffic as seen through `model` to `out`; returns (chunks, bytes). Long
/// captures are generated in batches of [`BATCH`] transactions (batch `i` uses seed `seed + i`
/// and starts where the previous one ended), so a gigabyte file needs no gigabytes of memory.
///
/// # Errors
/// I/O errors.
pub fn write_capture<W: Write>(out: W, cfg: &TrafficConfig, model: Observation) -> std::io::Result<(usize, usize)> {
    let line: LineSettings = cfg.line;
    let latency = model.latency_ns(line.char_ns());
    let mut w = PcapNgWriter::new(out)?;
    w.add_serial_interface("generated", &LineOverrides::describe(SerialMode::Rtu, line, latency))?;
    let (mut chunks_total, mut bytes_total) = (0, 0);
    let mut start_ns = cfg.start_ns;
    let mut left = cfg.transactions;
    let mut batch = 0u64;
    while left > 0 || batch == 0 {
        let n = left.min(BATCH);
        let bcfg = TrafficConfig { seed: cfg.seed.wrapping_add(batch), transactions: n, start_ns, ..*cfg };
        let wire = generate(&bcfg);
        let chunks = observe(&wire, model, line.char_ns());
        for (t, r) in &chunks {
            w.write_packet(0, Timestamp(*t), &wire.bytes[r.clone()])?;
        }
        chunks_total += chunks.len();
        bytes_total += wire.bytes.len();
        // The next batch starts after this one's last read, with an idle gap.
        start_ns = chunks.last().map_or(start_ns, |(t, _)| *t) + 100_000_000;
        left -= n;
        batch += 1;
        if n == 0 {
            break;
        }
    }
    w.flush()?;
    Ok((chunks_total, bytes_total))
}

/// Writes `frames` (wire bytes; a line may hold glitch bytes around its frame) to `out` as
/// `model` reads them: each frame sent at the line's character rate, 5 ms of silence between
/// frames. Returns the bytes written.
///
/// # Errors
/// I/O errors.
pub fn write_frames<W: Write>(
    out: W,
    frames: &[Vec<u8>],
    mode: SerialMode,
    line: LineSettings,
    start_ns: u64,
    model: Observation,
) -> std::io::Result<usize> {
    let c = line.char_ns();
    let mut wire = Wire::default();
    let mut t = start_ns;
    for f in frames {
        let start = wire.bytes.len();
        for &b in f {
            t += c;
            wire.bytes.push(b);
            wire.end_ns.push(t);
        }
        wire.truth.push(Truth { kind: TruthKind::Good, start, end: wire.bytes.len(), is_request: false });
        t += 5_000_000;
    }
    let mut w = PcapNgWriter::new(out)?;
    w.add_serial_interface("frames", &LineOverrides::describe(mode, line, model.latency_ns(c)))?;
    for (t, r) in observe(&wire, model, c) {
        w.write_packet(0, Timestamp(t), &wire.bytes[r])?;
    }
    w.flush()?;
    Ok(wire.bytes.len())
}
