//! One entry of a Home Assistant `modbus:` hub (a sensor, binary sensor or switch): the keys the
//! import reads, and the point it becomes — converted as the YAML is read, so a file of
//! 200 000 sensors holds its points, not its entries as well.

use std::fmt;

use serde::de::{self, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

use super::{Point, Problem};
use crate::profile::Table;
use crate::profile::format::{Access, ValueType, WordOrder};

/// A scalar as YAML typed it; a list or a mapping where a scalar belongs is `Other`.
#[derive(Debug, Clone, PartialEq)]
pub enum Scalar {
    Bool(bool),
    Unsigned(u64),
    Signed(i64),
    Float(f64),
    Text(String),
    Other,
}

impl Scalar {
    /// A non-negative integer (a signed one too, when it is not negative).
    #[must_use]
    pub fn as_u64(&self) -> Option<u64> {
        match *self {
            Self::Unsigned(n) => Some(n),
            Self::Signed(n) => u64::try_from(n).ok(),
            _ => None,
        }
    }

    /// Any number, an integer as the float nearest it.
    #[must_use]
    #[allow(clippy::cast_precision_loss)] // YAML integers given where a float is read.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Self::Unsigned(n) => Some(n as f64),
            Self::Signed(n) => Some(n as f64),
            Self::Float(f) => Some(f),
            _ => None,
        }
    }

    /// A scalar as text: a string as it is, a number or a boolean as YAML would print it.
    #[must_use]
    pub fn text(&self) -> Option<String> {
        match self {
            Self::Text(s) => Some(s.clone()),
            Self::Unsigned(n) => Some(n.to_string()),
            Self::Signed(n) => Some(n.to_string()),
            Self::Float(f) => Some(f.to_string()),
            Self::Bool(b) => Some(b.to_string()),
            Self::Other => None,
        }
    }
}

/// A node's value, or `other` when it carries an application tag (`!secret host`, `!lambda …`,
/// `!include other.yaml`, `!!python/object …`): a tag is plain data to the import — nothing is
/// resolved or run — and its content is not the value Home Assistant would see (a secret's
/// name is not the secret), so the node counts as no value (a hostile probe's `tags.yaml`).
/// The core schema's own tags (`!!str`, `!!int`, …, and the non-specific `!`) only type it.
pub(super) fn untagged<T>(node: serde_saphyr::Tagged<T>, other: impl FnOnce() -> T) -> T {
    // YAML 1.2 §10.3 (core schema) and the failsafe/JSON schemas' tags, as the parser resolves
    // `!!name` to `tag:yaml.org,2002:name`.
    const CORE: [&str; 8] = ["str", "int", "float", "bool", "null", "map", "seq", "binary"];
    let core = |t: &str| t == "!" || t.strip_prefix("tag:yaml.org,2002:").is_some_and(|n| CORE.contains(&n));
    match node.1 {
        Some(tag) if !core(&tag) => other(),
        _ => node.0,
    }
}

impl<'de> de::Deserialize<'de> for Scalar {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Scalar;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a scalar")
            }
            fn visit_bool<E>(self, v: bool) -> Result<Scalar, E> {
                Ok(Scalar::Bool(v))
            }
            fn visit_u64<E>(self, v: u64) -> Result<Scalar, E> {
                Ok(Scalar::Unsigned(v))
            }
            fn visit_i64<E>(self, v: i64) -> Result<Scalar, E> {
                Ok(Scalar::Signed(v))
            }
            fn visit_f64<E>(self, v: f64) -> Result<Scalar, E> {
                Ok(Scalar::Float(v))
            }
            fn visit_str<E>(self, v: &str) -> Result<Scalar, E> {
                Ok(Scalar::Text(v.to_owned()))
            }
            fn visit_string<E>(self, v: String) -> Result<Scalar, E> {
                Ok(Scalar::Text(v))
            }
            fn visit_unit<E>(self) -> Result<Scalar, E> {
                Ok(Scalar::Other)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<Scalar, A::Error> {
                while s.next_element::<IgnoredAny>()?.is_some() {}
                Ok(Scalar::Other)
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Scalar, A::Error> {
                while m.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
                Ok(Scalar::Other)
            }
        }
        d.deserialize_any(V)
    }
}

