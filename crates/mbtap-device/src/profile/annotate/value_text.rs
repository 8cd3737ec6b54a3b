//! How one value is shown: scaled and trimmed, signed, as a date, or as its enumeration's
//! text — with the notes of what is impossible or out of the profile's range.

use super::{Note, Shown};
use crate::profile::format::ValueType;
use crate::profile::model::Def;

/// A float without noise: 230.5, not 230.50000000000003 (rounded to 6 decimals; `{}` then
/// prints the shortest form).
pub(super) fn trim(v: f64) -> f64 {
    let r = (v * 1e6).round() / 1e6;
    if r == 0.0 { 0.0 } else { r }
}

/// Decimals a scale implies: 1 → 0, 0.1 → 1, 0.01 → 2, 0.5 → 1.
pub(super) fn decimals_of(scale: Option<f64>) -> u8 {
    let Some(s) = scale.filter(|s| *s > 0.0 && *s < 1.0) else { return 0 };
    (1..=6u8)
        .find(|&d| {
            let scaled = s * 10f64.powi(i32::from(d));
            (scaled - scaled.round()).abs() < 1e-9
        })
        .unwrap_or(6)
}

/// `2026-11-22 14:35:07` from the parts there are (missing ones left out: `11-22 14:35`).
pub(super) fn datetime(parts: &[crate::profile::format::DatePart], values: &[u16]) -> String {
    use crate::profile::format::DatePart as P;
    let get = |p: P| parts.iter().position(|&q| q == p).and_then(|i| values.get(i).copied());
    let day = match (get(P::Month), get(P::Day)) {
        (Some(m), Some(d)) => format!("{m:02}-{d:02}"),
        (Some(m), None) => format!("{m:02}"),
        (None, Some(d)) => format!("day {d:02}"),
        (None, None) => String::new(),
    };
    let date = match get(P::Year) {
        Some(y) if day.is_empty() => format!("{y:04}"),
        Some(y) => format!("{y:04}-{day}"),
        None => day,
    };
    let time = match (get(P::Hour), get(P::Minute), get(P::Second)) {
        (Some(h), Some(m), Some(s)) => format!("{h:02}:{m:02}:{s:02}"),
        (Some(h), Some(m), None) => format!("{h:02}:{m:02}"),
        (Some(h), None, _) => format!("{h:02}h"),
        _ => String::new(),
    };
    [date, time].into_iter().filter(|s| !s.is_empty()).collect::<Vec<_>>().join(" ")
}

/// The first part outside what a clock can show (month 13, minute 75). Zero is allowed in every
/// part because the documented devices write all zeros into an empty log record.
pub(super) fn impossible_date_part(parts: &[crate::profile::format::DatePart], values: &[u16]) -> Option<Note> {
    use crate::profile::format::DatePart as P;
    parts.iter().zip(values).find_map(|(&p, &v)| {
        let max = match p {
            P::Year => return None,
            P::Month => 12,
            P::Day => 31,
            P::Hour => 23,
            P::Minute | P::Second => 59,
        };
        (v > max).then_some(Note::OutOfRange { min: 0, max: max.into() })
    })
}

pub(super) fn signed16(v: u16) -> i64 {
    i64::from(i16::from_ne_bytes(v.to_ne_bytes()))
}

pub(super) fn shown(def: &Def, raw: i64, bits32: Option<u32>) -> (Shown, Vec<Note>) {
    let mut notes = Vec::new();
    let s = match def.value_type {
        ValueType::Enum => {
            if let Some(l) = def.labels.get(&raw) {
                Shown::Label(l.clone())
            } else {
                notes.push(Note::UnknownLabel);
                Shown::Raw
            }
        }
        ValueType::Bits => Shown::Bits(
            (0..16u8)
                .filter(|b| (raw >> b) & 1 == 1)
                .map(|b| def.bits.get(&b).cloned().unwrap_or_else(|| format!("bit {b}")))
                .collect(),
        ),
        ValueType::Bool => Shown::Bool { on: raw != 0, label: None },
        ValueType::F32 => {
            let f = f32::from_bits(bits32.unwrap_or(0));
            // The float's shortest decimal form, so 229.9 shows as 229.9 and not as its f64
            // expansion 229.899994; a scale applies to floats too (imported sheets and Home
            // Assistant configurations scale them).
            let value = f.to_string().parse::<f64>().unwrap_or_else(|_| f64::from(f));
            Shown::Number {
                value: value * def.scale.unwrap_or(1.0),
                unit: def.unit.clone(),
                decimals: def.scale.map(|k| decimals_of(Some(k))),
            }
        }
        _ => {
            #[allow(clippy::cast_precision_loss)]
            let value = raw as f64 * def.scale.unwrap_or(1.0);
            Shown::Number { value, unit: def.unit.clone(), decimals: Some(decimals_of(def.scale)) }
        }
    };
    (s, notes)
}
