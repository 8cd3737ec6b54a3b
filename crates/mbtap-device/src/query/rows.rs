//! Answers turned into rows: one per value (a register, a point, or a whole multi-register
//! value), with the profile's name, the scaled value or label, and the unit of measure. The
//! JSON keys are those of `replay --image` where they overlap (`unit`, `table`, `address`,
//! `name`, `raw`, `value`, `unit_of_measure`).

use std::fmt::Write as _;

use super::is_bits;
use crate::profile::annotate::{Annotation, Lang, Shown, annotate_bits, annotate_registers};
use crate::profile::{Profile, Table};

/// One value read.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub unit: u8,
    pub table: Table,
    pub address: u16,
    pub name: Option<String>,
    pub raw: i64,
    /// The scaled number, the label, the text or the date; the raw number without a profile.
    pub value: serde_json::Value,
    pub unit_of_measure: Option<String>,
    pub notes: Vec<String>,
    /// The value as text, with its unit (`230.5 V`, `running`).
    pub shown: String,
}

impl Row {
    /// The row as one JSON object.
    #[must_use]
    pub fn to_json(&self) -> serde_json::Value {
        let mut o = serde_json::json!({
            "unit": self.unit, "table": self.table.name(), "address": self.address, "name": self.name,
            "raw": self.raw, "value": self.value, "unit_of_measure": self.unit_of_measure,
        });
        if !self.notes.is_empty()
            && let Some(m) = o.as_object_mut()
        {
            m.insert("notes".into(), self.notes.clone().into());
        }
        o
    }

    /// The row as one line: `input 430 Phase A (L1) voltage = 230.5 V (raw 2305)`.
    #[must_use]
    pub fn line(&self) -> String {
        let mut s = format!(
            "{} {} {} = {}",
            short_table(self.table),
            self.address,
            self.name.as_deref().unwrap_or("-"),
            self.shown
        );
        if !matches!(self.value, serde_json::Value::Number(_)) || self.shown != self.raw.to_string() {
            let _ = write!(s, " (raw {})", self.raw);
        }
        for n in &self.notes {
            let _ = write!(s, " [{n}]");
        }
        s
    }
}

/// The table word users type for `t`.
#[must_use]
pub const fn short_table(t: Table) -> &'static str {
    t.word()
}

fn value_of(a: &Annotation) -> serde_json::Value {
    match &a.shown {
        Shown::Number { value, decimals, .. } => {
            let v = match decimals {
                Some(d) => format!("{value:.*}", usize::from(*d)).parse().unwrap_or(*value),
                None => *value,
            };
            serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, serde_json::Value::Number)
        }
        Shown::Label(l) | Shown::Text(l) | Shown::Time(l) | Shown::Bool { label: Some(l), .. } => l.clone().into(),
        Shown::Bits(b) => b.join(", ").into(),
        Shown::Bool { on, label: None } => u8::from(*on).into(),
        Shown::Raw => a.raw.into(),
    }
}

/// Rows of the values `values` read from `table` at `address` of `unit`, named by `p`.
#[must_use]
pub fn rows(unit: u8, table: Table, address: u16, values: &[u16], p: Option<&Profile>) -> Vec<Row> {
    let Some(p) = p else {
        return values
            .iter()
            .enumerate()
            .filter_map(|(i, &v)| {
                let a = address.checked_add(u16::try_from(i).ok()?)?;
                Some(Row {
                    unit,
                    table,
                    address: a,
                    name: None,
                    raw: i64::from(v),
                    value: v.into(),
                    unit_of_measure: None,
                    notes: Vec::new(),
                    shown: v.to_string(),
                })
            })
            .collect();
    };
    let annotations = if is_bits(table) {
        annotate_bits(p, table, address, &values.iter().map(|&v| v != 0).collect::<Vec<_>>(), false)
    } else {
        annotate_registers(p, table, address, values, false)
    };
    annotations
        .into_iter()
        .map(|a| Row {
            unit,
            table,
            address: a.address,
            name: a.name_in(Lang::En).map(str::to_owned),
            raw: a.raw,
            value: value_of(&a),
            unit_of_measure: match &a.shown {
                Shown::Number { unit, .. } => unit.clone(),
                _ => None,
            },
            notes: a.notes.iter().map(ToString::to_string).collect(),
            shown: a.value_text(),
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn mk4_voltages_named_and_scaled() {
        let mk4 = crate::profile::builtin::get("mk4").unwrap().unwrap();
        let r = rows(1, Table::InputRegisters, 430, &[2305, 2311, 2298, 2305], Some(&mk4));
        assert_eq!(r.len(), 4);
        assert_eq!(r[0].name.as_deref(), Some("Phase A (L1) voltage"));
        assert_eq!(r[0].value, serde_json::json!(230.5));
        assert_eq!(r[0].unit_of_measure.as_deref(), Some("V"));
        assert_eq!(r[0].line(), "input 430 Phase A (L1) voltage = 230.5 V (raw 2305)");
        let j = r[1].to_json();
        assert_eq!(j["table"], "input_registers");
        assert_eq!(j["raw"], 2311);
    }

    #[test]
    fn raw_rows_without_a_profile() {
        let r = rows(3, Table::HoldingRegisters, 65535, &[7, 8], None);
        assert_eq!(r.len(), 1, "addresses past 65535 do not exist");
        assert_eq!(r[0].line(), "holding 65535 - = 7");
    }
}
