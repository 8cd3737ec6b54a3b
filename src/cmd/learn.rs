//! `mbtap learn CAPTURE|PORT`: a register map drafted from what a recorded or a live line says
//! ([`mbtap_analysis::learn`]): the blocks the master polls, its writes, the exceptions, and each
//! register's likely type with its evidence; `-o DRAFT.toml` writes one unit's profile and
//! `--dir DIR` one per unit, each one `profiles check` accepts. A live line is heard through the sniffer's loop
//! ([`crate::source::sniff`]) until `--duration` or Ctrl-C.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;

use crate::cli::args::CaptureLineArgs;

/// Draft a register map from a capture or a live line: blocks polled, writes, exceptions, and
/// each register's likely type (constant, counter, enumeration, bits, signed, 32-bit integers
/// and floats in either word order, text) with the evidence for it.
///
/// Example: `mbtap learn site.pcapng -o meter.toml` (one unit heard, or `--unit 7`; `--dir
/// drafts/` for one profile per unit), then `mbtap profiles check meter.toml` and
/// `mbtap replay site.pcapng --device 7=meter.toml`; `mbtap learn /dev/ttyUSB0 --duration
/// 10min -o meter.toml` listens (the drafts rewritten every 10 s while it does).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The capture (pcap or pcapng, as `sniff --record` writes), or a serial port to listen
    /// to (`/dev/ttyUSB0`, `rtu-over-tcp://HOST:PORT`) until --duration or Ctrl-C.
    pub capture: PathBuf,
    /// Listening to a port: stop after this long (`90s`, `10min`, `1h`; a bare number is
    /// seconds). Without it, until Ctrl-C.
    #[arg(long, value_name = "DURATION", value_parser = crate::cli::args::duration_arg)]
    pub duration: Option<std::time::Duration>,
    #[command(flatten)]
    pub line: CaptureLineArgs,
    /// Write the draft profile here: one unit's (a profile describes one device; with several
    /// units heard, give --unit N, or --dir).
    #[arg(short, long, value_name = "DRAFT.toml", conflicts_with = "dir")]
    pub output: Option<PathBuf>,
    /// Write a draft profile per unit heard into this directory (`learned-unit-N.toml`).
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Replace draft files that are there already (without it they are kept, and said).
    #[arg(long)]
    pub force: bool,
    /// Only this unit.
    #[arg(long)]
    pub unit: Option<u8>,
    /// What to print.
    #[arg(long, value_enum, default_value_t = Format::Text)]
    pub format: Format,
    /// A value read off the device's display when the capture ended, `UNIT:TABLE:ADDRESS=VALUE`
    /// (e.g. `1:input:430=230.4`): fixes that register's scale in the draft (repeatable).
    #[arg(long, value_name = "UNIT:TABLE:ADDRESS=VALUE", value_parser = mbtap_analysis::learn::hint::parse_hint)]
    pub hint: Vec<mbtap_analysis::learn::hint::Hint>,
    /// Where the traffic leaves registers decided by one or two samples, read those blocks again
    /// from the device here (a serial port with the line options, `HOST:PORT` for Modbus TCP,
    /// `rtu+tcp://…`): only reads (03/04) of blocks its master read, paced at --rate, for at
    /// most --confirm-for; nothing is ever written. A busy or refusing device ends it, said.
    #[arg(long, value_name = "TARGET")]
    pub confirm: Option<String>,
    /// With --confirm: requests per second, at most.
    #[arg(long, default_value_t = 2.0, value_parser = crate::cli::numbers::rate, requires = "confirm")]
    pub rate: f64,
    /// With --confirm: how long it may ask, at most (`30s`, `2min`).
    #[arg(long, value_name = "DURATION", value_parser = crate::cli::args::duration_arg, requires = "confirm")]
    pub confirm_for: Option<std::time::Duration>,
    /// With --confirm: how long to wait for each answer, ms.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=60_000), requires = "confirm")]
    pub timeout_ms: u64,
}

/// Output of `learn`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Text,
    Json,
}

