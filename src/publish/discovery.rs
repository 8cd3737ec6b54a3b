//! Home Assistant MQTT discovery: a sensor (or binary sensor) per named value heard, and with
//! writes from the broker on, a switch, select or number per writable register.

use mbtap_device::profile::Table;
use mbtap_device::query::rows::Row;

/// A Home Assistant discovery id: HA takes node and object ids of `[a-zA-Z0-9_-]` only and
/// ignores, with a log line the user never sees, a config whose topic has anything else (a
/// target's dots: `mbtap_vm_127.0.0.1_17502`). Every other character becomes `_`; when any did,
/// a hash of the original follows, so two prefixes that differ only there stay two devices. The
/// same prefix gives the same id on every run.
pub(super) fn ha_id(s: &str) -> String {
    let clean: String =
        s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect();
    if clean == s && !clean.is_empty() {
        return clean;
    }
    // FNV-1a, 32 bits: stable across runs and builds (a std hasher is not).
    let hash = s.bytes().fold(0x811c_9dc5_u32, |h, b| (h ^ u32::from(b)).wrapping_mul(0x0100_0193));
    format!("{clean}_{hash:08x}")
}

/// The discovery object id of a row: `u1_holding_registers_105`.
pub(super) fn discovery_object(r: &Row) -> String {
    format!("u{}_{}_{}", r.unit, r.table.name(), r.address)
}

/// A Home Assistant discovery message for `r`: (node id, object id, component, config).
/// Keys without a value are left out (`"manufacturer": null` for a profile without a
/// vendor, which Home Assistant's schema refuses: a string or no key); coils and discrete inputs
/// are binary sensors with the raw 1/0 as their state, not numeric sensors. A known unit is
/// spelled as Home Assistant does, with its device and state class; the device names
/// no `via_device` (it named a bridge device no config announced).
///
/// Writable registers are sensors here too; [`control`] makes them controls when writes from the
/// broker are on (a control whose commands nothing executes would mislead).
pub fn discovery(
    prefix: &str,
    r: &Row,
    profile: Option<&mbtap_device::profile::Profile>,
    state_topic: &str,
) -> (String, String, &'static str, serde_json::Value) {
    let node = ha_id(&prefix.replace('/', "_"));
    let object = discovery_object(r);
    let mut device = serde_json::json!({
        "identifiers": [format!("{node}_u{}", r.unit)],
        "name": format!("{} (unit {})", profile.map_or("Modbus device", |p| p.meta.device.as_str()), r.unit),
    });
    if let Some(d) = device.as_object_mut() {
        if let Some(vendor) = profile.and_then(|p| p.meta.vendor.clone()) {
            d.insert("manufacturer".into(), vendor.into());
        }
        if let Some(p) = profile {
            d.insert("model".into(), p.meta.name.clone().into());
        }
    }
    let bits = mbtap_device::query::is_bits(r.table);
    let mut config = serde_json::json!({
        "name": r.name,
        "unique_id": format!("{node}_{object}"),
        "object_id": format!("{node}_{object}"),
        "state_topic": state_topic,
        "availability_topic": format!("{prefix}/status"),
        "device": device,
    });
    if let Some(o) = config.as_object_mut() {
        if bits {
            o.insert("value_template".into(), "{{ value_json.raw }}".into());
            o.insert("payload_on".into(), "1".into());
            o.insert("payload_off".into(), "0".into());
        } else {
            o.insert("value_template".into(), "{{ value_json.value }}".into());
            // Home Assistant's spelling and classes (long-term statistics, the Energy dashboard).
            match r.unit_of_measure.as_deref().map(|u| (u, mbtap_device::profile::ha_classes::ha_class(u))) {
                Some((_, Some(c))) => {
                    o.insert("unit_of_measurement".into(), c.unit.into());
                    if let Some(d) = c.device_class {
                        o.insert("device_class".into(), d.into());
                    }
                    o.insert("state_class".into(), c.state_class.into());
                }
                Some((u, None)) => {
                    o.insert("unit_of_measurement".into(), u.into());
                }
                None => {}
            }
        }
    }
    (node, object, if bits { "binary_sensor" } else { "sensor" }, config)
}

