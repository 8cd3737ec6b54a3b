//! `mbtap demo`: the whole job with no hardware — simulated MK4, Display and MKZP-0.4 on a
//! virtual line ([`mbtap_sim::bus`]), polled by a built-in master, heard by the same
//! analyzer `sniff` uses and shown annotated by their profiles, in real time.

use std::io::{self, IsTerminal, Write};
use std::process::ExitCode;

use mbtap_analysis::framer::LineSettings;

use crate::cli::args::{EventFormatArg, FaultArg, LangArg, fault_list};
use crate::cli::runner::{EventSource, Input, Runner};
use crate::output::{EventWriter, SourceError};
use crate::source::demo::DemoOptions;

#[derive(Debug, clap::Args)]
/// The whole job with no hardware: simulated MK4, Display and MKZP-0.4 polled on a virtual
/// line, heard and shown annotated as `sniff` would.
pub struct Args {
    /// Output format [default: tui on a terminal, text otherwise].
    #[arg(long, value_enum)]
    pub format: Option<EventFormatArg>,
    /// Language of register names in annotations.
    #[arg(long, value_enum, default_value_t = LangArg::En)]
    pub lang: LangArg,
    /// Stop after this long (of line time): `90s`, `2min`, `1h`, `500ms` (a bare number is seconds).
    #[arg(long, value_name = "DURATION", value_parser = crate::cli::args::duration_arg)]
    pub duration: Option<std::time::Duration>,
    /// Inject a fault into every fourth transaction, faults taking turns (repeatable).
    #[arg(long = "fault", value_enum)]
    pub faults: Vec<FaultArg>,
    /// Line time per wall-clock time: 1 is real time, 10 ten times faster, 0 as fast as it goes.
    #[arg(long, default_value_t = 1.0, value_parser = crate::cli::numbers::speed)]
    pub speed: f64,
    /// Listen through a UART at these settings instead of the line's 19200 8E1 ("9600 8N1"):
    /// what a sniffer set up wrong gets.
    #[arg(long, value_name = "SETTINGS")]
    pub heard_at: Option<LineSettings>,
    /// Record what the listener hears to this pcapng file, with its timing (as `sniff --record`):
    /// a recording to replay, export, report on or learn from.
    #[arg(long, value_name = "FILE.pcapng")]
    pub record: Option<std::path::PathBuf>,
    /// End (Ctrl-C or --duration) with the bus health report, as `mbtap report` gives it.
    #[arg(long)]
    pub report: bool,
    /// Also give the report so far every SECONDS of line time (implies --report).
    #[arg(long, value_name = "SECONDS", value_parser = crate::cli::numbers::seconds)]
    pub report_every: Option<f64>,
    #[command(flatten)]
    pub publish: crate::publish::PublishArgs,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { format, lang, duration, faults, speed, heard_at, record, report, report_every, mut publish } = args;
    // A demo's devices are nobody's: what it announced to Home Assistant is taken back at its
    // end, so no `unavailable` entity is left behind (`--mqtt-forget` on by default here).
    publish.mqtt.mqtt_forget = true;
    let faults = fault_list(&faults);
    anyhow::ensure!(speed.is_finite() && speed >= 0.0, "--speed {speed}: expected 0 (no waiting) or more");
    let format =
        format.unwrap_or_else(|| if io::stdout().is_terminal() { EventFormatArg::Tui } else { EventFormatArg::Text });
    let profiles = mbtap_sim::demo_profiles()?;
    let publishing = crate::publish::Publishing::start(&publish, Input::Simulated.ages_by_clock(), "demo", &profiles)?;
    let line = heard_at.unwrap_or_default();
    let mut runner = Runner::new("demo (simulated bus)".into(), Input::Simulated, format, profiles, lang.into(), line);
    runner.publishing = publishing;
    runner.recording.clone_from(&record);
    // The report as sniff's output options ask it (the demo's devices are its own).
    runner.output = Some(crate::cli::args::OutputArgs {
        format,
        devices: Vec::new(),
        lang,
        report,
        report_every,
        learn: None,
        learn_force: false,
        publish,
    });
    runner.run(Demo(DemoOptions { duration, faults, speed, heard_at, record }))
}

/// The simulated line as the runner's source.
struct Demo(DemoOptions);

impl EventSource for Demo {
    fn run<W: Write>(self, writer: &mut EventWriter<W>, _: &mut dyn Write) -> Result<(), SourceError> {
        // The demo fails only while it sets its line up (a built-in profile that does not load).
        let started = crate::runtime()?.block_on(crate::source::demo::demo(self.0, writer));
        started.map_err(SourceError::NotStarted)
    }
}
