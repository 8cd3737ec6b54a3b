//! A model's registers decoded into its points: types as the SunSpec Information Model
//! Specification defines them, scale factors (`sf` points: value × 10^sf) applied, and the
//! "not implemented" values of each type (§6.2: int16 0x8000, uint16/enum16/bitfield16 0xFFFF,
//! acc 0, int32 0x80000000, uint32 0xFFFFFFFF, float32 NaN, a string of NULs) as absent.

use std::fmt::Write as _;

use super::{Count, Found, ModelDef, PointDef, Sf};

/// One decoded point.
#[derive(Debug, Clone, PartialEq)]
pub struct Value {
    /// The point's name inside its model: `Mn`, `module[1].DCA` (a repeating group's instance,
    /// from 1); `raw` for a model not known.
    pub point: String,
    /// The address of its first register.
    pub address: u16,
    /// Its registers as read.
    pub registers: Vec<u16>,
    /// The value; `None` where the device says "not implemented".
    pub shown: Option<Shown>,
    pub units: Option<String>,
}

/// A decoded value.
#[derive(Debug, Clone, PartialEq)]
pub enum Shown {
    /// A number, scaled, with the decimals its scale factor gives.
    Number {
        value: f64,
        decimals: u8,
    },
    Text(String),
}

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Number { value, decimals } => write!(f, "{value:.*}", usize::from(*decimals)),
            Self::Text(t) => write!(f, "{t:?}"),
        }
    }
}

/// A point's raw value: an integer (for numbers and scale factors), or text.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Raw {
    Int(i128),
    Float(f32),
}

fn join(r: &[u16]) -> u128 {
    r.iter().fold(0u128, |acc, &w| (acc << 16) | u128::from(w))
}

/// The raw number of a numeric point, `None` when not implemented or not numeric.
fn raw_number(kind: &str, r: &[u16]) -> Option<Raw> {
    let v = join(r);
    let bits = 16 * u32::try_from(r.len().min(8)).unwrap_or(8);
    let all_ones = if bits >= 128 { u128::MAX } else { (1u128 << bits) - 1 };
    let sign_only = 1u128 << bits.saturating_sub(1);
    let signed = |v: u128| -> i128 {
        let v = i128::try_from(v).unwrap_or(0);
        if bits < 128 && v >= 1i128 << (bits - 1) { v - (1i128 << bits) } else { v }
    };
    match kind {
        "uint16" | "enum16" | "bitfield16" | "uint32" | "enum32" | "bitfield32" | "uint64" => {
            (v != all_ones).then(|| Raw::Int(i128::try_from(v).unwrap_or(0)))
        }
        "count" => Some(Raw::Int(i128::try_from(v).unwrap_or(0))),
        "acc16" | "acc32" | "acc64" => (v != 0).then(|| Raw::Int(i128::try_from(v).unwrap_or(0))),
        "int16" | "sunssf" | "int32" | "int64" => (v != sign_only).then(|| Raw::Int(signed(v))),
        "float32" => {
            let f = f32::from_bits(u32::try_from(v).unwrap_or(0));
            (!f.is_nan()).then_some(Raw::Float(f))
        }
        _ => None,
    }
}

/// A point's scale factor as found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scale {
    /// The point has none.
    Unscaled,
    Factor(i16),
    /// Its scale factor point is not implemented (or not there): no value can be given.
    Unknown,
}

