//! `mbtap export FILE -o OUT`: the rebuilt frames as a pcapng that Wireshark's `mbrtu`
//! dissector decodes with no configuration.

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;

use crate::cli::args::CaptureLineArgs;

#[derive(Debug, clap::Args)]
/// Export the rebuilt frames for Wireshark (pcapng, link type 252, `mbrtu` dissector).
///
/// `tshark -r OUT` decodes every frame as Modbus RTU with no configuration; add
/// `-o mbrtu.tcp.port:502` to have echo-shaped frames (05, 06, 08, 16) classified as query
/// or response from the direction mbtap worked out.
pub struct Args {
    /// The line capture to read.
    pub file: PathBuf,
    /// The Wireshark file to write.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Replace the file if it is already there (without, it is kept and nothing is written).
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub line: CaptureLineArgs,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { file, out, force, line } = args;
    let input = crate::output::progress::open_capture(&file, true)?;
    let output =
        crate::output::whole_file::WholeFile::create(&out, crate::output::whole_file::Existing::forced(force))?;
    let export = mbtap_analysis::capture::export::WiresharkExport::new(io::BufWriter::new(output))?;
    let mut sink = ExportSink { export, error: None };
    mbtap_analysis::replay::replay_into(input, line.overrides(), &mut sink)
        .context("reading the capture")
        .with_context(|| format!("reading {}", file.display()))?;
    if let Some(e) = sink.error {
        return Err(e).with_context(|| format!("writing {}", out.display()));
    }
    let frames = sink.export.frames;
    let written = sink.export.finish().with_context(|| format!("writing {}", out.display()))?;
    written
        .into_inner()
        .map_err(io::IntoInnerError::into_error)
        .with_context(|| format!("writing {}", out.display()))?
        .commit()?;
    eprintln!("mbtap: exported {frames} frames to {}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// Collects frames for the Wireshark export.
struct ExportSink<W: Write> {
    export: mbtap_analysis::capture::export::WiresharkExport<W>,
    error: Option<io::Error>,
}

impl<W: Write> mbtap_analysis::analyzer::Sink for ExportSink<W> {
    fn event(&mut self, e: &mbtap_analysis::analyzer::Event<'_>) {
        if let mbtap_analysis::analyzer::Event::Frame { frame, role, .. } = *e
            && self.error.is_none()
            && let Err(err) = self.export.frame(frame.t_start, frame.bytes, role, frame.check_ok)
        {
            self.error = Some(err);
        }
    }

    fn warning(&mut self, message: &str) {
        crate::output::progress::clear_line();
        eprintln!("mbtap: warning: {message}");
    }
}
