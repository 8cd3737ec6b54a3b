//! `mbtap generate`: a synthetic line capture from the traffic generator.

use std::io::Write;

use crate::analyzer::SerialMode;
use crate::capture::PcapNgWriter;
use crate::chunk::Timestamp;
use crate::framer::LineSettings;
use crate::line_args::LineOverrides;
use crate::traffic::{Observation, TrafficConfig, generate, observe};

/// Writes `cfg`'s traffic as seen through `model` to `out`; returns (chunks, bytes).
///
/// # Errors
/// I/O errors.
pub fn write_capture<W: Write>(out: W, cfg: &TrafficConfig, model: Observation) -> std::io::Result<(usize, usize)> {
    let wire = generate(cfg);
    let line: LineSettings = cfg.line;
    let chunks = observe(&wire, model, line.char_ns());
    let latency = model.latency_ns(line.char_ns());
    let mut w = PcapNgWriter::new(out)?;
    w.add_serial_interface("generated", &LineOverrides::describe(SerialMode::Rtu, line, latency))?;
    for (t, r) in &chunks {
        w.write_packet(0, Timestamp(*t), &wire.bytes[r.clone()])?;
    }
    w.flush()?;
    Ok((chunks.len(), wire.bytes.len()))
}

/// Writes `frames` (wire bytes) to `out` as a per-byte capture: each frame sent at the line's
/// character rate, 5 ms of silence between frames. Returns the bytes written.
///
/// # Errors
/// I/O errors.
pub fn write_frames<W: Write>(
    out: W,
    frames: &[Vec<u8>],
    mode: SerialMode,
    line: LineSettings,
    start_ns: u64,
) -> std::io::Result<usize> {
    let mut w = PcapNgWriter::new(out)?;
    w.add_serial_interface("frames", &LineOverrides::describe(mode, line, 0))?;
    let c = line.char_ns();
    let mut t = start_ns;
    let mut n = 0;
    for f in frames {
        for b in f {
            t += c;
            w.write_packet(0, Timestamp(t), std::slice::from_ref(b))?;
            n += 1;
        }
        t += 5_000_000;
    }
    w.flush()?;
    Ok(n)
}
