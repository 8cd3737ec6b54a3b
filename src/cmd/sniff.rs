//! `mbtap sniff PORT`: a live serial port through the analyzer (the I/O loop: [`crate::source::sniff`]).

use std::io;
use std::path::PathBuf;
use std::process::ExitCode;

use crate::args::event_writer;
use crate::args::{EventFormatArg, LineArgs, OutputArgs};
use crate::cmd::runtime;

#[derive(Debug, clap::Args)]
/// Listen to a live serial port: rebuild, pair and show every frame.
///
/// Stops on Ctrl-C or SIGTERM (or after --duration) and prints a summary. With --record,
/// every read is written to a pcapng line capture (flushed each second) that `replay`
/// shows exactly as this session did.
pub struct Args {
    /// The serial port (e.g. /dev/ttyUSB0), or a serial server: `rtu-over-tcp://HOST:PORT` in
    /// transparent mode (ser2net raw, USR, Elfin, NPort) or `rfc2217://HOST:PORT` (Telnet, the
    /// line's settings set from the line options), its line framed by structure and CRC.
    pub port: String,
    #[command(flatten)]
    pub line: LineArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Record every read to this pcapng file.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Stop after this long: `90s`, `2min`, `1h`, `500ms` (a bare number is seconds).
    #[arg(long, value_name = "DURATION", value_parser = crate::args::duration_arg)]
    pub duration: Option<std::time::Duration>,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { port, line, output, record, duration } = args;
    let (mode, settings, latency_ns) = line.overrides().resolve();
    let record_path = record.clone();
    let opts = crate::source::sniff::SniffOptions { port, mode, line: settings, latency_ns, record, duration };
    let profiles = crate::config::devices::load_devices(&output.devices)?;
    let publishing = crate::publish::Publishing::start(&output.publish, true, &opts.port, &profiles)?;
    let taps = publishing.taps();
    if output.format == EventFormatArg::Tui {
        let source = opts.port.clone();
        let ui = crate::args::tui_source(&output, settings, false)?;
        let recorded = opts.record.clone();
        let ended = ui.run(&source, move |writer, err| {
            writer.taps = taps;
            runtime()?.block_on(crate::source::sniff::sniff(opts, writer, err))
        });
        if let Some(note) = recorded.as_deref().and_then(crate::source::record::ended_note) {
            eprintln!("mbtap: {note}");
        }
        return ended;
    }
    let stdout = io::stdout();
    let mut writer = event_writer(io::LineWriter::new(stdout.lock()), &output)?;
    writer.taps = taps;
    let result = runtime()?.block_on(crate::source::sniff::sniff(opts, &mut writer, &mut io::stderr()));
    // The summary is written even when the recording failed; the exit status says it did. A
    // port that never opened heard nothing: only the error is said.
    let opened = !matches!(&result, Err(e) if e.downcast_ref::<crate::source::sniff::NeverOpened>().is_some());
    if opened {
        writer.finish()?;
    }
    publishing.finish();
    if let Some(note) = record_path.as_deref().and_then(crate::source::record::ended_note) {
        eprintln!("mbtap: {note}");
    }
    result?;
    Ok(ExitCode::SUCCESS)
}
