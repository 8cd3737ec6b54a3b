//! Home Assistant's `modbus:` YAML read straight into what the import uses: the hubs'
//! `sensors`, `binary_sensors` and `switches` with the dozen keys an entry may carry, everything
//! else skipped as it is read. No tree of the whole document is built (200 000 sensors took
//! 540 MB as a `serde_norway::Value`, about 30 bytes per byte of YAML), nor a list of its events
//! (serde_norway's reader held 201 MB of them for the same file): serde-saphyr streams.
//!
//! The shapes a user has: a whole `configuration.yaml` (a `modbus:` key among others), the list
//! of hubs an `!include` names, or one hub (a mapping with entry lists).

use std::fmt;

use serde::de::{self, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde_saphyr::Tagged;

use super::ha_entry::{Entry, Read, Scalar, untagged};

/// A hub's list of `kind` entries, each converted as it is read; anything else where the list
/// belongs holds none.
struct EntriesOf(&'static str);

impl<'de> de::DeserializeSeed<'de> for EntriesOf {
    type Value = Vec<Read>;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Vec<Read>, D::Error> {
        struct V(&'static str);
        impl<'de> Visitor<'de> for V {
            type Value = Vec<Read>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a list of entries")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<Vec<Read>, A::Error> {
                let mut out = Vec::new();
                while let Some(e) = s.next_element::<Tagged<Entry>>()? {
                    out.push(Read::of(self.0, out.len(), &untagged(e, Entry::not_keys)));
                }
                Ok(out)
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Vec<Read>, A::Error> {
                while m.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
                Ok(Vec::new())
            }
            fn visit_str<E>(self, _: &str) -> Result<Vec<Read>, E> {
                Ok(Vec::new())
            }
            fn visit_bool<E>(self, _: bool) -> Result<Vec<Read>, E> {
                Ok(Vec::new())
            }
            fn visit_u64<E>(self, _: u64) -> Result<Vec<Read>, E> {
                Ok(Vec::new())
            }
            fn visit_i64<E>(self, _: i64) -> Result<Vec<Read>, E> {
                Ok(Vec::new())
            }
            fn visit_f64<E>(self, _: f64) -> Result<Vec<Read>, E> {
                Ok(Vec::new())
            }
            fn visit_unit<E>(self) -> Result<Vec<Read>, E> {
                Ok(Vec::new())
            }
        }
        d.deserialize_any(V(self.0))
    }
}

/// A mapping as a hub reads it (the document's top level too): its entry lists, its unit, the
/// platforms a profile has no equivalent for, and — at the top — the `modbus:` key's hubs.
#[derive(Debug, Default)]
pub struct Level {
    /// A mapping at all (a hub must be one).
    pub mapping: bool,
    /// Has a `sensors`, `binary_sensors` or `switches` key (whatever its value): a hub.
    pub hub: bool,
    pub sensors: Vec<Read>,
    pub binary_sensors: Vec<Read>,
    pub switches: Vec<Read>,
    pub slave: Option<Scalar>,
    pub device_address: Option<Scalar>,
    /// `climates`, `covers`, `fans`, `lights` present.
    pub other: [bool; 4],
    /// The `modbus:` key's value: its hubs (a list, or one hub).
    pub modbus: Option<Vec<Level>>,
    /// Not a mapping, but a list of levels (the document as an `!include`d list of hubs).
    pub list: Option<Vec<Level>>,
}

/// The platforms a hub may have that a profile cannot hold.
pub const OTHER_PLATFORMS: [&str; 4] = ["climates", "covers", "fans", "lights"];

impl Level {
    /// The unit a hub names (`device_address` first, then `slave`).
    #[must_use]
    pub fn unit(&self) -> Option<u64> {
        [&self.device_address, &self.slave].into_iter().find_map(|s| s.as_ref().and_then(Scalar::as_u64))
    }

    /// The entries read, in the import's order: sensors, binary sensors, switches.
    pub fn reads(&self) -> impl Iterator<Item = &Read> {
        self.sensors.iter().chain(&self.binary_sensors).chain(&self.switches)
    }

    /// The entries read, taken, in the same order.
    pub fn into_reads(self) -> impl Iterator<Item = Read> {
        self.sensors.into_iter().chain(self.binary_sensors).chain(self.switches)
    }
}

impl<'de> de::Deserialize<'de> for Level {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Level;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a Home Assistant configuration or `modbus:` hub")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Level, A::Error> {
                let mut l = Level { mapping: true, ..Level::default() };
                while let Some(key) = m.next_key::<Scalar>()? {
                    let Scalar::Text(k) = key else {
                        m.next_value::<IgnoredAny>()?;
                        continue;
                    };
                    match k.as_str() {
                        "sensors" => (l.hub, l.sensors) = (true, m.next_value_seed(EntriesOf("sensors"))?),
                        "binary_sensors" => {
                            (l.hub, l.binary_sensors) = (true, m.next_value_seed(EntriesOf("binary_sensors"))?);
                        }
                        "switches" => (l.hub, l.switches) = (true, m.next_value_seed(EntriesOf("switches"))?),
                        "slave" => l.slave = Some(untagged(m.next_value()?, || Scalar::Other)),
                        "device_address" => l.device_address = Some(untagged(m.next_value()?, || Scalar::Other)),
                        "modbus" => {
                            let v = untagged(m.next_value::<Tagged<Level>>()?, Level::default);
                            l.modbus = Some(match v.list {
                                Some(hubs) => hubs,
                                None if v.mapping => vec![v],
                                None => Vec::new(),
                            });
                        }
                        other => {
                            if let Some(i) = OTHER_PLATFORMS.iter().position(|p| *p == other) {
                                l.other[i] = true;
                            }
                            m.next_value::<IgnoredAny>()?;
                        }
                    }
                }
                // An entry without a unit of its own is its hub's, whichever key came first.
                if let Some(unit) = l.unit() {
                    for r in l.sensors.iter_mut().chain(&mut l.binary_sensors).chain(&mut l.switches) {
                        r.unit = r.unit.or(Some(unit));
                    }
                }
                Ok(l)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<Level, A::Error> {
                let mut list = Vec::new();
                while let Some(x) = s.next_element::<Tagged<Level>>()? {
                    list.push(untagged(x, Level::default));
                }
                Ok(Level { list: Some(list), ..Level::default() })
            }
            fn visit_str<E>(self, _: &str) -> Result<Level, E> {
                Ok(Level::default())
            }
            fn visit_bool<E>(self, _: bool) -> Result<Level, E> {
                Ok(Level::default())
            }
            fn visit_u64<E>(self, _: u64) -> Result<Level, E> {
                Ok(Level::default())
            }
            fn visit_i64<E>(self, _: i64) -> Result<Level, E> {
                Ok(Level::default())
            }
            fn visit_f64<E>(self, _: f64) -> Result<Level, E> {
                Ok(Level::default())
            }
            fn visit_unit<E>(self) -> Result<Level, E> {
                Ok(Level::default())
            }
        }
        d.deserialize_any(V)
    }
}

/// The hubs of a document: the `modbus:` key's when there is one, else the document's own list
/// of hubs or the document as one hub.
#[must_use]
pub fn hubs(mut doc: Level) -> Vec<Level> {
    let candidates = match (doc.modbus.take(), doc.list.take()) {
        (Some(hubs), _) | (None, Some(hubs)) => hubs,
        (None, None) => vec![doc],
    };
    candidates.into_iter().filter(|h| h.mapping && h.hub).collect()
}
