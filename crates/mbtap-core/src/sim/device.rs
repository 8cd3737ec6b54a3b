//! An emulated device, whatever it was made from: a profile ([`Slave`], values at rest and
//! moving with the clock), a recording ([`RecordedDevice`], answering as it did) or another
//! device it mirrors (a [`Slave`] of the served profile whose values the shell sets from the
//! source, [`super::mirror`]). The I/O
//! shells (`simulate` on a pseudo-terminal, the bridge's fronts) hold these and nothing else.

use super::recorded::RecordedDevice;
use super::{Slave, world};

/// One device on the emulated line.
#[derive(Debug, Clone)]
pub enum Device {
    Profile(Slave),
    Recorded(RecordedDevice),
    /// Values from another device; `fresh` false once the source stopped answering: every
    /// request then gets exception 0B (MAP v1.1b3 §7: the target failed to respond), never a
    /// stale value presented as current.
    Mirror {
        slave: Slave,
        fresh: bool,
    },
}

impl Device {
    /// The address it answers at.
    #[must_use]
    pub const fn address(&self) -> u8 {
        match self {
            Self::Profile(s) | Self::Mirror { slave: s, .. } => s.address(),
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
            Self::Mirror { slave, fresh: true } => slave.handle(unit, pdu),
            Self::Mirror { slave, fresh: false } => {
                let function = *pdu.first()?;
                (unit == slave.address()).then(|| {
                    vec![function | crate::proto::EXCEPTION_FLAG, crate::profile::image::GATEWAY_TARGET_FAILED]
                })
            }
        }
    }

    /// A mirror's new values from its source (`fresh`: they are), or that the source is gone
    /// (`fresh` false, no values). Other devices ignore it.
    pub fn mirrored(&mut self, values: &[((crate::profile::Table, u16), u16)], now_fresh: bool) {
        if let Self::Mirror { slave, fresh } = self {
            for &((table, address), v) in values {
                slave.set(table, address, v);
            }
            *fresh = now_fresh;
        }
    }

    /// Its own time to answer, when it has one (a recording's median), in nanoseconds.
    #[must_use]
    pub fn latency_ns(&self) -> Option<u64> {
        match self {
            Self::Profile(_) | Self::Mirror { .. } => None,
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
