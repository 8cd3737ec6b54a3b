//! Framers: turn [`Chunk`](crate::chunk::Chunk)s — bytes as reads delivered them, with the time
//! each read returned — into frames and noise. Pure: time is an input, never read.
//!
//! Modules: `event` (what the framers produce), `rtu` (the RTU framer), `ascii` (the ASCII framer),
//! `observer` (how late this observer's reads deliver bytes), `lengths` (frame lengths learned per
//! unit, function and direction), `glitch` (how often each side leaves a turnaround glitch).

pub mod ascii;
pub mod event;
mod glitch;
mod lengths;
pub mod observer;
pub mod rtu;

pub use ascii::AsciiFramer;
pub use event::{Frame, FrameEvent, Noise};
pub use mbtap_proto::serial_line::{LineSettings, Parity};
pub use observer::ObserverEstimate;
pub use rtu::{FramerConfig, RtuFramer};
