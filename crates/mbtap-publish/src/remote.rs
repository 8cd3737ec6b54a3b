//! Writes asked for over MQTT, as items a `write` would take: a plain `…/set` topic or a
//! Sparkplug DCMD becomes the unit and the item (table, address or name, and the value as
//! text), or says why it cannot. Whether the value may be written — the profile's access, its
//! range, the scale — is the write path's to judge (`encode::encode_write`), as for a write typed
//! on the command line. Pure: topics and payloads in, items out.

use crate::sparkplug::node::metric_name;
use crate::sparkplug::{Payload, Value};
use mbtap_device::profile::Profiles;
use mbtap_device::query::items::{Item, What};
use mbtap_device::query::table_word;

/// What became of one ask: the value read back (if the read back answered), or why it was not
/// written.
pub type WriteResult = Result<Option<mbtap_device::query::rows::Row>, String>;

/// One write asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ask {
    pub unit: u8,
    pub item: Item,
}

/// A plain topic under `prefix`: `PREFIX/unit/U/TABLE/ADDRESS/set` with the value as the payload
/// (what a Home Assistant `number` or `switch` sends), or `PREFIX/unit/U/set` with `NAME=VALUE`
/// or `TABLE:ADDRESS=VALUE` (a name from the unit's profile). `None`: not a write topic of this
/// prefix. `Some(Err)`: one, but unreadable — why.
#[must_use]
pub fn parse_set(prefix: &str, topic: &str, payload: &[u8]) -> Option<Result<Ask, String>> {
    let rest = topic.strip_prefix(prefix)?.strip_prefix("/unit/")?;
    let levels: Vec<&str> = rest.split('/').collect();
    let (unit, tail) = levels.split_first()?;
    if tail.last() != Some(&"set") {
        return None;
    }
    Some((|| {
        let unit = unit.parse::<u8>().map_err(|_| format!("{topic}: {unit:?} is not a unit 0–255"))?;
        let text = std::str::from_utf8(payload).map_err(|_| format!("{topic}: the payload is not text"))?.trim();
        match tail {
            ["set"] => {
                let item = mbtap_device::query::items::parse_item(text, None).map_err(|e| format!("{topic}: {e}"))?;
                if item.value.is_none() {
                    return Err(format!("{topic}: {text:?} has no value: send NAME=VALUE"));
                }
                Ok(Ask { unit, item })
            }
            [table, address, "set"] => {
                let table = table_word(table).ok_or_else(|| format!("{topic}: {table:?} is no table"))?;
                let address = address.parse::<u16>().map_err(|_| format!("{topic}: {address:?} is no address"))?;
                Ok(Ask {
                    unit,
                    item: Item {
                        text: format!("{} {address}={text}", table.name()),
                        table: Some(table),
                        what: What::Range { first: address, last: address },
                        value: Some(text.to_owned()),
                    },
                })
            }
            _ => Err(format!("{topic}: expected PREFIX/unit/U/TABLE/ADDRESS/set or PREFIX/unit/U/set")),
        }
    })())
}

/// A Sparkplug DCMD to `device` (`PROFILE-U` or `unit-U`, as the node names its devices): one
/// ask per metric, by the metric's name as the node published it (the register's name, escaped)
/// or `TABLE ADDRESS` for registers without one. Errors say which metric and why.
#[must_use]
pub fn parse_dcmd(device: &str, payload: &[u8], profiles: &Profiles) -> Vec<Result<Ask, String>> {
    let Some(unit) = device.rsplit_once('-').and_then(|(_, u)| u.parse::<u8>().ok()) else {
        return vec![Err(format!("DCMD to {device:?}: not a device of this node (PROFILE-UNIT or unit-UNIT)"))];
    };
    let p = match Payload::parse_payload(payload) {
        Ok(p) => p,
        Err(e) => return vec![Err(format!("DCMD to {device}: not a Sparkplug payload: {e}"))],
    };
    p.metrics
        .iter()
        .map(|m| {
            let name = m.name.clone().unwrap_or_default();
            let value = match &m.value {
                Some(Value::Int(v)) => v.to_string(),
                Some(Value::Long(v)) => v.to_string(),
                Some(Value::Float(v)) => v.to_string(),
                Some(Value::Double(v)) => v.to_string(),
                Some(Value::Boolean(b)) => u8::from(*b).to_string(),
                Some(Value::String(s)) => s.clone(),
                Some(Value::Bytes(_)) | None => {
                    return Err(format!("DCMD to {device}: metric {name:?} has no value mbtap can write"));
                }
            };
            let (table, address) = find(&name, profiles.get(&unit))
                .ok_or_else(|| format!("DCMD to {device}: no register is published as {name:?}"))?;
            Ok(Ask {
                unit,
                item: Item {
                    text: format!("{name}={value}"),
                    table: Some(table),
                    what: What::Range { first: address, last: address },
                    value: Some(value),
                },
            })
        })
        .collect()
}

