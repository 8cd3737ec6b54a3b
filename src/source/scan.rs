//! `mbtap scan PORT`: opens a live port at each baud rate, parity and character size in turn,
//! listens for a while, and ranks the settings by the valid frames they give
//! ([`mbtap_analysis::scan`]). Bounded: `--dwell-ms` per setting, stopping early once a setting
//! decodes the bus cleanly.

use std::io::Write;
use std::time::Duration;

use anyhow::Context;
use tokio::io::AsyncReadExt;
use tokio_serial::SerialPortBuilderExt;

use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::framer::{LineSettings, Parity};
use mbtap_analysis::scan::{BAUDS, Candidate, Score, rank, score};

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
                let mut p = crate::io::serial::builder(port, line)
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
        out.push((crate::io::serial::now().0, buf.get(..n).unwrap_or_default().to_vec()));
    }
    out
}

/// The result for people: the best setting and the units heard, then the runners-up.
#[must_use]
pub fn describe(scores: &[Score]) -> String {
    let mut s = String::new();
    let tie = mbtap_analysis::scan::tied_stop_bits(scores);
    let ranked = scores.iter().enumerate().map(|(i, r)| {
        let label = format!("{} {}", r.candidate.line, r.candidate.mode.name());
        match tie {
            // A second stop bit is idle line to a one-stop-bit receiver: both read the same.
            Some(other) if i == 0 => (
                format!(
                    "{label} (or {other} stop bits: they read alike when listening; set what the devices' manuals say)"
                ),
                r,
            ),
            _ => (label, r),
        }
    });
    if !write_ranked(&mut s, ranked, 3) {
        s.push_str("no setting gave a valid Modbus frame: is the bus silent, or the wiring (A/B) swapped?\n");
    }
    s
}

/// Writes the best reading with the units heard and up to `more` runners-up that gave valid
/// frames; false when none did.
fn write_ranked<'a>(s: &mut String, mut ranked: impl Iterator<Item = (String, &'a Score)>, more: usize) -> bool {
    use std::fmt::Write as _;
    let Some((label, best)) = ranked.next().filter(|(_, b)| b.valid_frames > 0) else { return false };
    let units: Vec<String> = best.units.iter().map(u8::to_string).collect();
    let _ = writeln!(
        s,
        "best: {label} — {} valid frames, {} failed, {} noise bytes; units heard: {}",
        best.valid_frames,
        best.bad_frames,
        best.noise_bytes,
        units.join(", ")
    );
    for (label, r) in ranked.take(more).filter(|(_, r)| r.valid_frames > 0) {
        let _ = writeln!(
            s,
            "  then: {label} — {} valid, {} failed, {} noise bytes",
            r.valid_frames, r.bad_frames, r.noise_bytes
        );
    }
    true
}

/// Stored bytes read at most: enough frames to judge by, bounded memory on any file.
const STORED_MAX: usize = 16 << 20;

/// `mbtap scan FILE`: the readings of a capture (pcap/pcapng, with its timing and recorded
/// settings) or of a raw dump of received bytes; the description for people and whether any
/// reading gave a valid frame.
///
/// # Errors
/// When the file cannot be read.
pub fn scan_file(path: &std::path::Path) -> anyhow::Result<(String, bool)> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(STORED_MAX as u64).read_to_end(&mut bytes))
        .with_context(|| format!("reading {}", path.display()))?;
    // pcapng section header; pcap in either byte order, µs or ns timestamps.
    let capture = bytes.get(..4).and_then(|h| <[u8; 4]>::try_from(h).ok()).is_some_and(|h| {
        matches!(u32::from_le_bytes(h), 0x0A0D_0D0A | 0xA1B2_C3D4 | 0xD4C3_B2A1 | 0xA1B2_3C4D | 0x4D3C_B2A1)
    });
    let (chunks, recorded) = if capture {
        read_capture(&bytes).with_context(|| format!("reading {}", path.display()))?
    } else {
        (vec![(0, bytes)], None)
    };
    let total: usize = chunks.iter().map(|(_, b)| b.len()).sum();
    let ranked = mbtap_analysis::scan::scan_stored(&chunks, recorded.unwrap_or_default());
    let ok = ranked.first().is_some_and(|b| b.score.valid_frames > 0);
    Ok((describe_stored(&ranked, recorded, total, capture), ok))
}

/// Stored chunks: (time ns, bytes).
type Chunks = Vec<(u64, Vec<u8>)>;

/// The packets of a capture (merged in time order) and the line settings it was recorded at.
fn read_capture(file: &[u8]) -> anyhow::Result<(Chunks, Option<LineSettings>)> {
    let mut reader = mbtap_analysis::capture::CaptureReader::new(file);
    let mut chunks = Vec::new();
    let mut recorded = None;
    while let Some(item) = reader.next_item()? {
        match item {
            mbtap_analysis::capture::Item::Interface { interface, .. } if recorded.is_none() => {
                let described = mbtap_analysis::line_args::LineOverrides::from_description(
                    interface.description.as_deref().unwrap_or_default(),
                );
                if described.baud.is_some() {
                    recorded = Some(described.resolve().1);
                }
            }
            mbtap_analysis::capture::Item::Packet { t, data, .. } => chunks.push((t.0, data.to_vec())),
            _ => {}
        }
    }
    chunks.sort_by_key(|(t, _)| *t);
    Ok((chunks, recorded))
}

/// The readings of stored bytes, for people.
fn describe_stored(
    ranked: &[mbtap_analysis::scan::StoredScore],
    recorded: Option<LineSettings>,
    bytes: usize,
    capture: bool,
) -> String {
    use mbtap_analysis::scan::EighthBit;
    use std::fmt::Write as _;
    let mut s = String::new();
    let what = if capture { "bytes of capture" } else { "raw bytes (no timing: framed by structure and check)" };
    let at = recorded.map_or_else(String::new, |l| format!(", recorded at {l}"));
    let _ = writeln!(s, "{bytes} {what}{at}");
    let reading = |r: &mbtap_analysis::scan::StoredScore| match r.seven_bit {
        None => r.mode.name().to_owned(),
        Some(EighthBit::Even) => {
            "ascii, 7 data bits + even parity stored as the 8th bit (a 7E1 line recorded at 8N1)".into()
        }
        Some(EighthBit::Odd) => {
            "ascii, 7 data bits + odd parity stored as the 8th bit (a 7O1 line recorded at 8N1)".into()
        }
        Some(EighthBit::One) => {
            "ascii, 7 data bits + a stop bit stored as the 8th bit (a 7N2 line recorded at 8N1)".into()
        }
        Some(EighthBit::Zero | EighthBit::Mixed) => "ascii, 7 data bits (8th bit ignored)".into(),
    };
    if !write_ranked(&mut s, ranked.iter().map(|r| (reading(r), &r.score)), ranked.len()) {
        s.push_str(
            "no reading gave a valid Modbus frame: the bytes were recorded at the wrong baud rate or parity, and what \
             a wrong receiver lost cannot be re-read at other settings — scan the live port (mbtap scan /dev/ttyUSB0)\n",
        );
    } else if ranked.first().is_some_and(|b| b.score.bad_frames + b.score.noise_bytes / 8 > b.score.valid_frames) {
        s.push_str(
            "  mostly garbage even so: the recording's baud rate or parity is probably wrong; scan the live port\n",
        );
    }
    s
}
