//! `mbtap decode`: frames typed or pasted as text, explained ([`mbtap_core::decode`]).

use std::io::{self, BufRead, Read, Write};
use std::process::ExitCode;

use anyhow::Context;
use clap::ValueEnum;
use mbtap_core::decode::{self as decode_cmd, Format};
use mbtap_core::proto::Mode;

use crate::args::LangArg;

#[derive(Debug, clap::Args)]
/// Explain Modbus frames given as hex (RTU, TCP) or ASCII (`:...`).
///
/// Frames come as arguments, or one per line on stdin when there are none. Spaces, `0x`
/// prefixes and separators (, ; - _ |) are tolerated. A request followed by its response is
/// shown as one transaction.
///
/// Exit status: 0 every frame decoded and passed its check; 1 a check failed or a PDU does
/// not fit its function code; 2 some input is not a frame at all.
#[command(
    after_help = "Examples:\n  mbtap decode \"01 03 06 00 00 00 00 01 90 20 89\"\n  mbtap decode ':01030065000394'\n  mbtap decode 010300650003 15D4 0103060000000001902089\n  echo 0183030131 | mbtap decode --format jsonl"
)]
pub struct Args {
    /// Frames, one per argument (read from stdin, one per line, when none are given).
    pub frames: Vec<String>,
    /// Framing; detected per frame when not given (':' = ASCII, valid CRC = RTU, consistent MBAP = TCP).
    #[arg(long, value_enum)]
    pub mode: Option<ModeArg>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = FormatArg::Text)]
    pub format: FormatArg,
    /// Annotate unit UNIT's values with a profile: `UNIT=NAME` (built-in, see `profiles
    /// list`) or `UNIT=FILE.toml` (repeatable).
    #[arg(long = "device", value_name = "UNIT=PROFILE")]
    pub devices: Vec<String>,
    /// Language of register names in annotations.
    #[arg(long, value_enum, default_value_t = LangArg::En)]
    pub lang: LangArg,
}

/// A line longer than this is no frame (the longest, an ASCII frame, is 513 characters; hex
/// of 256 bytes with separators and a log's timestamp stays well under it): it is cut, and said.
const MAX_LINE: usize = 4096;

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { frames, mode, format, devices, lang } = args;
    let profiles = crate::devices::load_devices(&devices)?;
    let mode = mode.map(|m| match m {
        ModeArg::Rtu => Mode::Rtu,
        ModeArg::Ascii => Mode::Ascii,
        ModeArg::Tcp => Mode::Tcp,
    });
    let format = match format {
        FormatArg::Text => Format::Text,
        FormatArg::Jsonl => Format::Jsonl,
    };
    let stdout = io::stdout();
    let mut out = io::BufWriter::new(stdout.lock());
    let mut err = io::stderr();
    let mut decoder = decode_cmd::Decoder::new(mode, format, &profiles, lang.into());
    if frames.is_empty() {
        // Streamed: a line in, its result out, in constant memory (`tail -f log | mbtap decode`).
        let stdin = io::stdin();
        let mut reader = io::BufReader::new(stdin.lock());
        let mut buf = Vec::with_capacity(256);
        let mut number = 0usize;
        loop {
            buf.clear();
            let n = (&mut reader)
                .take(MAX_LINE as u64 + 1)
                .read_until(b'\n', &mut buf)
                .context("reading frames from stdin")?;
            if n == 0 {
                break;
            }
            number += 1;
            if buf.last() != Some(&b'\n') && n > MAX_LINE {
                // Skip the rest of the line without holding it.
                let mut rest = Vec::new();
                loop {
                    rest.clear();
                    let m = (&mut reader).take(64 * 1024).read_until(b'\n', &mut rest)?;
                    if m == 0 || rest.last() == Some(&b'\n') {
                        break;
                    }
                }
                writeln!(err, "mbtap: line {number} is longer than {MAX_LINE} characters: cut, not read as a frame")?;
                buf.truncate(MAX_LINE);
            }
            // Bytes, not text: a Latin-1 comment must not stop the input (the line is named when
            // such bytes stand where a frame's digits should).
            let line = String::from_utf8_lossy(&buf);
            let line = line.trim_end_matches(['\n', '\r']);
            if line.trim().is_empty() || line.trim_start().starts_with('#') {
                continue;
            }
            decoder.line(line, &mut out, &mut err)?;
            if reader.buffer().is_empty() {
                out.flush()?;
            }
        }
    } else {
        for f in &frames {
            decoder.line(f, &mut out, &mut err)?;
        }
    }
    let outcome = decoder.finish(&mut out, &mut err)?;
    out.flush()?;
    Ok(ExitCode::from(outcome as u8))
}

/// Framing of the frames given to `decode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    Rtu,
    Ascii,
    Tcp,
}

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// Human-readable text.
    Text,
    /// One JSON object per line.
    Jsonl,
}