/// A point's value and, when numeric, scaled by `sf`.
fn shown(p: &PointDef, r: &[u16], sf: Scale) -> Option<Shown> {
    match p.kind.as_str() {
        "string" => {
            let bytes: Vec<u8> = r.iter().flat_map(|w| w.to_be_bytes()).collect();
            let text = String::from_utf8_lossy(&bytes).trim_end_matches('\0').trim_end().to_owned();
            (!text.is_empty()).then_some(Shown::Text(text))
        }
        "ipaddr" => (join(r) != 0).then(|| {
            let b: Vec<String> = r.iter().flat_map(|w| w.to_be_bytes()).map(|x| x.to_string()).collect();
            Shown::Text(b.join("."))
        }),
        "ipv6addr" | "eui48" => (join(r) != 0).then(|| {
            let mut s = String::new();
            for w in r {
                let _ = write!(s, "{w:04X}");
            }
            Shown::Text(s)
        }),
        "pad" => None,
        kind => {
            let raw = raw_number(kind, r)?;
            // A point with a scale factor whose own value is not implemented has no value.
            let sf = match sf {
                Scale::Factor(sf) => sf,
                Scale::Unknown => return None,
                Scale::Unscaled => 0,
            };
            let scale = 10f64.powi(i32::from(sf));
            let decimals = u8::try_from(-i32::from(sf).min(0)).unwrap_or(0).min(10);
            Some(match raw {
                #[allow(clippy::cast_precision_loss)]
                Raw::Int(i) => Shown::Number { value: i as f64 * scale, decimals },
                Raw::Float(f) => {
                    // The float's shortest decimal form, as pysunspec2 shows it.
                    let v = f.to_string().parse::<f64>().unwrap_or_else(|_| f64::from(f));
                    Shown::Number { value: v * scale, decimals: if sf == 0 { 3 } else { decimals } }
                }
            })
        }
    }
}

/// Lays `points` out from register `start` of `block`: (point, offset) while they fit.
fn layout<'p>(points: &'p [PointDef], start: usize, block: &[u16]) -> Vec<(&'p PointDef, usize)> {
    let mut out = Vec::new();
    let mut at = start;
    for p in points {
        let end = at + usize::from(p.size.max(1));
        if end > block.len() {
            break;
        }
        out.push((p, at));
        at = end;
    }
    out
}

/// The scale factor named `name` among `points` laid out in `block`: `None` when there is no
/// such point; [`Scale::Unknown`] when the device does not implement it.
fn sf_of(name: &str, laid: &[(&PointDef, usize)], block: &[u16]) -> Option<Scale> {
    let &(p, at) = laid.iter().find(|(p, _)| p.name == name)?;
    Some(match raw_number(&p.kind, &block[at..at + usize::from(p.size.max(1))]) {
        // A scale factor outside −10…10 is not one (SunSpec Information Model Reference,
        // `sunssf`): the point is shown without a value, never as "inf V".
        Some(Raw::Int(i)) => {
            i16::try_from(i).ok().filter(|k| (-10..=10).contains(k)).map_or(Scale::Unknown, Scale::Factor)
        }
        _ => Scale::Unknown,
    })
}

/// The scale of point `p`: fixed, or its scale-factor point's value in `first` (its group),
/// else in `then` (the model).
fn scale_of(p: &PointDef, first: &[(&PointDef, usize)], then: &[(&PointDef, usize)], block: &[u16]) -> Scale {
    match &p.sf {
        None => Scale::Unscaled,
        Some(Sf::Fixed(k)) => Scale::Factor(*k),
        Some(Sf::Point(s)) => sf_of(s, first, block).or_else(|| sf_of(s, then, block)).unwrap_or(Scale::Unknown),
    }
}

