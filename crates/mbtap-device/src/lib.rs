//! mbtap's device model, pure: what a device holds and how to ask it.
//!
//! - [`profile`] — device register maps: the format, the loader with positioned errors,
//!   annotation of values, the built-in MK4, MKZP-0.4 and Display profiles, imports (vendor
//!   sheets, Home Assistant YAML) and exports (Home Assistant, ESPHome, Telegraf).
//! - [`sunspec`] — SunSpec model discovery and decoding (the models' JSON compiled in).
//! - [`query`] — what `read`/`write`/`watch` ask of a device: names resolved, requests split,
//!   writes checked and encoded, answers named and scaled.
//! - [`fuzzing`] — the bodies of this crate's fuzz targets, also run over the seeds by `cargo test`.
//!
//! Only `mbtap-proto` below it; the analysis annotates with it, the simulator serves it, the
//! publisher names values by it. No I/O, no clock.

pub mod fuzzing;
pub mod profile;
pub mod query;
pub mod sunspec;
