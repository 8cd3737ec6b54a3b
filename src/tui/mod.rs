//! The terminal UI shared by `sniff`, `replay`, `tap` and `demo`: traffic, detail, devices and
//! registers views over a bounded model of what the analyzer reported.
//!
//! Layers: [`model`] (events in, rows and statistics out) and [`app`] (keys in, view state out)
//! are pure and unit-tested; the `view_*` modules draw them with ratatui (snapshot-tested on
//! `TestBackend`); [`terminal`] owns the real terminal, the key loop and the exports.
//!
//! The rest: [`source`] (the UI over a source's thread), [`render`] (the frame: title, view,
//! status, help), [`style`] (how the views write shared figures), [`stats`] (per-device and bus
//! statistics), [`layout`] (where each field lies in a frame's bytes); the views `view_traffic`,
//! `view_detail`, `view_devices`, `view_registers`.

pub mod app;
pub mod layout;
pub mod model;
pub mod registers;
pub mod render;
pub mod source;
pub mod stats;
pub mod style;
pub mod terminal;
mod view_detail;
mod view_devices;
mod view_registers;
mod view_traffic;

pub use app::App;
pub use model::Model;
