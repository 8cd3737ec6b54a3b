//! Device profiles as users name them: a built-in name, a user profile in the config
//! directory, or a file; `--device UNIT=PROFILE` lists merged over the configuration file's
//! `[devices]`. Reads files and the environment, so it lives at the edge.

use anyhow::Context;
use mbtap_core::profile::Profiles;

pub fn load_profile_file(path: &std::path::Path) -> anyhow::Result<mbtap_core::profile::Profile> {
    let src = std::fs::read_to_string(path).with_context(|| format!("reading profile {}", path.display()))?;
    Ok(mbtap_core::profile::load(&path.display().to_string(), &src)?)
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
pub fn resolve_profile(spec: &str) -> anyhow::Result<mbtap_core::profile::Profile> {
    if let Some(p) = mbtap_core::profile::builtin::get(spec) {
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
    anyhow::bail!(
        "no profile named {spec:?}: built-in profiles are {}; user profiles are NAME.toml files in {dir}; or give the path of a profile file (see docs/profiles.md)",
        mbtap_core::profile::builtin::names().join(", ")
    )
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