/// A live line rather than a capture: a serial server's URL, or a path that is not a regular
/// file (a character device, a pseudo-terminal).
fn is_port(path: &std::path::Path) -> bool {
    let s = path.to_string_lossy();
    s.starts_with("rtu-over-tcp://")
        || s.starts_with("rtu+tcp://")
        || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// Where the drafts go: `-o FILE` or `--dir DIR`.
fn target(args: &Args) -> Option<crate::output::learn_draft::DraftTo> {
    use crate::output::learn_draft::DraftTo;
    args.output.clone().map(DraftTo::File).or_else(|| args.dir.clone().map(DraftTo::Dir))
}

/// Listens to `args.capture` as a port, the learner fed as the sniffer hears.
fn listen(args: &Args) -> anyhow::Result<mbtap_analysis::learn::Learner> {
    let (mode, settings, latency_ns) = args.line.line.overrides().resolve();
    let port = args.capture.to_string_lossy().into_owned();
    let opts = crate::source::sniff::SniffOptions {
        port: port.clone(),
        mode,
        line: settings,
        latency_ns,
        record: None,
        duration: args.duration,
    };
    let mut writer = crate::output::EventWriter::new(std::io::sink(), crate::output::EventFormat::Summary);
    let mut draft = crate::output::learn_draft::LiveDraft::new(target(args), port);
    draft.replace = crate::output::learn_draft::Replace::new(args.force);
    draft.learner.only = args.unit;
    writer.learn = Some(draft);
    crate::cmd::runtime()?
        .block_on(crate::source::sniff::sniff(opts, &mut writer, &mut std::io::stderr()))
        .map_err(crate::output::SourceError::into_error)?;
    Ok(writer.learn.take().map(|l| l.learner).unwrap_or_default())
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let mut learner = if is_port(&args.capture) {
        listen(args)?
    } else {
        anyhow::ensure!(
            args.duration.is_none(),
            "--duration is for listening to a port; {} is a capture, read whole",
            args.capture.display()
        );
        let input = crate::output::progress::open_capture(&args.capture, true)?;
        let mut learner = mbtap_analysis::learn::Learner::default();
        learner.only = args.unit;
        mbtap_analysis::replay::replay_into(input, args.line.overrides(), &mut learner)
            .with_context(|| format!("reading {}", args.capture.display()))?;
        learner
    };
    if let Some(u) = args.unit {
        learner.units.retain(|&k, _| k == u);
    }
    if let Some(note) = mbtap_analysis::learn::draft::not_kept_note(&learner) {
        eprintln!("mbtap: {note}");
    }
    anyhow::ensure!(
        !learner.units.is_empty(),
        "{}: no answered read or write{} was heard; nothing to learn from",
        args.capture.display(),
        args.unit.map(|u| format!(" of unit {u}")).unwrap_or_default()
    );
    if let Some(target) = &args.confirm {
        let opts = crate::master::confirm::ConfirmOptions {
            target: target.clone(),
            line: args.line.line.serial.clone(),
            rate: args.rate,
            limit: args.confirm_for.unwrap_or(std::time::Duration::from_secs(30)),
            timeout: std::time::Duration::from_millis(args.timeout_ms),
        };
        let said = crate::cmd::runtime()?
            .block_on(crate::master::confirm::confirm(&mut learner, &opts))
            .with_context(|| format!("--confirm {target}"))?;
        for line in said.lines() {
            eprintln!("mbtap: --confirm {target}: {line}");
        }
    }
    let mut out = std::io::stdout().lock();
    let shown = match args.format {
        Format::Text => {
            mbtap_analysis::report::format::printable(&mbtap_analysis::learn::draft::text(&learner)).into_owned()
        }
        Format::Json => String::new(),
    };
    let written = if args.format == Format::Json {
        // Streamed: a capture of many registers is never held as one JSON tree.
        let mut w = std::io::BufWriter::new(&mut out);
        serde_json::to_writer_pretty(&mut w, &mbtap_analysis::learn::draft::Json(&learner))
            .map_err(std::io::Error::from)
            .and_then(|()| w.write_all(b"\n"))
            .and_then(|()| w.flush())
    } else {
        out.write_all(shown.as_bytes())
    };
    match written {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => return Err(e).context("writing the findings"),
        _ => {}
    }
    if let Some(to) = target(args) {
        let source = args.capture.display().to_string();
        let mut replace = crate::output::learn_draft::Replace::new(args.force);
        for (unit, file) in crate::output::learn_draft::write_drafts(&learner, &to, &source, &args.hint, &mut replace)?
        {
            eprintln!(
                "mbtap: draft profile of unit {unit} written to {} (check it: mbtap profiles check)",
                file.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
