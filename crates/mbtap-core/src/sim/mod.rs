//! Simulated slaves for the virtual bus: devices that answer requests the way their profile
//! (and the document behind it) says. Pure like the rest of the core: a request PDU in, a
//! response PDU (or silence) out, time an input; the pseudo-terminal sits at the edge
//! (`simulate_cmd`).

pub mod answers;
pub mod ascii_requests;
pub mod bus;
pub mod device;
pub mod mirror;
pub mod poll_list;
pub mod recorded;
pub mod recording;
pub mod rtu_requests;
pub mod slave;
pub mod uart;
pub mod world;

pub use ascii_requests::AsciiRequestAssembler;
pub use device::Device;
pub use recorded::RecordedDevice;
pub use recording::Recorder;
pub use rtu_requests::{RequestAssembler, RequestFrame};
pub use slave::Slave;

/// The devices of the demo line and their addresses (`mbtap demo`, `mbtap simulate`'s default).
pub const DEMO_DEVICES: [(&str, u8); 3] = [("mk4", 1), ("display", 5), ("mkzp", 17)];

/// The profiles of the demo's devices, by address.
///
/// # Errors
/// When a built-in profile does not load (a build defect, caught by the tests).
pub fn demo_profiles() -> Result<crate::profile::Profiles, crate::profile::ProfileError> {
    let mut out = crate::profile::Profiles::new();
    for (name, address) in DEMO_DEVICES {
        if let Some(profile) = crate::profile::builtin::get(name) {
            out.insert(address, profile?);
        }
    }
    Ok(out)
}
