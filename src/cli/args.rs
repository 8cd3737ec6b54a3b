//! Command-line pieces more than one command takes: line settings, output options, languages,
//! faults, and how their values become the library's types. Each command's own options live in
//! its file under `cmd/`.

use clap::{Args, ValueEnum};
use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::framer::Parity;
use mbtap_analysis::line_args::LineOverrides;

use crate::output::{EventFormat, EventWriter};

/// Language of names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LangArg {
    /// English.
    En,
    /// The document's original (Russian) names.
    Ru,
}

impl From<LangArg> for mbtap_device::profile::annotate::Lang {
    fn from(l: LangArg) -> Self {
        match l {
            LangArg::En => Self::En,
            LangArg::Ru => Self::Ru,
        }
    }
}

/// Serial mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SerialModeArg {
    Rtu,
    Ascii,
}

/// Parity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ParityArg {
    None,
    Even,
    Odd,
}

/// Output of analyzer commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EventFormatArg {
    /// One line per frame, noise burst and transaction.
    Text,
    /// One JSON object per line (`event`: frame, noise, transaction, warning, summary).
    Jsonl,
    /// Only the summary at the end.
    Summary,
    /// The terminal UI: traffic, detail, devices and registers views (needs a terminal).
    Tui,
}

/// Line settings (each one overrides what a capture file stores).
#[derive(Debug, Clone, Args)]
pub struct LineArgs {
    #[command(flatten)]
    pub serial: SerialLineArgs,
    /// How late the adapter may deliver a byte, in ms (FTDI default latency timer: 16).
    /// Timing gaps shorter than this are not trusted. Not given, it is also learned from the
    /// valid frames (a delayed read inside one shows the delay; the summary says what was
    /// learned); given, it is kept. [default: live ports: the adapter's latency timer, at least
    /// 1 ms; captures: what they were recorded with; else 0]
    #[arg(long, value_parser = crate::cli::numbers::millis)]
    pub latency_ms: Option<f64>,
}

/// Line settings of a command that reads a capture: those of [`LineArgs`], each one over what
/// the capture stores, and which link types carry serial bytes. Live commands (`simulate`,
/// `bridge`, `sniff`, `tap`) take [`LineArgs`] alone: no option that cannot apply to them is
/// listed in their help.
#[derive(Debug, Clone, Args)]
pub struct CaptureLineArgs {
    /// Mode, baud rate, parity, stop and data bits not given are what the capture stores (then
    /// the serial-line defaults).
    #[command(flatten)]
    pub line: LineArgs,
    /// Read a capture's interfaces of this link type as raw serial bytes too (147–162, the
    /// user link types, always are).
    #[arg(long, value_name = "DLT")]
    pub link_type: Option<u16>,
}

impl CaptureLineArgs {
    /// These settings over whatever the capture supplies.
    #[must_use]
    pub fn overrides(&self) -> LineOverrides {
        LineOverrides { link_type: self.link_type, ..self.line.overrides() }
    }
}

/// The settings of a serial line a master speaks on (`read`, `write`, `watch`) or anything
/// listens to (inside [`LineArgs`]).
#[derive(Debug, Args, Clone, Default)]
pub struct SerialLineArgs {
    /// RTU or ASCII framing [default: rtu].
    #[arg(long, value_enum)]
    pub mode: Option<SerialModeArg>,
    /// Baud rate [default: 19200].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: Option<u32>,
    /// Parity [default: even, as the serial-line spec says].
    #[arg(long, value_enum)]
    pub parity: Option<ParityArg>,
    /// Stop bits (1 or 2) [default: 1].
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub stop_bits: Option<u8>,
    /// Data bits (7 or 8) [default: 8 for RTU, 7 for ASCII].
    #[arg(long, value_parser = clap::value_parser!(u8).range(7..=8))]
    pub data_bits: Option<u8>,
}

