//! `mbtap diff A B`: which registers changed between two captures, register images or probe
//! dumps, and how ([`mbtap_analysis::learn::diff`]), named and scaled by profiles when given.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;
use mbtap_analysis::learn::diff::{Image, diff};

/// Which registers changed between two captures, register images (`replay --image` CSV or
/// JSON) or probe dumps (`probe --format json` saved) — before and after a settings change or
/// a firmware update.
///
/// The latest value of every register heard in each is compared. Exit status: 0 nothing
/// differs, 1 something does (as diff(1)), 2 an input cannot be read.
/// Example: `mbtap diff before.pcapng after.pcapng --device 1=mk4`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Before: a capture (pcap/pcapng), a register image (.csv, .json) or a probe dump (.json).
    pub before: PathBuf,
    /// After: the same kinds.
    pub after: PathBuf,
    /// Name and scale unit UNIT's registers with a profile: `UNIT=NAME` or `UNIT=FILE.toml`.
    #[arg(long = "device", value_name = "UNIT=PROFILE")]
    pub devices: Vec<String>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Text)]
    pub format: Format,
}

/// Output of `diff`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Text,
    Jsonl,
}

/// Builds the image of a capture and says what was wrong with the capture (a corrupt block)
/// on the way, as `replay` does.
struct ImageSink<'a> {
    image: mbtap_device::profile::image::RegisterImage,
    path: &'a Path,
}

impl mbtap_analysis::analyzer::Sink for ImageSink<'_> {
    fn event(&mut self, e: &mbtap_analysis::analyzer::Event<'_>) {
        crate::output::update_image(&mut self.image, e);
    }

    fn warning(&mut self, message: &str) {
        eprintln!("mbtap: {}: {}", self.path.display(), mbtap_analysis::report::format::printable(message));
    }
}

/// The register image of a capture or an image file.
fn load(path: &Path) -> anyhow::Result<Image> {
    if let Some(image) = crate::source::image_file::load(path)? {
        return Ok(image);
    }
    let input = crate::output::progress::open_capture(path, false)?;
    let mut sink = ImageSink { image: mbtap_device::profile::image::RegisterImage::default(), path };
    mbtap_analysis::replay::replay_into(input, mbtap_analysis::line_args::LineOverrides::default(), &mut sink)
        .with_context(|| format!("reading {}", path.display()))?;
    Ok(sink.image.values.iter().map(|(&k, v)| (k, v.raw)).collect())
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let profiles = crate::config::devices::load_devices(&args.devices)?;
    let (a, b) = (load(&args.before)?, load(&args.after)?);
    // Nothing heard in an input is not "nothing changed": said, and exit 2 (cannot compare).
    let empty: Vec<String> = [(&a, &args.before), (&b, &args.after)]
        .iter()
        .filter(|(i, _)| i.is_empty())
        .map(|(_, p)| p.display().to_string())
        .collect();
    if !empty.is_empty() {
        eprintln!("mbtap: no register value in {}: nothing to compare", empty.join(" nor in "));
        return Ok(ExitCode::from(2));
    }
    let (changes, same) = diff(&a, &b);
    let mut out = std::io::stdout().lock();
    let shown = |unit: u8, table, address: u16, raw: Option<u16>| -> String {
        let Some(raw) = raw else { return "—".into() };
        let named = profiles
            .get(&unit)
            .and_then(|p| mbtap_device::query::rows::rows(unit, table, address, &[raw], Some(p)).into_iter().next());
        named.map_or_else(|| raw.to_string(), |r| format!("{} ({})", r.shown, raw))
    };
    for c in &changes {
        let name = profiles
            .get(&c.unit)
            .and_then(|p| p.slot(c.table, c.address).map(|(s, _)| format!(" {}", s.name)))
            .unwrap_or_default();
        let line = match args.format {
            Format::Text => format!(
                "unit {} {} {}{name}: {} → {}",
                c.unit,
                mbtap_device::query::rows::short_table(c.table),
                c.address,
                shown(c.unit, c.table, c.address, c.before),
                shown(c.unit, c.table, c.address, c.after)
            ),
            Format::Jsonl => serde_json::json!({
                "unit": c.unit, "table": c.table.name(), "address": c.address,
                "before": c.before, "after": c.after,
            })
            .to_string(),
        };
        writeln!(out, "{}", mbtap_analysis::report::format::printable(&line)).context("writing the differences")?;
    }
    if args.format == Format::Text {
        writeln!(out, "{} differ, {same} the same", changes.len()).context("writing the differences")?;
    }
    Ok(if changes.is_empty() { ExitCode::SUCCESS } else { ExitCode::from(1) })
}