/// Decodes model `found` from `block`, its registers from the ID on (`found.registers()` of
/// them, fewer if the read came short); `def` its definition, `None` for a model not known
/// (one value, `raw`, with every register).
#[must_use]
pub fn decode_model(def: Option<&ModelDef>, found: Found, block: &[u16]) -> Vec<Value> {
    let address = |offset: usize| found.address.saturating_add(u16::try_from(offset).unwrap_or(u16::MAX));
    let Some(def) = def else {
        let body = block.get(2..).unwrap_or(&[]);
        let mut hex = String::new();
        for w in body {
            let _ = write!(hex, "{w:04X}");
        }
        return vec![Value {
            point: "raw".into(),
            address: address(2),
            registers: body.to_vec(),
            shown: Some(Shown::Text(hex)),
            units: None,
        }];
    };
    let top = layout(&def.points, 0, block);
    let value = |p: &PointDef, at: usize, name: String, sf: Scale| Value {
        point: name,
        address: address(at),
        registers: block[at..at + usize::from(p.size.max(1))].to_vec(),
        shown: shown(p, &block[at..at + usize::from(p.size.max(1))], sf),
        units: p.units.clone(),
    };
    let mut out: Vec<Value> = top
        .iter()
        .filter(|(p, _)| p.kind != "pad")
        .map(|&(p, at)| value(p, at, p.name.clone(), scale_of(p, &top, &top, block)))
        .collect();
    if let Some(rep) = &def.repeat {
        let start = top.last().map_or(0, |(p, at)| at + usize::from(p.size.max(1)));
        let size: usize = rep.points.iter().map(|p| usize::from(p.size.max(1))).sum();
        if let Some(room) = block.len().saturating_sub(start).checked_div(size) {
            let count = match &rep.count {
                Count::Fixed(0) => room,
                Count::Fixed(k) => usize::from(*k).min(room),
                Count::Point(n) => out
                    .iter()
                    .find(|v| v.point == *n)
                    .and_then(|v| match v.shown {
                        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                        Some(Shown::Number { value, .. }) if value >= 0.0 => Some(value as usize),
                        _ => None,
                    })
                    .unwrap_or(0)
                    .min(room),
            };
            for k in 0..count {
                let laid = layout(&rep.points, start + k * size, block);
                for &(p, at) in laid.iter().filter(|(p, _)| p.kind != "pad") {
                    // A group's scale factor is its own, else the model's.
                    let sf = scale_of(p, &laid, &top, block);
                    out.push(value(p, at, format!("{}[{}].{}", rep.name, k + 1, p.name), sf));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Model 103 (three-phase inverter): ID, L, then A=123 with A_SF=-1 … W=4500 with W_SF=0.
    fn inverter_block() -> (Found, Vec<u16>) {
        let def = super::super::model(103).expect("known");
        let len: u16 = def.points.iter().map(|p| p.size).sum::<u16>() - 2;
        let mut block = vec![0xFFFFu16; usize::from(len) + 2];
        block[0] = 103;
        block[1] = len;
        let mut at = 0;
        for p in &def.points {
            let v: Option<u16> = match p.name.as_str() {
                "A" => Some(123),
                "A_SF" | "V_SF" => Some(0xFFFF), // -1
                "W" => Some(4500),
                "W_SF" => Some(0),
                "PhVphA" => Some(2301),
                "VA" => Some(0x8000), // int16: not implemented
                _ => None,
            };
            if let Some(v) = v {
                block[at] = v;
            }
            at += usize::from(p.size);
        }
        (Found { id: 103, address: 40070, len }, block)
    }

    #[test]
    fn points_are_scaled_by_their_sf_and_not_implemented_values_are_absent() {
        let (found, block) = inverter_block();
        let values = decode_model(super::super::model(103), found, &block);
        let get = |n: &str| values.iter().find(|v| v.point == n).expect(n).clone();
        assert_eq!(get("A").shown, Some(Shown::Number { value: 12.3, decimals: 1 }));
        assert_eq!(get("W").shown.map(|s| s.to_string()), Some("4500".into()));
        assert_eq!(get("PhVphA").shown.map(|s| s.to_string()), Some("230.1".into()));
        assert_eq!(get("A").address, 40072);
        // AphA is 0xFFFF: not implemented.
        assert_eq!(get("AphA").shown, None);
        // VA is an int16 at 0x8000: absent.
        assert_eq!(get("VA").shown, None);
    }

    /// A scale factor outside SunSpec's −10…10 (here W_SF = 32767) is not applied: no "inf W".
    #[test]
    fn a_scale_factor_outside_ten_is_no_scale() {
        let (found, mut block) = inverter_block();
        let def = super::super::model(103).expect("known");
        let mut at = 0;
        for p in &def.points {
            if p.name == "W_SF" {
                block[at] = 32_767;
            }
            at += usize::from(p.size);
        }
        let values = decode_model(Some(def), found, &block);
        let w = values.iter().find(|v| v.point == "W").expect("W");
        assert_eq!(w.shown, None);
    }

    #[test]
    fn a_model_not_known_is_shown_raw_and_a_short_block_does_not_panic() {
        let found = Found { id: 64_999, address: 40200, len: 2 };
        let v = decode_model(None, found, &[64_999, 2, 0xABCD, 1]);
        assert_eq!(v[0].shown, Some(Shown::Text("ABCD0001".into())));
        let (found, block) = inverter_block();
        let v = decode_model(super::super::model(103), found, &block[..10]);
        assert!(v.len() <= 10 && v.iter().all(|x| x.address < found.address + 10), "{v:?}");
        let v = decode_model(super::super::model(160), Found { id: 160, address: 0, len: 0 }, &[]);
        assert!(v.is_empty());
    }
}
