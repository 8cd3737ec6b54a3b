//! `mbtap report FILE`: the bus health report of a capture, as text, JSON or an HTML page.

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::ValueEnum;

use crate::cli::args::CaptureLineArgs;

#[derive(Debug, clap::Args)]
/// A bus health report from a capture: per unit and per bus, and findings with evidence.
pub struct Args {
    /// The capture file (pcap or pcapng, as `sniff --record` writes).
    pub file: PathBuf,
    #[command(flatten)]
    pub line: CaptureLineArgs,
    /// Output format.
    #[arg(long, value_enum, default_value_t = ReportFormatArg::Text)]
    pub format: ReportFormatArg,
    /// Check unit UNIT's values against a profile: `UNIT=NAME` or `UNIT=FILE.toml` (repeatable).
    #[arg(long = "device", value_name = "UNIT=PROFILE")]
    pub devices: Vec<String>,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { file, line, format, devices } = args;
    let devices = [crate::config::devices::devices_beside(&file)?, devices].concat();
    let input = crate::output::progress::open_capture(&file, true)?;
    let mut health = mbtap_analysis::health::Health::new(crate::config::devices::load_devices(&devices)?);
    let mut warnings = Vec::new();
    let (mut settings, mut observers) = (None, Vec::new());
    {
        let mut sink = HealthSink {
            health: &mut health,
            warnings: &mut warnings,
            settings: &mut settings,
            observers: &mut observers,
        };
        mbtap_analysis::replay::replay_into(input, line.overrides(), &mut sink)
            .context("reading the capture")
            .with_context(|| format!("reading {}", file.display()))?;
    }
    for w in &warnings {
        eprintln!("mbtap: warning: {w}");
    }
    let mut report = health.report();
    // What the report worked with: the line settings and the observer latency.
    report.line = settings.map(|l| l.to_string());
    report.observers = observers;
    let text = match format {
        ReportFormatArg::Text => mbtap_analysis::report::format::printable(&report.text()).into_owned(),
        ReportFormatArg::Json => serde_json::to_string_pretty(&report.json())? + "\n",
        ReportFormatArg::Html => mbtap_analysis::health::html::render(&report, &file.display().to_string()),
    };
    io::stdout().lock().write_all(text.as_bytes())?;
    // Nothing that frames was heard: not a healthy bus, and scripts must see it.
    if report.findings.iter().any(|f| f.kind == "no_valid_frames") {
        return Ok(ExitCode::from(1));
    }
    Ok(ExitCode::SUCCESS)
}

/// Output of `report`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ReportFormatArg {
    Text,
    /// One JSON document with a top-level `findings` list.
    Json,
    /// A self-contained HTML page with plots (latency, errors over time, availability).
    Html,
}

/// The health report as an analyzer sink.
struct HealthSink<'a> {
    health: &'a mut mbtap_analysis::health::Health,
    warnings: &'a mut Vec<String>,
    settings: &'a mut Option<mbtap_analysis::framer::LineSettings>,
    observers: &'a mut Vec<String>,
}

impl mbtap_analysis::analyzer::Sink for HealthSink<'_> {
    fn event(&mut self, event: &mbtap_analysis::analyzer::Event<'_>) {
        self.health.event(event);
    }

    fn warning(&mut self, message: &str) {
        self.warnings.push(message.to_owned());
    }

    fn settings(&mut self, line: mbtap_analysis::framer::LineSettings) {
        *self.settings = Some(line);
    }

    fn observer(&mut self, port: mbtap_analysis::chunk::PortId, estimate: &mbtap_analysis::framer::ObserverEstimate) {
        self.health.observer(port, estimate);
        if estimate.split_frames > 0 || estimate.reads > 0 {
            self.observers.push(mbtap_analysis::report::events::observer_text(port.0, estimate).trim().to_owned());
        }
    }
}