impl SerialLineArgs {
    /// A line given whole (`--mirror-line "9600 8N1"`) as these options, with its framing.
    #[must_use]
    pub fn whole(settings: mbtap_proto::serial_line::LineSettings, mode: Option<SerialModeArg>) -> Self {
        Self {
            mode,
            baud: Some(settings.baud),
            parity: Some(match settings.parity {
                Parity::None => ParityArg::None,
                Parity::Even => ParityArg::Even,
                Parity::Odd => ParityArg::Odd,
            }),
            stop_bits: Some(settings.stop_bits),
            data_bits: Some(settings.data_bits),
        }
    }

    /// These settings over whatever a capture or a default supplies.
    #[must_use]
    pub fn overrides(&self) -> LineOverrides {
        let a = self;
        LineOverrides {
            mode: a.mode.map(|m| match m {
                SerialModeArg::Rtu => SerialMode::Rtu,
                SerialModeArg::Ascii => SerialMode::Ascii,
            }),
            baud: a.baud,
            data_bits: a.data_bits,
            parity: a.parity.map(|p| match p {
                ParityArg::None => Parity::None,
                ParityArg::Even => Parity::Even,
                ParityArg::Odd => Parity::Odd,
            }),
            stop_bits: a.stop_bits,
            ..LineOverrides::default()
        }
    }
}

impl LineArgs {
    /// These settings over whatever a capture or a default supplies.
    #[must_use]
    pub fn overrides(&self) -> LineOverrides {
        let a = self;
        LineOverrides {
            // Milliseconds given by a person; negative or absurd values clamp to 0..=10 s.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            latency_ns: a.latency_ms.map(|ms| (ms.clamp(0.0, 10_000.0) * 1e6) as u64),
            ..self.serial.overrides()
        }
    }
}

/// What `sniff`, `tap` and `replay` show, and how.
#[derive(Debug, Args)]
pub struct OutputArgs {
    /// Output format.
    #[arg(long, value_enum, default_value_t = EventFormatArg::Text)]
    pub format: EventFormatArg,
    /// Annotate unit UNIT's values with a profile: `UNIT=NAME` or `UNIT=FILE.toml` (repeatable).
    #[arg(long = "device", value_name = "UNIT=PROFILE")]
    pub devices: Vec<String>,
    /// Language of register names in annotations.
    #[arg(long, value_enum, default_value_t = LangArg::En)]
    pub lang: LangArg,
    /// End (end of file, Ctrl-C or --duration) with the bus health report, as `mbtap report`
    /// gives it.
    #[arg(long)]
    pub report: bool,
    /// Also give the report so far every SECONDS of bus time, while it runs (implies --report).
    #[arg(long, value_name = "SECONDS", value_parser = crate::cli::numbers::seconds)]
    pub report_every: Option<f64>,
    /// Draft a register map from what is heard, as `mbtap learn` does, and keep it up to date
    /// (rewritten every 10 s of line time and at the end): in this file, the first unit's
    /// profile; or, given a directory (ending in `/`, or one that exists), `learned-unit-N.toml`
    /// there for every unit heard.
    #[arg(long, value_name = "DRAFT.toml|DIR/")]
    pub learn: Option<std::path::PathBuf>,
    /// Replace `--learn` drafts that are there already (without it they are kept, and said).
    #[arg(long, requires = "learn")]
    pub learn_force: bool,
    #[command(flatten)]
    pub publish: crate::publish::PublishArgs,
}

/// What the live listening commands (`sniff`, `tap`) take beside their ports.
#[derive(Debug, clap::Args)]
pub struct LiveArgs {
    #[command(flatten)]
    pub line: LineArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Record every read to this pcapng file, flushed each second (`tap`: both directions, an
    /// interface each), which `replay` shows exactly as this session did.
    #[arg(long)]
    pub record: Option<std::path::PathBuf>,
    /// Stop after this long: `90s`, `2min`, `1h`, `500ms` (a bare number is seconds).
    #[arg(long, value_name = "DURATION", value_parser = duration_arg)]
    pub duration: Option<std::time::Duration>,
}

/// A fault to inject on the simulated line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FaultArg {
    /// A flipped bit in a response: bad CRC.
    Corrupt,
    /// A burst of random bytes on the idle line.
    Noise,
    /// A slave pausing in the middle of its answer (gap inside a frame).
    SlowSlave,
    /// A slave that does not answer (the master times out).
    SilentSlave,
    /// A second device on the first unit's address answering with it.
    Collision,
    /// A master polling again before t3.5 of silence.
    FastMaster,
    /// A second master sending its own request while the first one's answer is due.
    SecondMaster,
    /// The MK4's running pump trips on overcurrent; its alarm log records it.
    PumpTrip,
    /// All of the above, taking turns.
    All,
    /// The last unit loses power from the 20th to the 40th second of every minute (not in `all`).
    UnitOutage,
}

