//! Profiles from what users already have: vendor register sheets — rows of cells,
//! read from CSV or a workbook at the edge — and Home Assistant `modbus:` YAML, turned into the
//! points of a profile; every row or entry that cannot be read is listed with where and why, and
//! skipped, never guessed. Readers hand what they find to a [`Sink`] as they read it: the import
//! command's writes each point out as it comes, [`Imported`] collects (tests, SunSpec).
//! [`header`] and [`entry`] write the profile (`docs/profiles.md`), which the loader then checks
//! like any hand-written one ([`load_back()`]).
//!
//! Modules — sheets: `fields` (the columns and the header texts naming them), `notation`
//! (addresses, tables, types as vendors write them), `sheet` (the sheet reader and its passes),
//! `grid` and `cell_rows` (cells held compactly, handed on row by row), `ods_size` and `ods_rows`
//! (OpenDocument: its expanded size counted, its rows streamed), `xls_container`, `xls_stream`,
//! `xls_records` and `xls_rows` (XLS: the compound file, the workbook stream, its records, its
//! rows); Home Assistant: `ha_yaml` (the YAML read as it goes), `ha_entry` (one entry and its
//! point), `home_assistant` (hubs to points); every sink: `ledger` (the addresses taken),
//! `load_back` (the written profile loaded back).

pub mod cell_rows;
mod fields;
pub mod grid;
pub mod ha_entry;
pub mod ha_yaml;
pub mod home_assistant;
pub mod ledger;
pub mod load_back;
pub mod notation;
pub mod ods_rows;
pub mod ods_size;
pub mod sheet;
pub mod xls_container;
mod xls_records;
pub mod xls_rows;
mod xls_stream;

use std::collections::BTreeMap;
use std::fmt::Write as _;

pub use ledger::{Clash, Ledger};
pub use load_back::{LOAD_BACK_PART, LoadBackError, load_back};

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
            ValueType::U64 | ValueType::I64 => 4,
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

/// Where an import's findings go as they are read: collected ([`Imported`]), or written out as
/// they come (the import command's profile file: a sheet's points held in memory took
/// 20× the sheet).
pub trait Sink {
    /// A point read (taken unless its addresses clash: then a problem).
    fn point(&mut self, p: Point);
    /// Something not imported.
    fn problem(&mut self, p: Problem);
    /// How the source was read, in words.
    fn note(&mut self, n: String);
    /// The source made the import produce more than its budget: nothing is to be written. By
    /// default a problem like any other.
    fn over_budget(&mut self, p: Problem) {
        self.problem(p);
    }
}

/// What an import found, collected.
#[derive(Debug, Clone, Default)]
pub struct Imported {
    pub points: Vec<Point>,
    pub problems: Vec<Problem>,
    /// How the source was read, in words (`header on row 3: address=A, name=B, …`).
    pub notes: Vec<String>,
    /// The addresses taken: an overlap is found by looking up the new point's addresses, not by
    /// scanning every point (which is quadratic in rows).
    ledger: Ledger,
}

impl Sink for Imported {
    fn point(&mut self, p: Point) {
        self.add(p);
    }

    fn problem(&mut self, p: Problem) {
        self.problems.push(p);
    }

    fn note(&mut self, n: String) {
        self.notes.push(n);
    }
}

impl Imported {
    /// Adds `p` unless it overlaps a point already imported (a profile defines each address
    /// once per table), which becomes a problem naming both.
    pub fn add(&mut self, p: Point) {
        let key = u32::try_from(self.points.len()).unwrap_or(u32::MAX);
        match self.ledger.take(&p, key) {
            Ok(()) => self.points.push(p),
            Err(clash) => {
                let other = match clash {
                    Clash::Overlaps(n) => {
                        self.points.get(n as usize).map(|q| (q.name.as_str(), q.origin.as_str(), q.address))
                    }
                    Clash::PastEnd | Clash::NoKey => None,
                };
                self.problems.push(Ledger::problem(&p, clash, other));
            }
        }
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
        let mut s = header(name, device, source, &self.notes, self.problems.len());
        for n in self.ledger.in_order() {
            if let Some(p) = self.points.get(n as usize) {
                entry(&mut s, p);
            }
        }
        s
    }
}

