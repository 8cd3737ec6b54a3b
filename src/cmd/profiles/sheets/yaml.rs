//! Home Assistant `modbus:` YAML read for the import, streamed from its file, bounded.

use std::io::Read as _;
use std::path::Path;

use anyhow::Context as _;

/// The largest Home Assistant YAML read (32 MiB: twice a file naming every address of two tables;
/// a real `modbus:` configuration is kilobytes). The import holds ~6 bytes per byte of YAML (the
/// reader streams; the entries read and their problems remain): 193 MB for a 32.9 MB file.
pub const MAX_YAML_BYTES: u64 = 32 << 20;

/// A Home Assistant YAML file read into `out`, streamed twice (its nesting, then its entries),
/// refused unread past [`MAX_YAML_BYTES`] (a 200 MB file of nested mappings is never read
/// whole). Returns the device read.
///
/// # Errors
/// The file cannot be read, is too big, or is not a Home Assistant configuration.
pub fn read_yaml(
    path: &Path,
    unit: Option<u8>,
    out: &mut impl mbtap_device::profile::import::Sink,
) -> anyhow::Result<u8> {
    let open = || -> anyhow::Result<std::io::Take<std::fs::File>> {
        let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
        let len = file.metadata().with_context(|| format!("reading {}", path.display()))?.len();
        anyhow::ensure!(
            len <= MAX_YAML_BYTES,
            "{}: {len} bytes, over the {MAX_YAML_BYTES} a Home Assistant `modbus:` file may have; give only the `modbus:` part",
            path.display()
        );
        Ok(file.take(MAX_YAML_BYTES))
    };
    let depth = std::io::BufReader::new(open()?);
    let yaml = std::io::BufReader::new(open()?);
    mbtap_device::profile::import::home_assistant::read_home_assistant_from(depth, yaml, unit, out)
        .with_context(|| format!("reading {}", path.display()))
}
