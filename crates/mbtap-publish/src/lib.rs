//! mbtap's publishing, pure: what goes to a broker and what comes back from one.
//!
//! - [`sparkplug`] — Sparkplug B 3.0: the protobuf payload and the edge node's state machine.
//! - [`spool`] — the store-and-forward buffer's record format (the files are the binary's).
//! - [`remote`] — writes asked for over MQTT (`…/set` topics, Sparkplug DCMD) as items a `write`
//!   would take.
//! - [`fuzzing`] — the bodies of this crate's fuzz targets, also run over the seeds by `cargo test`.
//!
//! Above the device model (a write names a profile's register); the MQTT client, the clock and
//! the files sit at the edge (`src/publish/`).

pub mod fuzzing;
pub mod remote;
pub mod sparkplug;
pub mod spool;
