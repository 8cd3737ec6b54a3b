//! Profiles from what users already have (issue 27): vendor register sheets — rows of cells,
//! read from CSV or XLSX at the edge — and Home Assistant `modbus:` YAML, turned into the points
//! of a profile; every row or entry that cannot be read is listed with where and why, and
//! skipped, never guessed. [`Imported::to_toml`] writes the profile (`docs/profiles.md`), which
//! the loader then checks like any hand-written one.

mod fields;
pub mod grid;
pub mod ha_entry;
pub mod ha_yaml;
pub mod home_assistant;
pub mod notation;
pub mod ods_size;
pub mod sheet;
pub mod xls_size;

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

/// Points loaded back at a time by [`load_back`]: the TOML reader's document takes ~25 bytes per
/// byte of text, so a profile of 200 000 points read whole took 300 MB (issue 39).
pub const LOAD_BACK_PART: usize = 4096;

/// Why a written profile does not load back.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LoadBackError {
    #[error(transparent)]
    Part(#[from] crate::profile::ProfileError),
    #[error("{file}: {table} address {address} is defined twice")]
    Twice { file: String, table: &'static str, address: u16 },
}

/// Loads `toml` — [`Imported::to_toml`]'s output, named `file` — back as the loader loads any
/// profile, [`LOAD_BACK_PART`] entries at a time: each part is the file's header and a run of
/// its `[[table]]` entries (the writer emits nothing else, and no string spans lines), checked
/// whole by the loader; an address defined in two parts is found by a bit per address. Errors
/// name the line of the whole file.
///
/// # Errors
/// The first part that does not load, or an address defined twice.
pub fn load_back(file: &str, toml: &str) -> Result<(), LoadBackError> {
    // Byte offsets where an entry's `[[` line starts.
    let starts: Vec<usize> = toml.match_indices("\n[[").map(|(i, _)| i + 1).collect();
    let Some(&first) = starts.first() else {
        crate::profile::load(file, toml)?;
        return Ok(());
    };
    let header = toml.get(..first).unwrap_or_default();
    let header_lines = header.matches('\n').count();
    let mut seen = vec![0u64; 4 * 65_536 / 64];
    let mut text = String::new();
    for (k, part) in starts.chunks(LOAD_BACK_PART).enumerate() {
        let from = part.first().copied().unwrap_or(first);
        let to = starts.get((k + 1) * LOAD_BACK_PART).copied().unwrap_or(toml.len());
        text.clear();
        text.push_str(header);
        text.push_str(toml.get(from..to).unwrap_or_default());
        let loaded = crate::profile::load(file, &text).map_err(|mut e| {
            if e.line > header_lines {
                e.line = e.line - header_lines + toml.get(..from).unwrap_or_default().matches('\n').count();
            }
            e
        })?;
        for (&table, slots) in &loaded.tables {
            let t = match table {
                Table::Coils => 0,
                Table::DiscreteInputs => 1,
                Table::InputRegisters => 2,
                Table::HoldingRegisters => 3,
            };
            for &address in slots.keys() {
                let bit = t * 65_536 + usize::from(address);
                // Four tables of 65 536 addresses: every bit is within `seen`.
                let Some(word) = seen.get_mut(bit / 64) else { continue };
                if *word & (1 << (bit % 64)) != 0 {
                    return Err(LoadBackError::Twice { file: file.to_owned(), table: table.name(), address });
                }
                *word |= 1 << (bit % 64);
            }
        }
    }
    Ok(())
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn point(table: Table, address: u16, value_type: ValueType) -> Point {
        Point {
            table,
            address,
            name: format!("P{address}"),
            value_type,
            word_order: WordOrder::HighFirst,
            scale: None,
            unit: None,
            access: Access::Read,
            length: None,
            description: None,
            origin: format!("row {address}"),
        }
    }

    /// Issue 39: 200 000 rows' profile read back whole took 300 MB; in parts it loads the same.
    #[test]
    fn a_big_profile_loads_back_in_parts() {
        let mut all = Imported::default();
        for a in 0..10_000u16 {
            all.add(point(Table::HoldingRegisters, a * 2, ValueType::F32));
            all.add(point(Table::Coils, a, ValueType::Bool));
        }
        let toml = all.to_toml("big", "big", "big.csv");
        assert!(toml.matches("\n[[").count() > 2 * LOAD_BACK_PART);
        load_back("big", &toml).unwrap();
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
        assert!(matches!(load_back("x", &twice), Err(LoadBackError::Twice { address: 3, .. })));
        // A bad value in the last part: its line in the whole file.
        let bad = format!("{toml}\n[[input_registers]]\naddress = 70000\nname = \"bad\"\n");
        let line = bad.lines().position(|l| l == "address = 70000").unwrap() + 1;
        match load_back("x", &bad) {
            Err(LoadBackError::Part(e)) => assert_eq!(e.line, line, "{e}"),
            other => panic!("{other:?}"),
        }
    }
}
