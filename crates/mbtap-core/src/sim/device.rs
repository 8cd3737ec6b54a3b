//! An emulated device, whatever it was made from: a profile ([`Slave`], values at rest and
//! moving with the clock) or a recording ([`RecordedDevice`], answering as it did). The I/O
//! shells (`simulate` on a pseudo-terminal, the bridge's fronts) hold these and nothing else.

use super::recorded::RecordedDevice;
use super::{Slave, world};

/// One device on the emulated line.
#[derive(Debug, Clone)]
pub enum Device {
    Profile(Slave),
    Recorded(RecordedDevice),
}

impl Device {
    /// The address it answers at.
    #[must_use]
    pub const fn address(&self) -> u8 {
        match self {
            Self::Profile(s) => s.address(),
            Self::Recorded(r) => r.address(),
        }
    }

    /// Moves its values to the time `t` (seconds since the start): a profile's measurements
    /// move; a recording's stay as heard.
    pub fn step(&mut self, t: f64) {
        if let Self::Profile(s) = self {
            world::step(s, t);
        }
    }

    /// Handles one request PDU addressed to `unit`: the response PDU, or `None` when the
    /// device stays silent (another unit's request, a broadcast).
    pub fn handle(&mut self, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        match self {
            Self::Profile(s) => s.handle(unit, pdu),
            Self::Recorded(r) => r.handle(unit, pdu),
        }
    }

    /// Its own time to answer, when it has one (a recording's median), in nanoseconds.
    #[must_use]
    pub fn latency_ns(&self) -> Option<u64> {
        match self {
            Self::Profile(_) => None,
            Self::Recorded(r) => r.latency.map(|l| l.median_ns),
        }
    }
}

/// The answer of the first of `devices` that answers `unit` (only one answers an address:
/// two on one address is a fault, not a simulation), with that device's own latency.
pub fn answer(devices: &mut [Device], unit: u8, pdu: &[u8], t: f64) -> Option<(Vec<u8>, Option<u64>)> {
    let mut first = None;
    for d in devices.iter_mut() {
        d.step(t);
        // Every device acts on a broadcast; none answers it.
        if let Some(answer) = d.handle(unit, pdu)
            && first.is_none()
        {
            first = Some((answer, d.latency_ns()));
            if unit != super::slave::BROADCAST {
                break;
            }
        }
    }
    first
}
