//! Device profiles as users name them: a built-in name, a user profile in the config
//! directory, or a file; `--device UNIT=PROFILE` lists merged over the configuration file's
//! `[devices]`. Reads files and the environment, so it lives at the edge.

use anyhow::Context;
use mbtap_device::profile::Profiles;

pub fn load_profile_file(path: &std::path::Path) -> anyhow::Result<mbtap_device::profile::Profile> {
    let src = std::fs::read_to_string(path).with_context(|| format!("reading profile {}", path.display()))?;
    Ok(mbtap_device::profile::load(&path.display().to_string(), &src)?)
}

/// Where users keep their own profiles: `$MBTAP_PROFILE_DIR`, else
/// `$XDG_CONFIG_HOME/mbtap/profiles`, else `~/.config/mbtap/profiles` (the Linux config dir).
pub fn user_profile_dir() -> Option<std::path::PathBuf> {
    if let Some(d) = std::env::var_os("MBTAP_PROFILE_DIR") {
        return Some(d.into());
    }
    let base = std::env::var_os("XDG_CONFIG_HOME")
        .map(std::path::PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| std::path::PathBuf::from(h).join(".config")))?;
    Some(base.join("mbtap").join("profiles"))
}

/// A built-in profile by name, a user profile by name (`NAME.toml` in the user profile
/// directory), or a profile file by path.
pub fn resolve_profile(spec: &str) -> anyhow::Result<mbtap_device::profile::Profile> {
    if let Some(p) = mbtap_device::profile::builtin::get(spec) {
        return Ok(p?);
    }
    let path = std::path::Path::new(spec);
    if path.exists() {
        return load_profile_file(path);
    }
    if let Some(dir) = user_profile_dir() {
        let user = dir.join(format!("{spec}.toml"));
        if user.exists() {
            return load_profile_file(&user);
        }
    }
    let dir = user_profile_dir().map_or_else(|| "(no config directory)".to_owned(), |d| d.display().to_string());
    let guess = closest(spec, known_names()).map(|n| format!(" (did you mean {n:?}?)")).unwrap_or_default();
    anyhow::bail!(
        "no profile named {spec:?}{guess}: built-in profiles are {}; user profiles are NAME.toml files in {dir}; or give the path of a profile file (see docs/profiles.md)",
        mbtap_device::profile::builtin::names().join(", ")
    )
}

/// The profile names a user may mean: the built-in ones and the user profiles' (at most the
/// first 4 096 files of the directory: a name is a guess, not a scan).
fn known_names() -> Vec<String> {
    let mut names: Vec<String> = mbtap_device::profile::builtin::names().iter().map(|&n| n.to_owned()).collect();
    if let Some(entries) = user_profile_dir().and_then(|d| std::fs::read_dir(d).ok()) {
        names.extend(entries.take(4096).filter_map(|e| {
            let path = e.ok()?.path();
            (path.extension()? == "toml").then(|| path.file_stem()?.to_str().map(str::to_owned)).flatten()
        }));
    }
    names
}

/// The name nearest to `typed` by edit distance (the query's own "did you mean" measure), when
/// it is near enough to be a typo: at most 2 edits, and fewer than half the name (`sdm360` →
/// `sdm630`; `xyz` suggests nothing).
fn closest(typed: &str, names: Vec<String>) -> Option<String> {
    let typed = typed.to_lowercase();
    names
        .into_iter()
        .map(|n| (mbtap_device::query::resolve::distance(&typed, &n.to_lowercase()), n))
        .filter(|(d, n)| *d <= 2 && *d * 2 < n.chars().count())
        .min_by_key(|(d, _)| *d)
        .map(|(_, n)| n)
}

/// The `UNIT=PROFILE` lines of the `NAME.devices` file beside a capture `NAME.pcapng`, if there
/// is one (blank lines and `#` comments skipped), said on stderr when used; `--device` entries
/// given after them win unit by unit (`replay` ignored the file the captures ship with).
///
/// # Errors
/// A line that is not `UNIT=PROFILE`, with the file and line.
pub fn devices_beside(capture: &std::path::Path) -> anyhow::Result<Vec<String>> {
    let path = capture.with_extension("devices");
    let Ok(text) = std::fs::read_to_string(&path) else { return Ok(Vec::new()) };
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or_default().trim();
        if line.is_empty() {
            continue;
        }
        let ok = line.split_once('=').is_some_and(|(u, p)| u.trim().parse::<u8>().is_ok() && !p.trim().is_empty());
        anyhow::ensure!(ok, "{}:{}: {line:?} is not UNIT=PROFILE (e.g. 1=mk4)", path.display(), i + 1);
        out.push(line.to_owned());
    }
    if !out.is_empty() {
        eprintln!("mbtap: profiles from {}: {} (--device overrides)", path.display(), out.join(", "));
    }
    Ok(out)
}

/// `--device UNIT=PROFILE` values: a unit address and a built-in name or a profile file.
/// The configuration file's `[devices]` come first; `--device` replaces them unit by unit.
pub fn load_devices(devices: &[String]) -> anyhow::Result<Profiles> {
    let mut out = Profiles::new();
    if let Some(path) = super::default_path() {
        let config = super::load(&path)?;
        for (unit, profile) in &config.devices {
            let u: u8 = unit.trim().parse().with_context(|| format!("{}: unit {unit:?}", path.display()))?;
            out.insert(
                u,
                resolve_profile(profile).with_context(|| format!("{}: device {unit} = {profile:?}", path.display()))?,
            );
        }
    }
    for d in devices {
        let (unit, profile) =
            d.split_once('=').with_context(|| format!("--device {d:?}: expected UNIT=PROFILE, e.g. --device 1=mk4"))?;
        let unit: u8 = unit.trim().parse().with_context(|| format!("--device {d:?}: unit {unit:?} is not 0..=255"))?;
        out.insert(unit, resolve_profile(profile.trim()).with_context(|| format!("--device {d:?}"))?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_profile_name_typed_wrong_gets_the_nearest_as_a_suggestion() {
        let names = || ["mk4", "mkzp", "display", "sdm630"].map(String::from).to_vec();
        assert_eq!(closest("sdm360", names()).as_deref(), Some("sdm630"));
        assert_eq!(closest("MKZP", names()).as_deref(), Some("mkzp"));
        assert_eq!(closest("dispaly", names()).as_deref(), Some("display"));
        assert_eq!(closest("xyz", names()), None, "nothing near: no suggestion");
        assert_eq!(closest("mk5", names()).as_deref(), Some("mk4"));
        assert_eq!(closest("zz", names()), None, "two edits of a short name are no typo");
    }
}
