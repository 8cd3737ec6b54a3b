//! Command-line definitions (clap). Parsing only; `main` dispatches.

use clap::{Parser, Subcommand, ValueEnum};

/// mbtap — a Modbus RTU/ASCII bus analyzer: sniff, decode, record, replay, bridge.
#[derive(Debug, Parser)]
#[command(name = "mbtap", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
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

#[derive(Debug, Subcommand)]
pub enum Command {
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
    Decode {
        /// Frames, one per argument (read from stdin, one per line, when none are given).
        frames: Vec<String>,
        /// Framing; detected per frame when not given (':' = ASCII, valid CRC = RTU, consistent MBAP = TCP).
        #[arg(long, value_enum)]
        mode: Option<ModeArg>,
        /// Output format.
        #[arg(long, value_enum, default_value_t = FormatArg::Text)]
        format: FormatArg,
    },
}
