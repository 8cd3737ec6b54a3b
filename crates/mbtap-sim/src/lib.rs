//! mbtap's simulated lines and devices, pure: devices that answer requests the way their profile,
//! a recording or a live device says; the virtual bus with its faults and the UART model; the
//! traffic generator with ground truth that the framer is scored against. A request PDU in, a
//! response PDU (or silence) out, time an input; the pseudo-terminal, the serial port and the
//! bridge's fronts sit at the edge (`src/cmd/simulate.rs`, `src/bridge/emulated.rs`).
//!
//! Above the analysis (a device emulated from a recording is built by an analyzer sink,
//! [`recording`]) and the device model (profiles); nothing below names this crate.
//!
//! - Devices: [`slave`] (a profile's device), [`recorded`] + [`recording`] (a recording's),
//!   [`mirror`] (another live device's), one [`device::Device`] over the three, [`answers`]
//!   (their read/write answers, one encoding).
//! - The line: [`bus`] (the virtual bus: master, devices, faults), [`world`] (what the devices measure),
//!   [`poll_list`], [`uart`] (what a receiver at other settings hears), [`scan_line`].
//! - [`traffic`] — synthetic traffic with ground truth, observation models, scoring.
//! - Values: [`meters`] (the built-in energy meters' moving values), [`store`] (a device's
//!   register values as a recording or an image gave them).

pub mod answers;
pub mod bus;
pub mod device;
pub mod fuzzing;
pub mod meters;
pub mod mirror;
pub mod poll_list;
pub mod recorded;
pub mod recording;
pub mod scan_line;
pub mod slave;
pub mod store;
pub mod traffic;
pub mod uart;
pub mod world;

pub use device::Device;
pub use recorded::RecordedDevice;
pub use recording::RecordedDevicesBuilder;
pub use scan_line::scan_line;
pub use slave::Slave;

pub use mbtap_device::profile::builtin::{DEMO_DEVICES, demo_profiles};
