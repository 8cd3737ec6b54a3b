//! `mbtap replay FILE`: a line capture through the analyzer, exactly as a live session would
//! have seen it.

use std::io;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;

use crate::args::event_writer;
use crate::args::{CaptureLineArgs, EventFormatArg, OutputArgs};

#[derive(Debug, clap::Args)]
/// Replay a line capture (pcap/pcapng, link type 147) through the analyzer.
///
/// Each packet is one chunk as a serial read delivered it, with its timestamp; frames are
/// rebuilt, paired and shown exactly as a live session would have.
pub struct Args {
    /// The capture file.
    pub file: PathBuf,
    /// Write the register image (latest value of every unit/table/address seen, when, and
    /// from which transaction) to this file: `.json` for JSON, anything else CSV.
    #[arg(long)]
    pub image: Option<PathBuf>,
    #[command(flatten)]
    pub line: CaptureLineArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { file, image, line, mut output } = args;
    // The profiles a capture ships with (NAME.devices beside it) under the command line's.
    output.devices = [crate::config::devices::devices_beside(&file)?, output.devices].concat();
    let input = crate::output::progress::open_capture(&file, output.format != EventFormatArg::Tui)?;
    let profiles = crate::config::devices::load_devices(&output.devices)?;
    let publishing = crate::publish::Publishing::start(&output.publish, false, &file.display().to_string(), &profiles)?;
    let taps = publishing.taps();
    if output.format == EventFormatArg::Tui {
        let (_, settings, _) = line.overrides().resolve();
        let source = file.display().to_string();
        let ui = crate::args::tui_source(&output, settings, true)?;
        return ui.run(&source, move |writer, err| {
            writer.paced = true;
            writer.taps = taps;
            crate::output::replay(input, line.overrides(), writer, err)
                .with_context(|| format!("replaying {}", file.display()))
        });
    }
    let stdout = io::stdout();
    let mut writer = event_writer(io::BufWriter::with_capacity(1 << 16, stdout.lock()), &output)?;
    writer.taps = taps;
    if image.is_some() {
        writer.image = Some(mbtap_device::profile::image::RegisterImage::default());
    }
    crate::output::replay(input, line.overrides(), &mut writer, &mut io::stderr())
        .with_context(|| format!("replaying {}", file.display()))?;
    if let (Some(path), Some(img)) = (&image, writer.image.take()) {
        if img.overflowed > 0 {
            eprintln!(
                "mbtap: warning: the register image is full ({} addresses): {} values of new addresses not kept",
                mbtap_device::profile::image::MAX_VALUES,
                img.overflowed
            );
        }
        let text = if path.extension().is_some_and(|e| e == "json") {
            serde_json::to_string_pretty(&img.to_json(&writer.profiles))?
        } else {
            img.to_csv(&writer.profiles)
        };
        std::fs::write(path, text).with_context(|| format!("writing the register image {}", path.display()))?;
    }
    writer.finish()?;
    if publishing.spy.is_some() {
        // A replay ends in a moment; the image it built is served until asked to stop.
        eprintln!("mbtap: the capture is replayed; serving its register image until Ctrl-C");
        super::runtime()?.block_on(crate::signals::shutdown_signal());
    }
    publishing.finish();
    Ok(ExitCode::SUCCESS)
}
