//! `mbtap generate-config`: a commented sample configuration for `bridge --config`.

use std::io::{self, Write};
use std::process::ExitCode;

/// Print a commented sample configuration for `bridge --config`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_: &Args) -> anyhow::Result<ExitCode> {
    io::stdout().lock().write_all(crate::bridge::config::SAMPLE.as_bytes())?;
    Ok(ExitCode::SUCCESS)
}
