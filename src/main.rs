//! The `mbtap` binary: parse the command line, dispatch, map outcomes to exit codes.

use std::io::{self, BufRead, Write};
use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use mbtap::cli::{Cli, Command, FormatArg, ModeArg};
use mbtap::decode_cmd::{self, Format};
use mbtap::proto::Mode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            // A closed pipe (`mbtap decode ... | head`) is not a failure.
            if e.downcast_ref::<io::Error>().is_some_and(|io| io.kind() == io::ErrorKind::BrokenPipe) {
                return ExitCode::SUCCESS;
            }
            eprintln!("mbtap: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Decode { frames, mode, format } => {
            let lines = if frames.is_empty() {
                io::stdin()
                    .lock()
                    .lines()
                    .collect::<Result<Vec<_>, _>>()
                    .context("reading frames from stdin")?
                    .into_iter()
                    .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
                    .collect()
            } else {
                frames
            };
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
            let outcome = decode_cmd::run(&lines, mode, format, &mut out, &mut io::stderr())?;
            out.flush()?;
            Ok(ExitCode::from(outcome as u8))
        }
    }
}
