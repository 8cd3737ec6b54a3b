//! Printing what a master command got: rows as text or JSON lines, failures per request with
//! the decoded exception (on stdout in JSON, so a pipe sees them in order; on stderr in text).

use std::io::Write;

use mbtap_analysis::report::format::printable;
use mbtap_device::query::plan::Read;
use mbtap_device::query::rows::{Row, short_table};

use super::MasterFormat;

/// A request that did not give values.
#[derive(Debug, Clone)]
pub struct Failure {
    pub unit: u8,
    pub item: String,
    pub read: Option<Read>,
    pub problem: String,
}

impl Failure {
    fn json(&self) -> serde_json::Value {
        let mut o = serde_json::json!({ "unit": self.unit, "item": self.item, "error": self.problem });
        if let (Some(r), Some(m)) = (self.read, o.as_object_mut()) {
            m.insert("table".into(), r.table.name().into());
            m.insert("address".into(), r.address.into());
            m.insert("quantity".into(), r.quantity.into());
        }
        o
    }

    fn text(&self) -> String {
        match self.read {
            Some(r) => format!(
                "{}: {} {}..{} of unit {}: {}",
                self.item,
                short_table(r.table),
                r.address,
                u32::from(r.address) + u32::from(r.quantity) - 1,
                self.unit,
                self.problem
            ),
            None => format!("{}: unit {}: {}", self.item, self.unit, self.problem),
        }
    }
}

/// Prints rows and failures; `extra` keys go into every JSON object (`t_ns` for `watch`).
pub fn print(
    format: MasterFormat,
    rows: &[Row],
    failures: &[Failure],
    extra: &[(&str, serde_json::Value)],
    out: &mut dyn Write,
) -> std::io::Result<()> {
    match format {
        MasterFormat::Text => {
            // Names and units come from profiles (user files, imports): control characters in
            // them never reach the terminal, as `decode` escapes them.
            for r in rows {
                writeln!(out, "{}", printable(&r.line()))?;
            }
            out.flush()?;
            for f in failures {
                eprintln!("mbtap: {}", printable(&f.text()));
            }
        }
        MasterFormat::Jsonl => {
            for mut o in rows.iter().map(Row::to_json).chain(failures.iter().map(Failure::json)) {
                if let Some(m) = o.as_object_mut() {
                    for (k, v) in extra {
                        m.insert((*k).to_owned(), v.clone());
                    }
                }
                writeln!(out, "{o}")?;
            }
            out.flush()?;
        }
    }
    Ok(())
}
