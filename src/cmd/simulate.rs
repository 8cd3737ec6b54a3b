//! `mbtap simulate`: simulated devices on a pseudo-terminal for a Modbus master, or the whole
//! line (master too) for a listener (the I/O: [`crate::source::simulate`]).

use std::io;
use std::path::PathBuf;
use std::process::ExitCode;

use mbtap_core::framer::LineSettings;

use crate::args::{FaultArg, LineArgs, fault_list};

#[derive(Debug, clap::Args)]
// Command-line switches are bools by nature; each is an independent option, not a state.
#[allow(clippy::struct_excessive_bools)]
/// Simulated devices on a pseudo-terminal: point a Modbus master (or mbtap) at --link.
pub struct Args {
    /// Where to create the pseudo-terminal link for the master.
    #[arg(long, default_value = "/tmp/mbtap-bus")]
    pub link: PathBuf,
    /// A simulated slave, `NAME@ADDRESS` (repeatable; default: mk4@1 display@5 mkzp@17).
    #[arg(long = "device", value_name = "NAME@ADDRESS")]
    pub devices: Vec<String>,
    #[command(flatten)]
    pub line: LineArgs,
    /// Stop after this long: `90s`, `2min`, `1h`, `500ms` (a bare number is seconds).
    #[arg(long, value_name = "DURATION", value_parser = crate::args::duration_arg)]
    pub duration: Option<std::time::Duration>,
    /// A slave's time from the end of a request to its answer, ms.
    #[arg(long, default_value_t = 3.0)]
    pub turnaround_ms: f64,
    /// Take the line's time when answering: requests end when their characters would
    /// have crossed the line, answers leave at the character rate.
    #[arg(long)]
    pub paced: bool,
    /// Echo every byte the master sends back to it before the answer, as a half-duplex adapter
    /// whose receiver stays on does (for `bridge --echo`).
    #[arg(long)]
    pub echo: bool,
    /// Play the master too: poll the devices and put the whole line on the pseudo-terminal,
    /// paced at the line's character rate, for a listener (`mbtap sniff LINK`).
    #[arg(long)]
    pub poll: bool,
    /// With --poll: inject a fault into every fourth transaction (repeatable).
    #[arg(long = "fault", value_enum, requires = "poll")]
    pub faults: Vec<FaultArg>,
    /// With --poll: the listener's UART settings when they are not the line's ("9600 8N1").
    #[arg(long, value_name = "SETTINGS", requires = "poll", conflicts_with = "follow_baud")]
    pub heard_at: Option<LineSettings>,
    /// With --poll: hear the line at the baud rate the listener set on the pseudo-terminal
    /// (as `mbtap scan` reopens it at each rate). A pty keeps the baud rate and odd parity
    /// of its termios but not the character size or parity enable, so only the rate follows.
    #[arg(long, requires = "poll")]
    pub follow_baud: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { link, devices, line, duration, turnaround_ms, paced, echo, poll, faults, heard_at, follow_baud } = args;
    anyhow::ensure!(
        turnaround_ms.is_finite() && turnaround_ms >= 0.0,
        "--turnaround-ms {turnaround_ms}: expected 0 or more"
    );
    let (mode, settings, _) = line.overrides().resolve();
    let specs: Vec<String> = if devices.is_empty() {
        crate::source::simulate::DEFAULT_DEVICES.iter().map(|(n, a)| format!("{n}@{a}")).collect()
    } else {
        devices
    };
    let devices = specs.iter().map(|d| crate::source::simulate::parse_device(d)).collect::<anyhow::Result<_>>()?;
    let opts = crate::source::simulate::SimulateOptions {
        link,
        devices,
        line: settings,
        mode,
        duration,
        turnaround: std::time::Duration::from_secs_f64(turnaround_ms / 1000.0),
        paced,
        echo,
        poll: poll.then(|| crate::source::simulate::PollOptions { faults: fault_list(&faults), heard_at, follow_baud }),
    };
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    rt.block_on(crate::source::simulate::simulate(opts, &mut io::stderr()))?;
    Ok(ExitCode::SUCCESS)
}