/// A profile's text before its entries: where it came from, the notes, how many rows were not
/// imported, and its `[profile]` table.
#[must_use]
pub fn header(name: &str, device: &str, source: &str, notes: &[String], skipped: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Imported by `mbtap profiles import` from {}.", comment(source));
    for n in notes {
        let _ = writeln!(s, "# {}", comment(n));
    }
    if skipped > 0 {
        let _ = writeln!(s, "# {skipped} row(s) or entries were not imported (see the import's output).");
    }
    let _ = writeln!(s, "\n[profile]\nname = {}\ndevice = {}", toml_str(name), toml_str(device));
    let _ = writeln!(s, "document = {}", toml_str(&format!("imported from {}", comment(source))));
    s
}

/// Appends `p`'s `[[table]]` entry to `s`.
pub fn entry(s: &mut String, p: &Point) {
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
        return;
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

/// The profile format's name of a value type.
#[must_use]
pub const fn type_name(t: ValueType) -> &'static str {
    match t {
        ValueType::U16 => "u16",
        ValueType::I16 => "i16",
        ValueType::U32 => "u32",
        ValueType::I32 => "i32",
        ValueType::U64 => "u64",
        ValueType::I64 => "i64",
        ValueType::F32 => "f32",
        ValueType::Bool => "bool",
        ValueType::Bits => "bits",
        ValueType::Enum => "enum",
        ValueType::String => "string",
        ValueType::Datetime => "datetime",
    }
}

/// A point named `P{address}` from `row {address}` (the tests' shape).
#[cfg(test)]
pub(crate) fn test_point(table: Table, address: u16, value_type: ValueType, length: Option<u16>) -> Point {
    Point {
        table,
        address,
        name: format!("P{address}"),
        value_type,
        word_order: WordOrder::HighFirst,
        scale: None,
        unit: None,
        access: Access::Read,
        length,
        description: None,
        origin: format!("row {address}"),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn point(table: Table, address: u16, value_type: ValueType) -> Point {
        test_point(table, address, value_type, None)
    }

    /// A profile of 200 000 rows loads back in parts the same as whole (whole, it takes 300 MB).
    #[test]
    fn a_big_profile_loads_back_in_parts() {
        let mut all = Imported::default();
        for a in 0..10_000u16 {
            all.add(point(Table::HoldingRegisters, a * 2, ValueType::F32));
            all.add(point(Table::Coils, a, ValueType::Bool));
        }
        let toml = all.to_toml("big", "big", "big.csv");
        assert!(toml.matches("\n[[").count() > 2 * LOAD_BACK_PART);
        load_back("big", toml.as_bytes()).unwrap();
        assert_eq!(
            crate::profile::load("big", &toml).unwrap().tables.values().map(BTreeMap::len).sum::<usize>(),
            30_000
        );
    }

    #[test]
    fn an_address_written_in_two_parts_is_found_and_errors_name_the_whole_file_s_line() {
        let mut all = Imported::default();
        for a in 0..u16::try_from(LOAD_BACK_PART + 10).unwrap() {
            all.add(point(Table::InputRegisters, a, ValueType::U16));
        }
        let toml = all.to_toml("x", "x", "x.csv");
        // The same address again at the end: in another part than the first.
        let twice = format!("{toml}\n[[input_registers]]\naddress = 3\nname = \"again\"\n");
        assert!(matches!(load_back("x", twice.as_bytes()), Err(LoadBackError::Twice { address: 3, .. })));
        // A bad value in the last part: its line in the whole file.
        let bad = format!("{toml}\n[[input_registers]]\naddress = 70000\nname = \"bad\"\n");
        let line = bad.lines().position(|l| l == "address = 70000").unwrap() + 1;
        match load_back("x", bad.as_bytes()) {
            Err(LoadBackError::Part(e)) => assert_eq!(e.line, line, "{e}"),
            other => panic!("{other:?}"),
        }
    }
}