impl From<EventFormatArg> for EventFormat {
    fn from(f: EventFormatArg) -> Self {
        match f {
            EventFormatArg::Text => Self::Text,
            EventFormatArg::Jsonl => Self::Jsonl,
            // The UI is set up by the command itself; its writer only counts.
            EventFormatArg::Summary | EventFormatArg::Tui => Self::Summary,
        }
    }
}

/// One duration syntax for every option that takes one (`--duration`, `--idle-timeout`, as
/// `--interval` and `--max-age` already did): `250ms`, `90s`, `2min`, `1h`, or a bare number of
/// seconds (what these options took before), at most 100 days.
///
/// # Errors
/// What is wrong with the value, with examples.
pub fn duration_arg(s: &str) -> Result<std::time::Duration, String> {
    mbtap_analysis::duration::parse_duration(s, std::time::Duration::ZERO, std::time::Duration::from_hours(24 * 100))
}

/// The faults named on the command line (`all`: every one, taking turns).
pub fn fault_list(args: &[FaultArg]) -> Vec<mbtap_sim::bus::Fault> {
    use mbtap_sim::bus::Fault;
    args.iter()
        .flat_map(|f| match f {
            FaultArg::Corrupt => vec![Fault::Corrupt],
            FaultArg::Noise => vec![Fault::Noise],
            FaultArg::SlowSlave => vec![Fault::SlowSlave],
            FaultArg::SilentSlave => vec![Fault::SilentSlave],
            FaultArg::Collision => vec![Fault::Collision],
            FaultArg::FastMaster => vec![Fault::FastMaster],
            FaultArg::SecondMaster => vec![Fault::SecondMaster],
            FaultArg::PumpTrip => vec![Fault::PumpTrip],
            FaultArg::All => Fault::ALL.to_vec(),
            FaultArg::UnitOutage => vec![Fault::Outage],
        })
        .collect()
}

/// The health report (`--report`, `--report-every`) and the learned draft (`--learn`) the output
/// options ask for, added to `writer` (whose profiles the report names units by).
///
/// # Errors
/// A `--report-every` that is no positive number of seconds.
pub fn add_reports<W: std::io::Write>(writer: &mut EventWriter<W>, o: &OutputArgs) -> anyhow::Result<()> {
    if let Some(every) = o.report_every {
        anyhow::ensure!(
            every.is_finite() && every > 0.0,
            "--report-every {every}: expected a number of seconds above 0, e.g. 60"
        );
        // Capped at a year: the report then comes at the end only.
        writer.report_every_ns = Some(std::time::Duration::from_secs_f64(every.min(3.2e7)).as_nanos().try_into()?);
    }
    if o.report || o.report_every.is_some() {
        writer.health = Some(mbtap_analysis::health::Health::new(writer.profiles.clone()));
    }
    if let Some(path) = &o.learn {
        use crate::output::learn_draft::DraftTo;
        let dir = path.as_os_str().to_string_lossy().ends_with('/') || path.is_dir();
        let to = if dir { DraftTo::Dir(path.clone()) } else { DraftTo::File(path.clone()) };
        let mut draft = crate::output::learn_draft::LiveDraft::new(Some(to), "the line mbtap listened to".into());
        draft.replace = crate::output::learn_draft::Replace::new(o.learn_force);
        writer.learn = Some(draft);
    }
    Ok(())
}
