//! Profile annotations as JSON.

use serde_json::{Value as J, json};

use mbtap_device::profile::annotate::{Annotation, Shown};

/// One annotation: `table`, `address`, `name`, `raw`, and `value` (+ `unit`), `label`,
/// `bits` or `text`, and `notes` (`kind`, `message`).
#[must_use]
/// The value at the precision its scale implies, so JSON says 229.2 and not the float noise
/// 229.20000000000002 that raw × 0.1 leaves.
fn rounded(value: f64, decimals: Option<u8>) -> f64 {
    match decimals {
        Some(d) => {
            let p = 10f64.powi(i32::from(d));
            (value * p).round() / p
        }
        None => value,
    }
}

pub fn json(a: &Annotation) -> J {
    let mut j = json!({
        "table": a.table.name(),
        "address": a.address,
        "name": a.name,
        "raw": a.raw,
    });
    if let Some(ru) = &a.name_ru {
        j["name_ru"] = json!(ru);
    }
    match &a.shown {
        Shown::Number { value, unit, decimals } => {
            j["value"] = json!(rounded(*value, *decimals));
            if let Some(u) = unit {
                j["unit"] = json!(u);
            }
        }
        Shown::Label(l) => j["label"] = json!(l),
        Shown::Bits(b) => j["bits"] = json!(b),
        Shown::Text(t) => j["text"] = json!(t),
        Shown::Time(t) => j["time"] = json!(t),
        Shown::Bool { on, label } => {
            j["value"] = json!(on);
            if let Some(l) = label {
                j["label"] = json!(l);
            }
        }
        Shown::Raw => {}
    }
    j["notes"] = J::Array(a.notes.iter().map(|n| json!({"kind": n.kind(), "message": n.to_string()})).collect());
    j
}

fn push_str_json(out: &mut String, s: &str) {
    // serde_json escapes exactly as JSON requires; a String cannot fail to serialize.
    out.push_str(&serde_json::to_string(s).unwrap_or_else(|_| "\"\"".to_owned()));
}

/// The same object as [`json`], written straight into `out` — no intermediate map: the
/// annotated output of a busy bus is mostly these objects.
pub fn write_json(out: &mut String, a: &Annotation) {
    use std::fmt::Write as _;
    let _ = write!(out, "{{\"table\":\"{}\",\"address\":{},\"name\":", a.table.name(), a.address);
    match &a.name {
        Some(n) => push_str_json(out, n),
        None => out.push_str("null"),
    }
    let _ = write!(out, ",\"raw\":{}", a.raw);
    if let Some(ru) = &a.name_ru {
        out.push_str(",\"name_ru\":");
        push_str_json(out, ru);
    }
    match &a.shown {
        Shown::Number { value, unit, decimals } => {
            out.push_str(",\"value\":");
            out.push_str(&serde_json::to_string(&rounded(*value, *decimals)).unwrap_or_else(|_| "null".to_owned()));
            if let Some(u) = unit {
                out.push_str(",\"unit\":");
                push_str_json(out, u);
            }
        }
        Shown::Label(l) => {
            out.push_str(",\"label\":");
            push_str_json(out, l);
        }
        Shown::Bits(b) => {
            out.push_str(",\"bits\":[");
            for (i, s) in b.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                push_str_json(out, s);
            }
            out.push(']');
        }
        Shown::Text(t) => {
            out.push_str(",\"text\":");
            push_str_json(out, t);
        }
        Shown::Time(t) => {
            out.push_str(",\"time\":");
            push_str_json(out, t);
        }
        Shown::Bool { on, label } => {
            let _ = write!(out, ",\"value\":{on}");
            if let Some(l) = label {
                out.push_str(",\"label\":");
                push_str_json(out, l);
            }
        }
        Shown::Raw => {}
    }
    out.push_str(",\"notes\":[");
    for (i, n) in a.notes.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        let _ = write!(out, "{{\"kind\":\"{}\",\"message\":", n.kind());
        push_str_json(out, &n.to_string());
        out.push('}');
    }
    out.push_str("]}");
}

#[cfg(test)]
mod tests {
    use super::*;
    use mbtap_device::profile::Table;
    use mbtap_device::profile::annotate::Note;

    /// The fast writer and the map-based object agree, field for field.
    #[test]
    fn write_json_matches_json() {
        let cases = [
            Annotation {
                table: Table::InputRegisters,
                address: 430,
                width: 1,
                name: Some("Phase \"A\"".into()),
                name_ru: Some("Фаза".into()),
                raw: 2305,
                shown: Shown::Number { value: 230.5, unit: Some("V".into()), decimals: Some(1) },
                notes: vec![Note::OutOfRange { min: 0, max: 10 }],
            },
            Annotation {
                table: Table::Coils,
                address: 1,
                width: 1,
                name: None,
                name_ru: None,
                raw: 1,
                shown: Shown::Bool { on: true, label: Some("on".into()) },
                notes: vec![],
            },
            Annotation {
                table: Table::HoldingRegisters,
                address: 9,
                width: 1,
                name: Some("b".into()),
                name_ru: None,
                raw: 5,
                shown: Shown::Bits(vec!["x".into(), "y".into()]),
                notes: vec![Note::Reserved],
            },
        ];
        for a in cases {
            let mut s = String::new();
            write_json(&mut s, &a);
            let fast: serde_json::Value = serde_json::from_str(&s).unwrap();
            assert_eq!(fast, json(&a), "{s}");
        }
    }
}
