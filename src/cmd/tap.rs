//! `mbtap tap PORT --link PTY`: relay an application's port through a pseudo-terminal and
//! analyse both directions (the relay: [`crate::source::tap`]).

use std::io;
use std::path::PathBuf;
use std::process::ExitCode;

use crate::args::event_writer;
use crate::args::{EventFormatArg, LineArgs, OutputArgs};
use crate::cmd::runtime;

#[derive(Debug, clap::Args)]
/// Tap a port used by an application on this computer: relay through a pseudo-terminal.
///
/// mbtap opens PORT and offers a pseudo-terminal at --link for the application (a SCADA,
/// a configuration tool) to open instead; bytes are relayed untouched both ways and both
/// directions are analysed with the direction known.
pub struct Args {
    /// The real serial port, or a serial server (`rtu-over-tcp://HOST:PORT`,
    /// `rfc2217://HOST:PORT`) whose line the application is put on.
    pub port: String,
    /// Where to create the pseudo-terminal link for the application.
    #[arg(long)]
    pub link: PathBuf,
    #[command(flatten)]
    pub line: LineArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Record both directions to this pcapng file.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Stop after this long: `90s`, `2min`, `1h`, `500ms` (a bare number is seconds).
    #[arg(long, value_name = "DURATION", value_parser = crate::args::duration_arg)]
    pub duration: Option<std::time::Duration>,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { port, link, line, output, record, duration } = args;
    let (mode, settings, latency_ns) = line.overrides().resolve();
    let record_path = record.clone();
    let opts = crate::source::tap::TapOptions { port, link, mode, line: settings, latency_ns, record, duration };
    let profiles = crate::config::devices::load_devices(&output.devices)?;
    let publishing = crate::publish::Publishing::start(&output.publish, true, &opts.port, &profiles)?;
    let taps = publishing.taps();
    if output.format == EventFormatArg::Tui {
        let source = format!("{} ⇄ {}", opts.port, opts.link.display());
        let ui = crate::args::tui_source(&output, settings, false)?;
        let recorded = opts.record.clone();
        let ended = ui.run(&source, move |writer, err| {
            writer.taps = taps;
            runtime()?.block_on(crate::source::tap::tap(opts, writer, err))
        });
        if let Some(note) = recorded.as_deref().and_then(crate::source::record::ended_note) {
            eprintln!("mbtap: {note}");
        }
        return ended;
    }
    let stdout = io::stdout();
    let mut writer = event_writer(io::LineWriter::new(stdout.lock()), &output)?;
    writer.taps = taps;
    let result = runtime()?.block_on(crate::source::tap::tap(opts, &mut writer, &mut io::stderr()));
    // The summary is written even when the recording failed; the exit status says it did.
    writer.finish()?;
    publishing.finish();
    if let Some(note) = record_path.as_deref().and_then(crate::source::record::ended_note) {
        eprintln!("mbtap: {note}");
    }
    result?;
    Ok(ExitCode::SUCCESS)
}
