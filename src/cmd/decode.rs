//! `mbtap decode`: frames typed or pasted as text, explained ([`mbtap_analysis::decode`]).

use std::io::{self, Write};
use std::process::ExitCode;

use anyhow::Context;
use clap::ValueEnum;
use mbtap_analysis::decode::{self as decode_cmd, Format};
use mbtap_analysis::decode_lines::{Line, Lines, MAX_LINE};
use mbtap_proto::Mode;

use crate::cli::args::LangArg;

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
    /// Frames, one per argument (read from stdin, one per line, when none are given or the
    /// only one is `-`, as other Unix tools take it).
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

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { frames, mode, format, devices, lang } = args;
    let profiles = crate::config::devices::load_devices(&devices)?;
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
    if frames.is_empty() || frames == ["-"] {
        // Streamed: a line in, its result out, in constant memory (`tail -f log | mbtap decode`).
        let stdin = io::stdin();
        let mut lines = Lines::new(io::BufReader::new(stdin.lock()));
        while let Some(line) = lines.next_line().context("reading frames from stdin")? {
            let Line { number, text, cut } = line;
            if cut {
                writeln!(err, "mbtap: line {number} is longer than {MAX_LINE} characters: cut, not read as a frame")?;
            }
            if text.trim().is_empty() || text.trim_start().starts_with('#') {
                continue;
            }
            decoder.line(&text, &mut out, &mut err)?;
            if lines.get_ref().buffer().is_empty() {
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
