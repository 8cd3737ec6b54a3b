//! `mbtap play FILE PORT`: write a capture into a port with its recorded timing.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::args::LineArgs;

#[derive(Debug, clap::Args)]
/// Play a line capture into a serial port with its recorded timing.
pub struct Args {
    /// The capture to play.
    pub file: PathBuf,
    /// The serial port to write to.
    pub port: String,
    #[command(flatten)]
    pub line: LineArgs,
    /// Speed factor (2 = twice as fast).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let Args { file, port, line, speed } = args;
    let speed = *speed;
    let (_, settings, _) = line.overrides().resolve();
    let (packets, bytes) = crate::source::play::play(file, port, settings, speed)?;
    eprintln!("mbtap: played {packets} packets ({bytes} bytes) into {port}");
    Ok(ExitCode::SUCCESS)
}
