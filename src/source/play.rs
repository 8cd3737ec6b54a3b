//! `mbtap play FILE PORT`: writes a line capture into a serial port with its timing — each
//! packet at its recorded offset from the first — so a device, a pseudo-terminal or another
//! sniffer sees the bus as it was. Blocking writes on a plain thread: `tokio::time::sleep`
//! has 1 ms granularity, too coarse for per-byte timing at 19200 baud.

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::io::serial::builder;
use mbtap_analysis::capture::{CaptureReader, Item};
use mbtap_analysis::framer::LineSettings;

/// Plays `file` into `port`; returns (packets, bytes) written. A silence in the capture longer
/// than `max_gap` (a clock step, a corrupt timestamp, a night without traffic) is played as
/// `max_gap`, and said.
///
/// # Errors
/// When the file or port cannot be opened or written.
pub fn play(
    file: &std::path::Path,
    port: &str,
    line: LineSettings,
    speed: f64,
    max_gap: Duration,
    rs485: crate::io::rs485::Rs485Args,
) -> anyhow::Result<(u64, u64)> {
    let input = crate::output::progress::open_capture(file, true)?;
    rs485.prepare(port)?;
    let mut out = builder(port, line).open().with_context(|| format!("opening serial port {port}"))?;
    let mut reader = CaptureReader::new(std::io::BufReader::new(input));
    let start = Instant::now();
    let max_gap_ns = u64::try_from(max_gap.as_nanos()).unwrap_or(u64::MAX);
    // Capture time played so far (gaps capped), and the previous packet's recorded time.
    let (mut played_ns, mut prev): (u64, Option<u64>) = (0, None);
    let mut capped = 0u64;
    let (mut packets, mut bytes) = (0u64, 0u64);
    while let Some(item) = reader.next_item().context("reading the capture")? {
        match item {
            Item::Packet { t, data, .. } => {
                let gap = prev.map_or(0, |p| t.0.saturating_sub(p));
                prev = Some(t.0);
                if gap > max_gap_ns {
                    capped += 1;
                    if capped <= 3 {
                        eprintln!(
                            "mbtap: {:.1} s of silence in the capture before packet {} played as {:.1} s (--max-gap){}",
                            Duration::from_nanos(gap).as_secs_f64(),
                            packets + 1,
                            max_gap.as_secs_f64(),
                            if capped == 3 { "; further ones are only counted" } else { "" }
                        );
                    }
                }
                played_ns = played_ns.saturating_add(gap.min(max_gap_ns));
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss, clippy::cast_precision_loss)]
                let due = Duration::from_secs_f64((played_ns as f64 / 1e9 / speed.max(1e-3)).min(1e9));
                // Sleep most of the way, then spin: thread sleeps overshoot by tens of µs.
                while let Some(left) = due.checked_sub(start.elapsed()).filter(|d| !d.is_zero()) {
                    match left.checked_sub(Duration::from_micros(200)) {
                        Some(sleep) if left > Duration::from_micros(300) => std::thread::sleep(sleep),
                        _ => std::hint::spin_loop(),
                    }
                }
                // With --rs485 rts, RTS is raised around each packet as it was read.
                rs485.send_blocking(&mut *out, data).with_context(|| format!("writing to {port}"))?;
                packets += 1;
                bytes += data.len() as u64;
            }
            Item::Warning(w) => {
                crate::output::progress::clear_line();
                eprintln!("mbtap: warning: {w}");
            }
            Item::Interface { .. } => {}
        }
    }
    out.flush()?;
    if capped > 3 {
        eprintln!("mbtap: {capped} silences longer than {:.1} s were shortened in all", max_gap.as_secs_f64());
    }
    Ok((packets, bytes))
}
