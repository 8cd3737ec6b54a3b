//! `mbtap play FILE PORT`: write a capture into a port with its recorded timing.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::cli::args::CaptureLineArgs;

#[derive(Debug, clap::Args)]
/// Play a line capture into a serial port with its recorded timing.
pub struct Args {
    /// The capture to play.
    pub file: PathBuf,
    /// The serial port to write to.
    pub port: String,
    #[command(flatten)]
    pub line: CaptureLineArgs,
    /// Speed factor (2 = twice as fast).
    #[arg(long, default_value_t = 1.0, value_parser = crate::cli::numbers::speed)]
    pub speed: f64,
    /// Play a silence in the capture longer than this many seconds as this long (a clock step
    /// or a corrupt timestamp must not make play wait for hours).
    #[arg(long, value_name = "SECONDS", default_value_t = 5.0, value_parser = crate::cli::numbers::seconds)]
    pub max_gap: f64,
    #[command(flatten)]
    pub rs485: crate::io::rs485::Rs485Args,
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let Args { file, port, line, speed, max_gap, rs485 } = args;
    anyhow::ensure!(speed.is_finite() && *speed > 0.0, "--speed {speed}: expected a factor above 0, e.g. 1 or 10");
    anyhow::ensure!(max_gap.is_finite() && *max_gap >= 0.0, "--max-gap {max_gap}: expected seconds, 0 or more");
    let (_, settings, _) = line.overrides().resolve();
    let max_gap = std::time::Duration::from_secs_f64(max_gap.min(1e6));
    let (packets, bytes) = crate::source::play::play(file, port, settings, *speed, max_gap, *rs485)?;
    eprintln!("mbtap: played {packets} packets ({bytes} bytes) into {port}");
    Ok(ExitCode::SUCCESS)
}
