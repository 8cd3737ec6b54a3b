//! The built-in profiles, compiled into the binary. Each is checked by the same loader as a
//! user's file, and tested against the document it was made from (tests/decode/builtin_profiles.rs).

use super::loader::{ProfileError, load};
use super::model::Profile;

/// (name, file name, TOML) of every built-in profile.
const BUILTIN: &[(&str, &str, &str)] = &[
    ("mk4", "builtin/mk4.toml", include_str!("mk4.toml")),
    ("mkzp", "builtin/mkzp.toml", include_str!("mkzp.toml")),
    ("display", "builtin/display.toml", include_str!("display.toml")),
    ("sdm120", "builtin/sdm120.toml", include_str!("sdm120.toml")),
    ("sdm230", "builtin/sdm230.toml", include_str!("sdm230.toml")),
    ("sdm630", "builtin/sdm630.toml", include_str!("sdm630.toml")),
    ("dtsu666", "builtin/dtsu666.toml", include_str!("dtsu666.toml")),
    ("ddsu666", "builtin/ddsu666.toml", include_str!("ddsu666.toml")),
    ("em24", "builtin/em24.toml", include_str!("em24.toml")),
    ("em340", "builtin/em340.toml", include_str!("em340.toml")),
    ("b21", "builtin/b21.toml", include_str!("b21.toml")),
    ("b23", "builtin/b23.toml", include_str!("b23.toml")),
    ("b24", "builtin/b24.toml", include_str!("b24.toml")),
];

/// Names of the built-in profiles.
#[must_use]
pub fn names() -> Vec<&'static str> {
    BUILTIN.iter().map(|(n, _, _)| *n).collect()
}

/// A built-in profile by name (case-insensitive), `None` if there is none of that name.
///
/// # Errors
/// Only if a built-in profile fails to load, which its test rules out.
pub fn get(name: &str) -> Option<Result<Profile, ProfileError>> {
    BUILTIN.iter().find(|(n, _, _)| n.eq_ignore_ascii_case(name)).map(|(_, file, src)| load(file, src))
}

/// The TOML of a built-in profile (for `profiles show` and as a starting point).
#[must_use]
pub fn source(name: &str) -> Option<&'static str> {
    BUILTIN.iter().find(|(n, _, _)| n.eq_ignore_ascii_case(name)).map(|(_, _, s)| *s)
}

/// The devices of the demo line and their addresses (`mbtap demo`, `mbtap simulate`'s default).
pub const DEMO_DEVICES: [(&str, u8); 3] = [("mk4", 1), ("display", 5), ("mkzp", 17)];

/// The profiles of the demo's devices, by address.
///
/// # Errors
/// When a built-in profile does not load (a build defect, caught by the tests).
pub fn demo_profiles() -> Result<super::Profiles, ProfileError> {
    let mut out = super::Profiles::new();
    for (name, address) in DEMO_DEVICES {
        if let Some(profile) = get(name) {
            out.insert(address, profile?);
        }
    }
    Ok(out)
}