/// The register a metric name stands for: a profile name as the node escapes it, or
/// `TABLE ADDRESS`.
fn find(name: &str, profile: Option<&mbtap_device::profile::Profile>) -> Option<(mbtap_device::profile::Table, u16)> {
    if let Some(p) = profile {
        for (table, slots) in &p.tables {
            if let Some(slot) = slots.values().find(|s| metric_name(&s.name) == name) {
                return Some((*table, slot.first));
            }
        }
    }
    let (table, address) = name.split_once(' ')?;
    Some((table_word(table)?, address.parse().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparkplug::Metric;
    use mbtap_device::profile::Table;

    #[test]
    fn plain_set_topics_by_address_and_by_name() {
        let a = parse_set("site", "site/unit/1/holding_registers/105/set", b"12.5").unwrap().unwrap();
        assert_eq!(a.unit, 1);
        assert_eq!(a.item.table, Some(Table::HoldingRegisters));
        assert_eq!(a.item.what, What::Range { first: 105, last: 105 });
        assert_eq!(a.item.value.as_deref(), Some("12.5"));
        let b = parse_set("site", "site/unit/17/set", b"Setpoint=3").unwrap().unwrap();
        assert_eq!(b.item.what, What::Name("Setpoint".into()));
        assert!(parse_set("site", "site/unit/1/holding_registers/105", b"1").is_none(), "a value topic");
        assert!(parse_set("other", "site/unit/1/set", b"x=1").is_none(), "another prefix");
        for (topic, payload, why) in [
            ("site/unit/300/set", &b"x=1"[..], "unit"),
            ("site/unit/1/set", b"Setpoint", "no value"),
            ("site/unit/1/bogus/5/set", b"1", "no table"),
            ("site/unit/1/coils/x/set", b"1", "no address"),
            ("site/unit/1/holding_registers/5/set", b"\xFF", "not text"),
        ] {
            let e = parse_set("site", topic, payload).unwrap().unwrap_err();
            assert!(e.contains(why), "{topic}: {e}");
        }
    }

    #[test]
    fn dcmd_metrics_by_their_published_names() {
        let mk4 = mbtap_device::profile::builtin::get("mk4").unwrap().unwrap();
        let (table, address, name) = mk4
            .tables
            .iter()
            .flat_map(|(t, s)| s.iter().map(move |(a, slot)| (*t, *a, slot.name.clone())))
            .find(|(t, _, _)| *t == Table::HoldingRegisters)
            .unwrap();
        let profiles: Profiles = [(1u8, mk4)].into_iter().collect();
        let metric =
            |name: &str, value: Value| Metric { name: Some(name.into()), value: Some(value), ..Metric::default() };
        let payload = Payload {
            metrics: vec![
                metric(&metric_name(&name), Value::Double(7.0)),
                metric("coils 3", Value::Boolean(true)),
                metric("Nonsense", Value::Long(1)),
            ],
            ..Payload::default()
        };
        let asks = parse_dcmd("mk4-1", &payload.to_bytes(), &profiles);
        let first = asks[0].as_ref().unwrap();
        assert_eq!((first.unit, first.item.table, first.item.value.as_deref()), (1, Some(table), Some("7")));
        assert_eq!(first.item.what, What::Range { first: address, last: address });
        assert_eq!(asks[1].as_ref().unwrap().item.table, Some(Table::Coils));
        assert!(asks[2].as_ref().unwrap_err().contains("Nonsense"));
        assert!(parse_dcmd("nodash", b"", &profiles)[0].is_err());
        assert!(
            parse_dcmd("mk4-1", b"\xFF\xFF", &profiles)[0].as_ref().unwrap_err().contains("not a Sparkplug payload")
        );
    }
}
