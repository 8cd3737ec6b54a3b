//! `mbtap sniff PORT`: a live serial port through the analyzer (the I/O loop: [`crate::source::sniff`]).

use std::io::Write;
use std::process::ExitCode;

use crate::cli::args::LiveArgs;
use crate::cli::runner::{EventSource, Input, Runner};
use crate::output::{EventWriter, SourceError};
use crate::source::sniff::SniffOptions;

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
    pub live: LiveArgs,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { port, live: LiveArgs { line, output, record, duration } } = args;
    let (mode, settings, latency_ns) = line.overrides().resolve();
    let mut runner = Runner::from_output(port.clone(), Input::Live, output, settings)?;
    runner.recording.clone_from(&record);
    runner.run(Sniff(SniffOptions { port, mode, line: settings, latency_ns, record, duration }))
}

/// The live port as the runner's source.
struct Sniff(SniffOptions);

impl EventSource for Sniff {
    fn run<W: Write>(self, writer: &mut EventWriter<W>, err: &mut dyn Write) -> Result<(), SourceError> {
        crate::runtime().map_err(SourceError::NotStarted)?.block_on(crate::source::sniff::sniff(self.0, writer, err))
    }
}
