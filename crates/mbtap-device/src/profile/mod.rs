//! Device profiles: register maps in TOML (`format`), loaded with precise errors (`loader`),
//! resolved per address (`model`), and used to annotate transactions (`annotate`).
//! Pure: no I/O here; callers read the files.
//!
//! Beside them: `builtin` (the built-in profiles), `image` (the register image of what the bus
//! carried), `import` (profiles from sheets and Home Assistant YAML), `export` (to Home Assistant,
//! ESPHome, Telegraf), `escape` (outside strings kept values in those files), `ha_classes` (units
//! as Home Assistant spells them, with their classes).

pub mod annotate;
pub mod builtin;
pub mod escape;
pub mod export;
pub mod format;
pub mod ha_classes;
pub mod image;
pub mod import;
pub mod loader;
pub mod model;
pub mod transaction;

pub use format::Table;
pub use loader::{ProfileError, load};

/// Profiles by unit address, for annotation.
pub type Profiles = std::collections::BTreeMap<u8, Profile>;
pub use model::Profile;
