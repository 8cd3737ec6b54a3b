//! `mbtap replay FILE`: a line capture through the analyzer, exactly as a live session would
//! have seen it.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;

use crate::cli::args::{CaptureLineArgs, EventFormatArg, OutputArgs};
use crate::cli::runner::{EventSource, Input, Runner};
use crate::output::{EventWriter, SourceError};

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
    /// With --image: replace the file if it is already there.
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub line: CaptureLineArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args { file, image, force, line, mut output } = args;
    // Said before the replay, not after it: a file there is kept unless --force.
    if let Some(path) = image.as_ref().filter(|p| !force && p.symlink_metadata().is_ok()) {
        anyhow::bail!("--image {}: already exists: kept as it is; give --force to replace it", path.display());
    }
    // The profiles a capture ships with (NAME.devices beside it) under the command line's.
    output.devices = [crate::config::devices::devices_beside(&file)?, output.devices].concat();
    let input = crate::output::progress::open_capture(&file, output.format != EventFormatArg::Tui)?;
    let (_, settings, _) = line.overrides().resolve();
    Runner::from_output(file.display().to_string(), Input::Recording, output, settings)?.run(Replay {
        input,
        line,
        file,
        image,
        force,
    })
}

/// A capture as the runner's source, and the register image it leaves (`--image`).
struct Replay<R> {
    input: R,
    line: CaptureLineArgs,
    file: PathBuf,
    image: Option<PathBuf>,
    force: bool,
}

impl<R: Read + Send + 'static> EventSource for Replay<R> {
    fn run<W: Write>(self, writer: &mut EventWriter<W>, err: &mut dyn Write) -> Result<(), SourceError> {
        let Self { input, line, file, image, force } = self;
        if image.is_some() {
            writer.image = Some(mbtap_device::profile::image::RegisterImage::default());
        }
        // A replay fails only on a file that cannot be read as a capture: nothing heard.
        crate::output::replay(input, line.overrides(), writer, err)
            .with_context(|| format!("replaying {}", file.display()))
            .map_err(SourceError::NotStarted)?;
        if let (Some(path), Some(img)) = (&image, writer.image.take()) {
            write_image(path, &img, &writer.profiles, force)?;
        }
        Ok(())
    }
}

/// The register image to `path`: JSON for `.json`, CSV otherwise; a full image said.
fn write_image(
    path: &std::path::Path,
    img: &mbtap_device::profile::image::RegisterImage,
    profiles: &mbtap_device::profile::Profiles,
    force: bool,
) -> anyhow::Result<()> {
    if img.overflowed > 0 {
        eprintln!(
            "mbtap: warning: the register image is full ({} addresses): {} values of new addresses not kept",
            mbtap_device::profile::image::MAX_VALUES,
            img.overflowed
        );
    }
    let text = if path.extension().is_some_and(|e| e == "json") {
        serde_json::to_string_pretty(&img.to_json(profiles))?
    } else {
        img.to_csv(profiles)
    };
    crate::output::whole_file::write_whole(path, text.as_bytes(), crate::output::whole_file::Existing::forced(force))
        .context("the register image")
}
