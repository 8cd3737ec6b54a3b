//! Profile annotations as JSON.

use serde_json::{Value as J, json};

use crate::profile::annotate::{Annotation, Shown};

/// One annotation: `table`, `address`, `name`, `raw`, and `value` (+ `unit`), `label`,
/// `bits` or `text`, and `notes` (`kind`, `message`).
#[must_use]
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
        Shown::Number { value, unit } => {
            j["value"] = json!(value);
            if let Some(u) = unit {
                j["unit"] = json!(u);
            }
        }
        Shown::Label(l) => j["label"] = json!(l),
        Shown::Bits(b) => j["bits"] = json!(b),
        Shown::Text(t) => j["text"] = json!(t),
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
