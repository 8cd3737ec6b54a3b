//! `mbtap learn CAPTURE`: a register map drafted from what a recorded line says
//! ([`mbtap_core::learn`]): the blocks the master polls, its writes, the exceptions, and each
//! register's likely type with its evidence; `-o DRAFT.toml` writes a profile per unit that
//! `profiles check` accepts.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;

use crate::args::CaptureLineArgs;

/// Draft a register map from a capture: blocks polled, writes, exceptions, and each register's
/// likely type (constant, counter, enumeration, bits, signed, 32-bit integers and floats in
/// either word order, text) with the evidence for it.
///
/// Example: `mbtap learn site.pcapng -o meter.toml`, then `mbtap profiles check meter.toml` and
/// `mbtap replay site.pcapng --device 7=meter.toml`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The capture (pcap or pcapng, as `sniff --record` writes).
    pub capture: PathBuf,
    #[command(flatten)]
    pub line: CaptureLineArgs,
    /// Write the draft profile here (one unit heard), or `NAME-unit-N.toml` beside it per unit.
    #[arg(short, long, value_name = "DRAFT.toml")]
    pub output: Option<PathBuf>,
    /// Only this unit.
    #[arg(long)]
    pub unit: Option<u8>,
    /// What to print.
    #[arg(long, value_enum, default_value_t = Format::Text)]
    pub format: Format,
    /// A value read off the device's display when the capture ended, `UNIT:TABLE:ADDRESS=VALUE`
    /// (e.g. `1:input:430=230.4`): fixes that register's scale in the draft (repeatable).
    #[arg(long, value_name = "UNIT:TABLE:ADDRESS=VALUE", value_parser = mbtap_core::learn::hint::parse_hint)]
    pub hint: Vec<mbtap_core::learn::hint::Hint>,
}

/// Output of `learn`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Text,
    Json,
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let input = crate::output::progress::open_capture(&args.capture, true)?;
    let mut learner = mbtap_core::learn::Learner::default();
    mbtap_core::replay::replay_into(input, args.line.overrides(), &mut learner)
        .with_context(|| format!("reading {}", args.capture.display()))?;
    if let Some(u) = args.unit {
        learner.units.retain(|&k, _| k == u);
    }
    anyhow::ensure!(
        !learner.units.is_empty(),
        "{}: no answered read or write{} was heard; nothing to learn from",
        args.capture.display(),
        args.unit.map(|u| format!(" of unit {u}")).unwrap_or_default()
    );
    let mut out = std::io::stdout().lock();
    let shown = match args.format {
        Format::Text => mbtap_core::report::format::printable(&mbtap_core::learn::draft::text(&learner)).into_owned(),
        Format::Json => serde_json::to_string_pretty(&mbtap_core::learn::draft::json(&learner))? + "\n",
    };
    match out.write_all(shown.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => return Err(e).context("writing the findings"),
        _ => {}
    }
    if let Some(path) = &args.output {
        let source = args.capture.display().to_string();
        for (unit, file) in crate::output::learn_draft::write_drafts(&learner, path, &source, &args.hint)? {
            eprintln!(
                "mbtap: draft profile of unit {unit} written to {} (check it: mbtap profiles check)",
                file.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