/// An entry read: the unit it names (its own, else its hub's, filled in when the hub ends) and
/// its point, or why it cannot be one.
#[derive(Debug, Clone)]
pub struct Read {
    pub unit: Option<u64>,
    pub point: Result<Point, Problem>,
}

impl Read {
    /// Entry `index` of the hub's `kind` list.
    #[must_use]
    pub fn of(kind: &str, index: usize, e: &Entry) -> Self {
        let name = text(e.name.as_ref()).unwrap_or_default();
        let at = format!("{kind}[{index}] {name:?}");
        let point = match to_point(kind, e, &name) {
            Ok(p) => Ok(Point { origin: at, ..p }),
            Err((key, why)) => Err(Problem { at, column: Some(key.to_owned()), why }),
        };
        Self { unit: e.unit(), point }
    }
}

/// The keys of an entry the import reads, each as given (absent: `None`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Entry {
    pub name: Option<Scalar>,
    pub address: Option<Scalar>,
    pub input_type: Option<Scalar>,
    pub write_type: Option<Scalar>,
    pub unit_of_measurement: Option<Scalar>,
    pub count: Option<Scalar>,
    pub data_type: Option<Scalar>,
    pub swap: Option<Scalar>,
    pub scale: Option<Scalar>,
    pub offset: Option<Scalar>,
    pub slave: Option<Scalar>,
    pub device_address: Option<Scalar>,
    /// Given as something other than a mapping of keys (a tagged node, a list, a scalar).
    pub not_keys: bool,
}

impl Entry {
    /// An entry given as something other than a mapping of keys.
    pub(super) fn not_keys() -> Self {
        Self { not_keys: true, ..Self::default() }
    }

    /// The unit this entry names (`device_address` first, then `slave`).
    #[must_use]
    pub fn unit(&self) -> Option<u64> {
        [&self.device_address, &self.slave].into_iter().find_map(|s| s.as_ref().and_then(Scalar::as_u64))
    }
}

impl<'de> de::Deserialize<'de> for Entry {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Entry;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("an entry")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Entry, A::Error> {
                let mut e = Entry::default();
                while let Some(key) = m.next_key::<Scalar>()? {
                    let Scalar::Text(k) = key else {
                        m.next_value::<IgnoredAny>()?;
                        continue;
                    };
                    let slot = match k.as_str() {
                        "name" => &mut e.name,
                        "address" => &mut e.address,
                        "input_type" => &mut e.input_type,
                        "write_type" => &mut e.write_type,
                        "unit_of_measurement" => &mut e.unit_of_measurement,
                        "count" => &mut e.count,
                        "data_type" => &mut e.data_type,
                        "swap" => &mut e.swap,
                        "scale" => &mut e.scale,
                        "offset" => &mut e.offset,
                        "slave" => &mut e.slave,
                        "device_address" => &mut e.device_address,
                        _ => {
                            m.next_value::<IgnoredAny>()?;
                            continue;
                        }
                    };
                    *slot = Some(untagged(m.next_value()?, || Scalar::Other));
                }
                Ok(e)
            }
            // Not a mapping: an entry with nothing in it (the import says what is missing).
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<Entry, A::Error> {
                while s.next_element::<IgnoredAny>()?.is_some() {}
                Ok(Entry::not_keys())
            }
            fn visit_str<E>(self, _: &str) -> Result<Entry, E> {
                Ok(Entry::not_keys())
            }
            fn visit_bool<E>(self, _: bool) -> Result<Entry, E> {
                Ok(Entry::not_keys())
            }
            fn visit_u64<E>(self, _: u64) -> Result<Entry, E> {
                Ok(Entry::not_keys())
            }
            fn visit_i64<E>(self, _: i64) -> Result<Entry, E> {
                Ok(Entry::not_keys())
            }
            fn visit_f64<E>(self, _: f64) -> Result<Entry, E> {
                Ok(Entry::not_keys())
            }
            fn visit_unit<E>(self) -> Result<Entry, E> {
                Ok(Entry::not_keys())
            }
        }
        d.deserialize_any(V)
    }
}