/// With writes from the broker on (`watch --mqtt-writes`): a register the profile documents as
/// writable is announced as a control instead of a sensor — a coil as a `switch`, a register
/// with labels as a `select` of them, a numeric holding register as a `number` within its
/// documented range (scaled) — whose commands go to its
/// `…/set` topic and through the profile's checks. `None`: stays a sensor (read-only, labels,
/// text, or no profile).
pub fn control(
    r: &Row,
    profile: Option<&mbtap_device::profile::Profile>,
    state_topic: &str,
    mut config: serde_json::Value,
) -> Option<(&'static str, serde_json::Value)> {
    use mbtap_device::profile::format::Access;
    let (_, def) = profile?.slot(r.table, r.address)?;
    if def.access == Access::Read || !matches!(r.table, Table::Coils | Table::HoldingRegisters) {
        return None;
    }
    let o = config.as_object_mut()?;
    o.insert("command_topic".into(), format!("{state_topic}/set").into());
    if r.table == Table::Coils {
        o.insert("state_on".into(), "1".into());
        o.insert("state_off".into(), "0".into());
        return Some(("switch", config));
    }
    // A register with labels is a choice among them: a select whose option is written by its
    // label (the write path takes labels as `mbtap write` does).
    if !def.labels.is_empty() {
        let options: Vec<serde_json::Value> = def.labels.values().map(|l| l.clone().into()).collect();
        o.insert("options".into(), options.into());
        return Some(("select", config));
    }
    // Text is not a number; a value without a documented range is not offered as one either.
    if !r.value.is_number() {
        return None;
    }
    let (lo, hi) = def.range?;
    let scale = def.scale.unwrap_or(1.0);
    #[allow(clippy::cast_precision_loss)] // documented ranges are far inside f64's exact integers
    let (min, max) = (lo as f64 * scale, hi as f64 * scale);
    o.insert("min".into(), min.min(max).into());
    o.insert("max".into(), max.max(min).into());
    o.insert("step".into(), scale.abs().into());
    o.insert("mode".into(), "box".into());
    Some(("number", config))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Home Assistant takes `[a-zA-Z0-9_-]` ids only (a topic outside it is logged as illegal and
    /// ignored), so a prefix holding a target's address is mapped into it: ids stay in the
    /// alphabet, stable, and apart.
    #[test]
    fn discovery_ids_use_home_assistants_alphabet_and_stay_apart() {
        use mbtap_device::profile::Table;
        let mk4 = mbtap_device::profile::builtin::get("mk4").unwrap().unwrap();
        let regs = mbtap_device::query::rows::rows(2, Table::InputRegisters, 430, &[2304], Some(&mk4));
        let (node, object, _, config) = discovery("mbtap/vm/127.0.0.1:17502", &regs[0], Some(&mk4), "t");
        let legal = |s: &str| !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        assert!(legal(&node) && legal(&object), "{node} {object}");
        assert!(legal(config["unique_id"].as_str().unwrap()) && legal(config["object_id"].as_str().unwrap()));
        assert_eq!(node, ha_id("mbtap_vm_127.0.0.1:17502"), "the same on every run");
        assert_ne!(ha_id("a.b"), ha_id("a_b"), "two prefixes, two devices");
        assert_eq!(ha_id("mbtap_site"), "mbtap_site", "a legal id is kept as it is");
    }

    /// A config carries its device and state class (long-term statistics, the Energy
    /// dashboard) and names no `via_device` that no config announces: the MK4's voltage (input
    /// 430, `V`) is a voltage measurement.
    #[test]
    fn discovery_gives_classes_and_no_unannounced_via_device() {
        use mbtap_device::profile::Table;
        let mk4 = mbtap_device::profile::builtin::get("mk4").unwrap().unwrap();
        let regs = mbtap_device::query::rows::rows(1, Table::InputRegisters, 430, &[2304], Some(&mk4));
        let (_, _, component, config) = discovery("mbtap/site", &regs[0], Some(&mk4), "t");
        assert_eq!(component, "sensor");
        assert_eq!(config["unit_of_measurement"], "V", "{config}");
        assert_eq!(config["device_class"], "voltage", "{config}");
        assert_eq!(config["state_class"], "measurement", "{config}");
        assert!(config["device"].get("via_device").is_none(), "{config}");
    }

    /// The MKZP (a profile without a vendor) is announced without `"manufacturer"` (a `null`
    /// there fails Home Assistant's schema), and its coils as binary sensors.
    #[test]
    fn discovery_leaves_out_absent_keys_and_announces_bits_as_binary_sensors() {
        use mbtap_device::profile::Table;
        let mkzp = mbtap_device::profile::builtin::get("mkzp").unwrap().unwrap();
        assert!(mkzp.meta.vendor.is_none(), "the test needs a profile without a vendor");
        let regs = mbtap_device::query::rows::rows(17, Table::HoldingRegisters, 50, &[123], Some(&mkzp));
        let (_, _, component, config) = discovery("mbtap/site", &regs[0], Some(&mkzp), "t");
        assert_eq!(component, "sensor");
        assert!(!config.to_string().contains("null"), "{config}");
        assert!(config["device"].get("manufacturer").is_none(), "{config}");
        let mk4 = mbtap_device::profile::builtin::get("mk4").unwrap().unwrap();
        let coil = mbtap_device::query::rows::rows(1, Table::Coils, 0, &[1], Some(&mk4));
        let (_, _, component, config) = discovery("mbtap/site", &coil[0], Some(&mk4), "t");
        assert_eq!(component, "binary_sensor");
        assert_eq!((config["payload_on"].as_str(), config["payload_off"].as_str()), (Some("1"), Some("0")));
        assert_eq!(config["value_template"], "{{ value_json.raw }}");
        assert!(config.get("unit_of_measurement").is_none());
        assert!(config["device"]["manufacturer"].is_string(), "the MK4 has a vendor: {config}");
    }

    /// With writes on, writable registers become Home Assistant controls — a rw coil a
    /// switch, a ranged set point a number within its scaled range — and the rest stay sensors.
    #[test]
    fn writable_registers_are_announced_as_controls() {
        use mbtap_device::profile::Table;
        let mk4 = mbtap_device::profile::builtin::get("mk4").unwrap().unwrap();
        let row = |table, address, raw: u16| {
            mbtap_device::query::rows::rows(1, table, address, &[raw], Some(&mk4)).into_iter().next().unwrap()
        };
        let announce = |r: &Row| {
            let (_, _, _, config) = discovery("p", r, Some(&mk4), "p/unit/1/x");
            control(r, Some(&mk4), "p/unit/1/x", config)
        };
        let (component, config) = announce(&row(Table::Coils, 0, 1)).unwrap();
        assert_eq!(component, "switch");
        assert_eq!(config["command_topic"], "p/unit/1/x/set");
        assert!(announce(&row(Table::Coils, 3, 1)).is_none(), "coil 3 is documented read-only");
        let (component, config) = announce(&row(Table::HoldingRegisters, 105, 250)).unwrap();
        assert_eq!(component, "number");
        assert_eq!(
            (config["min"].as_f64(), config["max"].as_f64(), config["step"].as_f64()),
            (Some(0.0), Some(100.0), Some(0.01))
        );
        let (component, config) = announce(&row(Table::HoldingRegisters, 101, 0)).unwrap();
        assert_eq!(component, "select", "an enumeration is a choice");
        assert_eq!(config["options"][1], "fill by level sensors");
        assert!(announce(&row(Table::InputRegisters, 430, 2305)).is_none(), "input registers are read-only");
    }
}
