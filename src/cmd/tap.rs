//! `mbtap tap PORT --link PTY`: relay an application's port through a pseudo-terminal and
//! analyse both directions (the relay: [`crate::source::tap`]).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use crate::cli::args::LiveArgs;
use crate::cli::runner::{EventSource, Input, Runner};
use crate::output::{EventWriter, SourceError};
use crate::source::tap::TapOptions;

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
    pub live: LiveArgs,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { port, link, live: LiveArgs { line, output, record, duration } } = args;
    let (mode, settings, latency_ns) = line.overrides().resolve();
    let mut runner = Runner::from_output(port.clone(), Input::Live, output, settings)?;
    runner.title = format!("{port} ⇄ {}", link.display());
    runner.recording.clone_from(&record);
    runner.run(Tap(TapOptions { port, link, mode, line: settings, latency_ns, record, duration }))
}

/// The relay as the runner's source.
struct Tap(TapOptions);

impl EventSource for Tap {
    fn run<W: Write>(self, writer: &mut EventWriter<W>, err: &mut dyn Write) -> Result<(), SourceError> {
        crate::runtime().map_err(SourceError::NotStarted)?.block_on(crate::source::tap::tap(self.0, writer, err))
    }
}