fn text(v: Option<&Scalar>) -> Option<String> {
    v.and_then(Scalar::text)
}

fn to_point(kind: &str, e: &Entry, name: &str) -> Result<Point, (&'static str, String)> {
    if e.not_keys {
        return Err((
            "entry",
            "not a mapping of keys (a tagged node such as !include, a list or a value): not read".to_owned(),
        ));
    }
    let address =
        e.address.as_ref().and_then(Scalar::as_u64).ok_or(("address", "missing or not a number".to_owned()))?;
    let address = u16::try_from(address).map_err(|_| ("address", format!("{address} is past 65535")))?;
    let input_type = text(e.input_type.as_ref()).or_else(|| text(e.write_type.as_ref()));
    let default = if kind == "sensors" { "holding" } else { "coil" };
    let input_type = input_type.as_deref().unwrap_or(default);
    let table = match input_type {
        "holding" | "holdings" => Table::HoldingRegisters,
        "input" => Table::InputRegisters,
        "coil" | "coils" => Table::Coils,
        "discrete_input" => Table::DiscreteInputs,
        other => return Err(("input_type", format!("{other:?} is not holding, input, coil or discrete_input"))),
    };
    let access = if kind == "switches" { Access::ReadWrite } else { Access::Read };
    let mut p = Point {
        table,
        address,
        name: if name.is_empty() { format!("reg_{address}") } else { name.to_owned() },
        value_type: ValueType::U16,
        word_order: WordOrder::HighFirst,
        scale: None,
        unit: text(e.unit_of_measurement.as_ref()),
        access,
        length: None,
        description: None,
        origin: String::new(),
    };
    if kind != "sensors" || matches!(table, Table::Coils | Table::DiscreteInputs) {
        p.value_type = ValueType::Bool;
        return Ok(p);
    }
    let count = e.count.as_ref().and_then(Scalar::as_u64).and_then(|c| u16::try_from(c).ok());
    let data_type = text(e.data_type.as_ref()).unwrap_or_else(|| "int16".to_owned());
    p.value_type = match data_type.as_str() {
        "int16" | "int" => ValueType::I16,
        "uint16" | "uint" => ValueType::U16,
        "int32" => ValueType::I32,
        "uint32" => ValueType::U32,
        "int64" => ValueType::I64,
        "uint64" => ValueType::U64,
        "float32" | "float" => ValueType::F32,
        "string" => {
            p.length = Some(count.ok_or(("count", "a string needs its count of registers".to_owned()))?);
            ValueType::String
        }
        other => {
            return Err((
                "data_type",
                format!(
                    "{other:?}: not in the profile format (int16, uint16, int32, uint32, int64, uint64, float32, string)"
                ),
            ));
        }
    };
    match text(e.swap.as_ref()).as_deref() {
        None | Some("none") => {}
        Some("word")
            if matches!(
                p.value_type,
                ValueType::I32 | ValueType::U32 | ValueType::F32 | ValueType::I64 | ValueType::U64
            ) =>
        {
            p.word_order = WordOrder::LowFirst;
        }
        Some(other) => return Err(("swap", format!("{other:?}: byte swaps are not in the profile format"))),
    }
    if let Some(s) = &e.scale {
        let k = s.as_f64().ok_or(("scale", "not a number".to_owned()))?;
        if k == 0.0 || !k.is_finite() {
            return Err(("scale", format!("{k} is not a usable scale")));
        }
        p.scale = ((k - 1.0).abs() > f64::EPSILON).then_some(k);
    }
    if e.offset.as_ref().and_then(Scalar::as_f64).is_some_and(|o| o != 0.0) {
        return Err(("offset", "offsets are not in the profile format".to_owned()));
    }
    Ok(p)
}
