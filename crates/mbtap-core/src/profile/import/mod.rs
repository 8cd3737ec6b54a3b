//! Profiles from what users already have (issue 27): vendor register sheets — rows of cells,
//! read from CSV or XLSX at the edge — and Home Assistant `modbus:` YAML, turned into the points
//! of a profile; every row or entry that cannot be read is listed with where and why, and
//! skipped, never guessed. [`Imported::to_toml`] writes the profile (`docs/profiles.md`), which
//! the loader then checks like any hand-written one.

mod fields;
pub mod grid;
pub mod home_assistant;
pub mod notation;
pub mod sheet;

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::profile::Table;
use crate::profile::escape::{comment, toml_str};
use crate::profile::format::{Access, ValueType, WordOrder};

/// One coil, input or register read from the source.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub table: Table,
    pub address: u16,
    pub name: String,
    pub value_type: ValueType,
    pub word_order: WordOrder,
    pub scale: Option<f64>,
    pub unit: Option<String>,
    pub access: Access,
    /// Registers a string spans.
    pub length: Option<u16>,
    pub description: Option<String>,
    /// Where it came from (`row 12`, `sensors[3]`), for the profile's comments.
    pub origin: String,
}

impl Point {
    /// Registers (or bits) the point occupies.
    #[must_use]
    pub fn width(&self) -> u16 {
        match self.value_type {
            ValueType::U32 | ValueType::I32 | ValueType::F32 => 2,
            ValueType::String => self.length.unwrap_or(1).max(1),
            _ => 1,
        }
    }
}

/// Something in the source that was not imported.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// Where: `row 12`, `sensors[3] "Flow"`.
    pub at: String,
    /// The column or key, when one is to blame.
    pub column: Option<String>,
    pub why: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.column {
            Some(c) => write!(f, "{}, {c}: {}", self.at, self.why),
            None => write!(f, "{}: {}", self.at, self.why),
        }
    }
}

/// What an import found.
#[derive(Debug, Clone, Default)]
pub struct Imported {
    pub points: Vec<Point>,
    pub problems: Vec<Problem>,
    /// How the source was read, in words (`header on row 3: address=A, name=B, …`).
    pub notes: Vec<String>,
    /// Which point holds each address taken so far, per table: an overlap is found by looking
    /// up the new point's addresses, not by scanning every point (issue 39: import was
    /// quadratic in rows — 65 536 rows took 11–40 s).
    taken: BTreeMap<(Table, u16), usize>,
}

impl Imported {
    /// Adds `p` unless it overlaps a point already imported (a profile defines each address
    /// once per table), which becomes a problem naming both.
    pub fn add(&mut self, p: Point) {
        let end = u32::from(p.address) + u32::from(p.width());
        if end > 0x1_0000 {
            self.problems.push(Problem {
                at: p.origin.clone(),
                column: None,
                why: format!("{} at {} runs past address 65535", type_name(p.value_type), p.address),
            });
            return;
        }
        let first = (p.table, p.address);
        let last = (p.table, u16::try_from(end - 1).unwrap_or(u16::MAX));
        if let Some(q) = self.taken.range(first..=last).next().and_then(|(_, &i)| self.points.get(i)) {
            self.problems.push(Problem {
                at: p.origin.clone(),
                column: None,
                why: format!(
                    "{} {} overlaps {:?} ({}, address {}) — a profile defines each address once",
                    p.table.name(),
                    p.address,
                    q.name,
                    q.origin,
                    q.address
                ),
            });
            return;
        }
        for address in p.address..=last.1 {
            self.taken.insert((p.table, address), self.points.len());
        }
        self.points.push(p);
    }

    /// Points per table.
    #[must_use]
    pub fn counts(&self) -> BTreeMap<Table, usize> {
        let mut m = BTreeMap::new();
        for p in &self.points {
            *m.entry(p.table).or_default() += 1;
        }
        m
    }

    /// The profile (TOML, `docs/profiles.md`) named `name` for `device`, made from `source`.
    #[must_use]
    pub fn to_toml(&self, name: &str, device: &str, source: &str) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# Imported by `mbtap profiles import` from {}.", comment(source));
        for n in &self.notes {
            let _ = writeln!(s, "# {}", comment(n));
        }
        if !self.problems.is_empty() {
            let _ =
                writeln!(s, "# {} row(s) or entries were not imported (see the import's output).", self.problems.len());
        }
        let _ = writeln!(s, "\n[profile]\nname = {}\ndevice = {}", toml_str(name), toml_str(device));
        let _ = writeln!(s, "document = {}", toml_str(&format!("imported from {}", comment(source))));
        let mut points: Vec<&Point> = self.points.iter().collect();
        points.sort_by_key(|p| (p.table, p.address));
        for p in points {
            let _ = writeln!(
                s,
                "\n# {}\n[[{}]]\naddress = {}\nname = {}",
                comment(&p.origin),
                p.table.name(),
                p.address,
                toml_str(&p.name)
            );
            if let Some(d) = &p.description {
                let _ = writeln!(s, "description = {}", toml_str(d));
            }
            match p.access {
                Access::Read => {}
                Access::ReadWrite => s.push_str("access = \"rw\"\n"),
                Access::Write => s.push_str("access = \"w\"\n"),
            }
            if matches!(p.table, Table::Coils | Table::DiscreteInputs) {
                continue;
            }
            if p.value_type != ValueType::U16 {
                let _ = writeln!(s, "type = \"{}\"", type_name(p.value_type));
            }
            if p.width() == 2 && p.word_order == WordOrder::LowFirst {
                s.push_str("word_order = \"low_first\"\n");
            }
            if p.value_type == ValueType::String {
                let _ = writeln!(s, "length = {}\nchars_per_register = 2", p.width());
            }
            if let Some(k) = p.scale {
                let _ = writeln!(s, "scale = {k:?}");
            }
            if let Some(u) = &p.unit {
                let _ = writeln!(s, "unit = {}", toml_str(u));
            }
        }
        s
    }
}

/// The profile format's name of a value type.
#[must_use]
pub const fn type_name(t: ValueType) -> &'static str {
    match t {
        ValueType::U16 => "u16",
        ValueType::I16 => "i16",
        ValueType::U32 => "u32",
        ValueType::I32 => "i32",
        ValueType::F32 => "f32",
        ValueType::Bool => "bool",
        ValueType::Bits => "bits",
        ValueType::Enum => "enum",
        ValueType::String => "string",
        ValueType::Datetime => "datetime",
    }
}
