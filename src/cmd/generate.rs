//! `mbtap generate OUT`: a synthetic line capture with known content — random traffic through
//! an observation model, or a list of frames back to back.

use std::io;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::ValueEnum;
use mbtap_sim::traffic::{Observation, TrafficConfig};

use crate::cli::args::LineArgs;

#[derive(Debug, clap::Args)]
/// Write a synthetic line capture with known content (for training, tests and benchmarks).
pub struct Args {
    /// Output pcapng file.
    pub out: PathBuf,
    /// Replace the file if it is already there (without, it is kept and nothing is written).
    #[arg(long)]
    pub force: bool,
    /// Transactions to generate.
    #[arg(long, default_value_t = 1000)]
    pub transactions: usize,
    /// Random seed (the same seed gives the same file).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub line: LineArgs,
    /// How the bytes are read.
    #[arg(long, value_enum, default_value_t = ObserveArg::PerByte)]
    pub observe: ObserveArg,
    /// Probability of a noise burst before a transaction.
    #[arg(long, default_value_t = 0.02, value_parser = crate::cli::numbers::probability)]
    pub noise: f64,
    /// Probability that a frame has a corrupted byte.
    #[arg(long, default_value_t = 0.02, value_parser = crate::cli::numbers::probability)]
    pub corrupt: f64,
    /// Probability that a response pauses inside (a slow slave).
    #[arg(long, default_value_t = 0.02, value_parser = crate::cli::numbers::probability)]
    pub slow: f64,
    /// Probability that a frame is followed by a turnaround glitch byte (`00` after the
    /// master, `FE`/`FF` after a slave): a line without fail-safe biasing.
    #[arg(long, default_value_t = 0.0, value_parser = crate::cli::numbers::probability)]
    pub glitch: f64,
    /// Probability that a register-read answer is a CRC look-alike (its CRC's high byte 00).
    #[arg(long, default_value_t = 0.0, value_parser = crate::cli::numbers::probability)]
    pub lookalike: f64,
    /// Instead of random traffic, send these frames (one per line, hex or `:ASCII`, as
    /// `decode` reads them) back to back with a 5 ms turnaround, one read per byte.
    #[arg(long)]
    pub frames: Option<PathBuf>,
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    match &args.frames {
        Some(list) => frames(args, list),
        None => random(args),
    }
}

/// `--frames LIST`: the listed frames back to back.
fn frames(args: &Args, list: &Path) -> anyhow::Result<ExitCode> {
    let Args { out, line, observe, .. } = args;
    let (mode, settings, _) = line.overrides().resolve();
    let text = std::fs::read_to_string(list).with_context(|| format!("reading {}", list.display()))?;
    let mut frames = Vec::new();
    for (i, l) in text.lines().enumerate() {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let wire = mbtap_proto::hexinput::parse_frame_text(l)
            .map_err(|e| anyhow::anyhow!("{}:{}: {e}", list.display(), i + 1))?;
        frames.push(wire);
    }
    let mut file = io::BufWriter::new(crate::output::whole_file::WholeFile::create(
        out,
        crate::output::whole_file::Existing::forced(args.force),
    )?);
    let n = mbtap_sim::traffic::capture::write_frames(
        &mut file,
        &frames,
        mode,
        settings,
        1_700_000_000_000_000_000,
        model(*observe),
    )
    .with_context(|| format!("writing {}", out.display()))?;
    file.into_inner()
        .map_err(io::IntoInnerError::into_error)
        .with_context(|| format!("writing {}", out.display()))?
        .commit()?;
    eprintln!("mbtap: wrote {} ({} frames, {n} bytes, {settings} {})", out.display(), frames.len(), mode.name());
    Ok(ExitCode::SUCCESS)
}

/// Random traffic with noise, corruption and slow slaves, as the observation model reads it.
fn random(args: &Args) -> anyhow::Result<ExitCode> {
    let Args { out, transactions, seed, line, observe, noise, corrupt, slow, glitch, lookalike, .. } = args;
    let (transactions, seed) = (*transactions, *seed);
    for (name, p) in
        [("noise", noise), ("corrupt", corrupt), ("slow", slow), ("glitch", glitch), ("lookalike", lookalike)]
    {
        anyhow::ensure!((0.0..=1.0).contains(p), "--{name} {p}: expected a probability from 0 to 1");
    }
    let (_, settings, _) = line.overrides().resolve();
    let cfg = TrafficConfig {
        seed,
        line: settings,
        transactions,
        noise: *noise,
        corrupt: *corrupt,
        slow: *slow,
        glitch: *glitch,
        lookalike: *lookalike,
        ..TrafficConfig::default()
    };
    let model = model(*observe);
    let mut file = io::BufWriter::new(crate::output::whole_file::WholeFile::create(
        out,
        crate::output::whole_file::Existing::forced(args.force),
    )?);
    let (chunks, bytes) = mbtap_sim::traffic::capture::write_capture(&mut file, &cfg, model)
        .with_context(|| format!("writing {}", out.display()))?;
    file.into_inner()
        .map_err(io::IntoInnerError::into_error)
        .with_context(|| format!("writing {}", out.display()))?
        .commit()?;
    eprintln!(
        "mbtap: wrote {} ({transactions} transactions, {bytes} bytes in {chunks} packets, {settings}, {})",
        out.display(),
        model.name()
    );
    Ok(ExitCode::SUCCESS)
}

/// How the generator's bytes reach the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ObserveArg {
    /// One read per byte, exact timestamps.
    PerByte,
    /// One packet per frame, as gap-cutting sniffers write captures.
    PerFrame,
    /// 16550 UART FIFO: 14-byte trigger, 4-character timeout.
    Fifo,
    /// USB adapter, 1 ms latency timer.
    Usb1,
    /// USB adapter, 16 ms latency timer (FTDI default).
    Usb16,
}

/// The observation model an `--observe` value names.
fn model(o: ObserveArg) -> Observation {
    match o {
        ObserveArg::PerByte => Observation::PerByte,
        ObserveArg::PerFrame => Observation::PerFrame,
        ObserveArg::Fifo => Observation::FIFO_16550,
        ObserveArg::Usb1 => Observation::USB_1MS,
        ObserveArg::Usb16 => Observation::USB_16MS,
    }
}
