//! `mbtap scan PORT`: opens a live port at each baud rate, parity and character size in turn,
//! listens for a while, and ranks the settings by the valid frames they give
//! ([`crate::scan`]). Bounded: `--dwell-ms` per setting, stopping early once a setting
//! decodes the bus cleanly.

use std::io::Write;
use std::time::Duration;

use anyhow::Context;
use tokio::io::AsyncReadExt;
use tokio_serial::SerialPortBuilderExt;

use crate::analyzer::SerialMode;
use crate::framer::{LineSettings, Parity};
use crate::scan::{BAUDS, Candidate, Score, rank, score};

/// A setting that decodes this many frames with no garbage ends the scan early.
const CLEAN_ENOUGH: i64 = 6;

/// Scans `port`; the ranked scores.
///
/// # Errors
/// When the port cannot be opened at all.
pub async fn scan(port: &str, bauds: &[u32], dwell: Duration, err: &mut dyn Write) -> anyhow::Result<Vec<Score>> {
    let bauds = if bauds.is_empty() { BAUDS.to_vec() } else { bauds.to_vec() };
    let mut scores = Vec::new();
    'all: for &baud in &bauds {
        for parity in [Parity::Even, Parity::None, Parity::Odd] {
            for data_bits in [8u8, 7] {
                let line = LineSettings { baud, data_bits, parity, stop_bits: 1 };
                let mut p = crate::source::serial::builder(port, line)
                    .open_native_async()
                    .with_context(|| format!("opening {port} at {line}"))?;
                let heard = listen(&mut p, dwell).await;
                drop(p);
                let modes: &[SerialMode] =
                    if data_bits == 8 { &[SerialMode::Rtu, SerialMode::Ascii] } else { &[SerialMode::Ascii] };
                for &mode in modes {
                    // A receiver with one stop bit hears a two-stop-bit sender too; score both
                    // so the tie rule can prefer what the serial-line spec prescribes.
                    for stop_bits in [1, 2] {
                        let c = Candidate { mode, line: LineSettings { stop_bits, ..line } };
                        let s = score(c, &heard);
                        if stop_bits == 1 && s.valid_frames > 0 {
                            let _ = writeln!(
                                err,
                                "mbtap: {line} {}: {} valid frames, {} failed, {} noise bytes",
                                mode.name(),
                                s.valid_frames,
                                s.bad_frames,
                                s.noise_bytes
                            );
                        }
                        let clean = s.value() >= CLEAN_ENOUGH && s.bad_frames == 0 && s.noise_bytes == 0;
                        scores.push(s);
                        if clean && stop_bits == 2 {
                            break 'all;
                        }
                    }
                }
            }
        }
    }
    rank(&mut scores);
    Ok(scores)
}

/// Reads for `dwell`; the chunks with their arrival times.
async fn listen(port: &mut tokio_serial::SerialStream, dwell: Duration) -> Vec<(u64, Vec<u8>)> {
    let deadline = tokio::time::Instant::now() + dwell;
    let mut out = Vec::new();
    let mut buf = [0u8; 1024];
    while let Ok(Ok(n)) = tokio::time::timeout_at(deadline, port.read(&mut buf)).await {
        if n == 0 {
            break;
        }
        out.push((crate::source::serial::now().0, buf.get(..n).unwrap_or_default().to_vec()));
    }
    out
}

/// The result for people: the best setting and the units heard, then the runners-up.
#[must_use]
pub fn describe(scores: &[Score]) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    match scores.first().filter(|b| b.valid_frames > 0) {
        None => s.push_str("no setting gave a valid Modbus frame: is the bus silent, or the wiring (A/B) swapped?\n"),
        Some(best) => {
            let units: Vec<String> = best.units.iter().map(u8::to_string).collect();
            let _ = writeln!(
                s,
                "best: {} {} — {} valid frames, {} failed, {} noise bytes; units heard: {}",
                best.candidate.line,
                best.candidate.mode.name(),
                best.valid_frames,
                best.bad_frames,
                best.noise_bytes,
                units.join(", ")
            );
            for r in scores.iter().skip(1).take(3).filter(|r| r.valid_frames > 0) {
                let _ = writeln!(
                    s,
                    "  then: {} {} — {} valid, {} failed, {} noise bytes",
                    r.candidate.line,
                    r.candidate.mode.name(),
                    r.valid_frames,
                    r.bad_frames,
                    r.noise_bytes
                );
            }
        }
    }
    s
}
