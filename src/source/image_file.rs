//! Register images kept in files: `replay --image` CSV or JSON and probe dumps (`probe --format
//! json`), read for `diff` and for `simulate --from`, bounded in size before a byte is parsed.

use std::path::Path;

use anyhow::Context as _;
use mbtap_analysis::learn::diff::{Image, parse_image_csv, parse_image_json_from};

/// The largest image file read: every address of the four tables as JSON rows is ~40 MB.
const MAX_IMAGE_FILE: u64 = 64 << 20;

/// The image in `path` when its name ends `.json` or `.csv`; `None` for anything else (a
/// capture, read by the replay).
///
/// # Errors
/// The file cannot be read, is over 64 MiB, or a row is wrong (said with its row).
pub fn load(path: &Path) -> anyhow::Result<Option<Image>> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or_default().to_ascii_lowercase();
    let open = || -> anyhow::Result<std::io::Take<std::fs::File>> {
        let f = std::fs::File::open(path).with_context(|| format!("{}: cannot read it", path.display()))?;
        let len = f.metadata().map_or(0, |m| m.len());
        anyhow::ensure!(
            len <= MAX_IMAGE_FILE,
            "{}: {len} bytes, over the {MAX_IMAGE_FILE} an image or probe dump of every address has; not read",
            path.display()
        );
        Ok(std::io::Read::take(f, MAX_IMAGE_FILE))
    };
    match ext.as_str() {
        "json" => parse_image_json_from(open()?).map(Some).map_err(|e| anyhow::anyhow!("{}: {e}", path.display())),
        "csv" => {
            let mut text = String::new();
            std::io::Read::read_to_string(&mut open()?, &mut text)
                .with_context(|| format!("{}: cannot read it", path.display()))?;
            parse_image_csv(&text).map(Some).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
        }
        _ => Ok(None),
    }
}
