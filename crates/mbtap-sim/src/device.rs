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
    /// move; a recording's stay as last heard, or follow their recorded course when replayed.
    pub fn step(&mut self, t: f64) {
        match self {
            Self::Profile(s) => world::step(s, t),
            Self::Recorded(r) => r.step(t),
            Self::Mirror { .. } => {}
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
                    vec![function | mbtap_proto::EXCEPTION_FLAG, mbtap_device::profile::image::GATEWAY_TARGET_FAILED]
                })
            }
        }
    }

    /// A mirror's new values from its source (`fresh`: they are), or that the source is gone
    /// (`fresh` false, no values). Other devices ignore it.
    pub fn mirrored(&mut self, values: &[((mbtap_device::profile::Table, u16), u16)], now_fresh: bool) {
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

/// Sets a value on the device from outside (`simulate --values-from`, an MQTT `…/set`): by a
/// name of its profile or `TABLE ADDRESS`, the value as the profile holds it (a number at the
/// register's scale and type, on/off for a bit, a label where the profile lists them) — input
/// registers too, as a device's own measurements move. The value as now read back.
///
/// # Errors
/// The item is unknown, the value cannot be held there, or the address is outside the device.
pub fn set_value(
    device: &mut Device,
    item: &mbtap_device::query::items::Item,
) -> Result<Option<mbtap_device::query::rows::Row>, String> {
    use mbtap_device::profile::Table;
    let (profile, address) = match device {
        Device::Profile(s) | Device::Mirror { slave: s, .. } => (Some(s.profile().clone()), s.address()),
        Device::Recorded(r) => (None, r.address()),
    };
    let text = item.value.as_deref().ok_or_else(|| format!("{}: no value: give NAME=VALUE", item.text))?;
    let target = mbtap_device::query::resolve::resolve(item, profile.as_ref()).map_err(|e| e.to_string())?;
    let bits = matches!(target.table, Table::Coils | Table::DiscreteInputs);
    let def = profile.as_ref().and_then(|p| p.slot(target.table, target.first)).map(|(_, d)| d.clone());
    let number = text.trim().parse::<f64>().ok();
    let words: Vec<u16> = match (&def, number) {
        (_, _) if bits => {
            let on = matches!(text.trim().to_ascii_lowercase().as_str(), "1" | "on" | "true")
                || def.as_ref().and_then(|d| d.on.as_deref()).is_some_and(|on| on.eq_ignore_ascii_case(text.trim()));
            vec![u16::from(on)]
        }
        (Some(d), Some(v)) => {
            mbtap_device::query::encode::encode_number(v, d).map_err(|why| format!("{}: {why}", item.text))?
        }
        (Some(d), None) => {
            let raw = d
                .labels
                .iter()
                .chain(&d.commands)
                .find(|(_, l)| l.eq_ignore_ascii_case(text.trim()))
                .map(|(&k, _)| k)
                .ok_or_else(|| format!("{}: {text:?} is neither a number nor one of its labels", item.text))?;
            // A label's raw value, at the register's scale (labels are raw values).
            #[allow(clippy::cast_precision_loss)]
            let value = raw as f64 * d.scale.unwrap_or(1.0);
            mbtap_device::query::encode::encode_number(value, d).map_err(|why| format!("{}: {why}", item.text))?
        }
        (None, _) => text
            .split(',')
            .map(|v| v.trim().parse::<u16>().map_err(|_| format!("{}: {v:?} is not a 16-bit raw value", item.text)))
            .collect::<Result<_, _>>()?,
    };
    for (a, &w) in (target.first..).zip(&words) {
        let stored = match device {
            Device::Profile(s) | Device::Mirror { slave: s, .. } => s.set(target.table, a, w),
            Device::Recorded(r) => r.set(target.table, a, w),
        };
        if !stored {
            return Err(format!("{}: unit {address} has no {} {a}", item.text, target.table.name()));
        }
    }
    Ok(mbtap_device::query::rows::rows(address, target.table, target.first, &words, profile.as_ref())
        .into_iter()
        .next())
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
