//! `mbtap play FILE PORT`: writes a line capture into a serial port with its timing — each
//! packet at its recorded offset from the first — so a device, a pseudo-terminal or another
//! sniffer sees the bus as it was. Blocking writes on a plain thread: `tokio::time::sleep`
//! has 1 ms granularity, too coarse for per-byte timing at 19200 baud.

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::source::serial::builder;
use mbtap_core::capture::{CaptureReader, Item};
use mbtap_core::framer::LineSettings;

/// Plays `file` into `port`; returns (packets, bytes) written.
///
/// # Errors
/// When the file or port cannot be opened or written.
pub fn play(file: &std::path::Path, port: &str, line: LineSettings, speed: f64) -> anyhow::Result<(u64, u64)> {
    let input = std::fs::File::open(file).with_context(|| format!("opening {}", file.display()))?;
    let mut out = builder(port, line).open().with_context(|| format!("opening serial port {port}"))?;
    let mut reader = CaptureReader::new(std::io::BufReader::new(input));
    let start = Instant::now();
    let mut first: Option<u64> = None;
    let (mut packets, mut bytes) = (0u64, 0u64);
    while let Some(item) = reader.next_item().context("reading the capture")? {
        match item {
            Item::Packet { t, data, .. } => {
                let t0 = *first.get_or_insert(t.0);
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss, clippy::cast_precision_loss)]
                let due = Duration::from_nanos(((t.0 - t0) as f64 / speed.max(1e-3)) as u64);
                // Sleep most of the way, then spin: thread sleeps overshoot by tens of µs.
                while let Some(left) = due.checked_sub(start.elapsed()).filter(|d| !d.is_zero()) {
                    match left.checked_sub(Duration::from_micros(200)) {
                        Some(sleep) if left > Duration::from_micros(300) => std::thread::sleep(sleep),
                        _ => std::hint::spin_loop(),
                    }
                }
                out.write_all(data).with_context(|| format!("writing to {port}"))?;
                packets += 1;
                bytes += data.len() as u64;
            }
            Item::Warning(w) => eprintln!("mbtap: warning: {w}"),
            Item::Interface { .. } => {}
        }
    }
    out.flush()?;
    Ok((packets, bytes))
}
