//! The analysing sources' loops — `sniff`, `tap`, `scan`, `play` and `demo` — over the ports of
//! [`crate::io`]: each produces [`Chunk`](mbtap_analysis::chunk::Chunk)s for the pure core
//! through the one [`session`] driver (or, for `play`, writes bytes a peer reads); and
//! `simulate` in one place ([`simulate`]): its pseudo-terminal, what it emulates and the devices
//! every front serves.
//!
//! Beside the loops: [`record`] (`--record FILE`) and [`image_file`] (register images kept in
//! files, read for `diff` and `simulate --from`).

pub mod demo;
pub mod image_file;
pub mod play;
pub mod record;
pub mod scan;
pub mod session;
pub mod simulate;
pub mod sniff;
pub mod tap;
