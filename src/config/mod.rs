//! The configuration file: settings that would otherwise be repeated on every command line.
//! It assigns profiles to units:
//!
//! ```toml
//! [devices]
//! 1 = "mk4"                 # a built-in or user profile name, or a path
//! 5 = "mkzp"
//! ```
//!
//! Found at `$MBTAP_CONFIG`, else `$XDG_CONFIG_HOME/mbtap/config.toml`, else
//! `~/.config/mbtap/config.toml`. Command-line options override it (`--device 1=…` replaces the
//! file's unit 1).
//!
//! Modules: [`devices`] (profiles by the names users give them), [`merge`] (a command's `--config
//! FILE` merged under its command line).

pub mod devices;
pub mod merge;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use mbtap_device::profile::ProfileError;

/// The parsed file.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Unit address → profile name or path.
    #[serde(default)]
    pub devices: BTreeMap<String, String>,
}

/// Where the configuration file is looked for.
#[must_use]
pub fn default_path() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("MBTAP_CONFIG") {
        return Some(p.into());
    }
    let base = std::env::var_os("XDG_CONFIG_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".config")))?;
    Some(base.join("mbtap").join("config.toml"))
}

/// Parses a configuration file's text; errors carry file:line:column.
///
/// # Errors
/// [`ProfileError`] (the same positioned error type as profiles) for bad TOML, unknown keys,
/// or a unit that is not 0–255.
pub fn parse(file: &str, src: &str) -> Result<Config, ProfileError> {
    let at = |span: std::ops::Range<usize>, message: String| {
        let before = &src[..span.start.min(src.len())];
        ProfileError {
            file: file.to_owned(),
            line: before.matches('\n').count() + 1,
            column: before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1,
            message,
        }
    };
    let c: Config = toml::from_str(src).map_err(|e| at(e.span().unwrap_or(0..0), e.message().trim().to_owned()))?;
    for unit in c.devices.keys() {
        if unit.trim().parse::<u8>().is_err() {
            let pos = src.find(&format!("{unit} =")).or_else(|| src.find(unit.as_str())).unwrap_or(0);
            return Err(at(pos..pos, format!("device unit {unit:?} is not an address 0–255")));
        }
    }
    Ok(c)
}

/// Loads the configuration file at `path`, or an empty configuration if there is none.
///
/// # Errors
/// A file that exists but cannot be read or parsed.
pub fn load(path: &Path) -> anyhow::Result<Config> {
    match std::fs::read_to_string(path) {
        Ok(src) => Ok(parse(&path.display().to_string(), &src)?),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Config::default()),
        Err(e) => Err(anyhow::Error::new(e).context(format!("reading {}", path.display()))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_parse() {
        let c = parse("c.toml", "[devices]\n1 = \"mk4\"\n5 = \"mkzp\"\n").unwrap();
        assert_eq!(c.devices.get("1").map(String::as_str), Some("mk4"));
    }

    #[test]
    fn bad_unit_and_unknown_keys_are_positioned() {
        let e = parse("c.toml", "[devices]\n1 = \"mk4\"\n300 = \"x\"\n").unwrap_err();
        assert_eq!((e.line, e.message.contains("300")), (3, true), "{e}");
        let e = parse("c.toml", "[devces]\n").unwrap_err();
        assert_eq!(e.line, 1, "{e}");
    }
}
