//! The addresses an import has taken, for every sink of points alike: each address of
//! the four tables holds the key its sink gave the point defined there (a flat 1 MiB table,
//! allocated at the first point), so an overlap is one lookup per address the new point covers
//! and points come out in address order by walking the table — no scan of the points, no
//! per-point map node, and nothing kept per point: the key is where the sink keeps the point (its
//! index in a list, its record's offset in a file).

use super::{Point, Problem, type_name};
use crate::profile::Table;

/// Addresses per table (MAP v1.1b3 §4.4: addresses 0–65535 in each of the four tables).
const ADDRESSES: usize = 65_536;

/// Where `table` starts in the flat table, in the order profiles are written (the tables'
/// `Ord`: coils, discrete inputs, holding registers, input registers).
const fn base(table: Table) -> usize {
    match table {
        Table::Coils => 0,
        Table::DiscreteInputs => ADDRESSES,
        Table::HoldingRegisters => 2 * ADDRESSES,
        Table::InputRegisters => 3 * ADDRESSES,
    }
}

/// Why a point was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clash {
    /// It runs past address 65535.
    PastEnd,
    /// The point keyed so already holds one of its addresses.
    Overlaps(u32),
    /// The sink's key is the one value a slot cannot hold (`u32::MAX`).
    NoKey,
}

/// The addresses taken so far.
#[derive(Debug, Clone, Default)]
pub struct Ledger {
    /// The point's key + 1 at each address of the four tables; 0 where free. Empty until the
    /// first point.
    slots: Vec<u32>,
    /// Points per table, in the tables' order.
    counts: [usize; 4],
}

impl Ledger {
    /// Points taken.
    #[must_use]
    pub fn len(&self) -> usize {
        self.counts.iter().sum()
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The flat range `p` covers, or why it cannot.
    fn span(p: &Point) -> Result<std::ops::Range<usize>, Clash> {
        let first = usize::from(p.address);
        let end = first + usize::from(p.width());
        if end > ADDRESSES {
            return Err(Clash::PastEnd);
        }
        Ok(base(p.table) + first..base(p.table) + end)
    }

    /// Takes `p`'s addresses for the point its sink keys `key` (distinct for every point taken),
    /// or says why they cannot be taken.
    ///
    /// # Errors
    /// It runs past 65535, overlaps a point taken before, or `key` is `u32::MAX`.
    pub fn take(&mut self, p: &Point, key: u32) -> Result<(), Clash> {
        let span = Self::span(p)?;
        let slot = key.checked_add(1).ok_or(Clash::NoKey)?;
        if let Some(&k) = self.slots.get(span.clone()).and_then(|s| s.iter().find(|&&k| k != 0)) {
            return Err(Clash::Overlaps(k - 1));
        }
        if self.slots.is_empty() {
            self.slots = vec![0; 4 * ADDRESSES];
        }
        for s in self.slots.get_mut(span.clone()).into_iter().flatten() {
            *s = slot;
        }
        if let Some(c) = self.counts.get_mut(span.start / ADDRESSES) {
            *c += 1;
        }
        Ok(())
    }

    /// The points' keys in the order a profile lists them: by table, then address (a point
    /// starts where the key changes: every point's key is its own).
    pub fn in_order(&self) -> impl Iterator<Item = u32> + '_ {
        self.slots.iter().enumerate().filter_map(|(i, &s)| {
            let starts = s != 0 && (i % ADDRESSES == 0 || self.slots.get(i - 1) != Some(&s));
            starts.then(|| s - 1)
        })
    }

    /// Points per table, in the tables' order.
    #[must_use]
    pub fn counts(&self) -> [usize; 4] {
        self.counts
    }

    /// The problem `clash` makes of `p`; `other` is the clashing point's name, origin and first
    /// address.
    #[must_use]
    pub fn problem(p: &Point, clash: Clash, other: Option<(&str, &str, u16)>) -> Problem {
        let why = match clash {
            Clash::PastEnd => format!("{} at {} runs past address 65535", type_name(p.value_type), p.address),
            Clash::Overlaps(_) => {
                let (name, origin, address) = other.unwrap_or(("?", "?", 0));
                format!(
                    "{} {} overlaps {name:?} ({origin}, address {address}) — a profile defines each address once",
                    p.table.name(),
                    p.address,
                )
            }
            Clash::NoKey => "more points than an import can keep".to_owned(),
        };
        Problem { at: p.origin.clone(), column: None, why }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::profile::format::ValueType;

    use super::super::test_point as point;

    #[test]
    fn overlaps_and_the_end_are_found_and_points_come_out_in_address_order() {
        let mut l = Ledger::default();
        assert_eq!(l.take(&point(Table::InputRegisters, 10, ValueType::F32, None), 70), Ok(()));
        assert_eq!(l.take(&point(Table::Coils, 10, ValueType::Bool, None), 71), Ok(()));
        assert_eq!(l.take(&point(Table::InputRegisters, 11, ValueType::U16, None), 5), Err(Clash::Overlaps(70)));
        assert_eq!(l.take(&point(Table::InputRegisters, 9, ValueType::U32, None), 5), Err(Clash::Overlaps(70)));
        assert_eq!(l.take(&point(Table::InputRegisters, 65_535, ValueType::F32, None), 5), Err(Clash::PastEnd));
        assert_eq!(l.take(&point(Table::InputRegisters, 65_534, ValueType::String, Some(2)), 72), Ok(()));
        // Right after the float at 10–11, keyed lower: a point starts where the key changes.
        assert_eq!(l.take(&point(Table::InputRegisters, 12, ValueType::U16, None), 0), Ok(()));
        assert_eq!(l.take(&point(Table::InputRegisters, 13, ValueType::U16, None), u32::MAX), Err(Clash::NoKey));
        assert_eq!(l.take(&point(Table::HoldingRegisters, 0, ValueType::U16, None), 73), Ok(()));
        assert_eq!(l.in_order().collect::<Vec<_>>(), [71, 73, 70, 0, 72]);
        assert_eq!(l.counts(), [1, 0, 1, 3]);
        assert_eq!(l.len(), 5);
        let p = point(Table::InputRegisters, 11, ValueType::U16, None);
        assert_eq!(
            Ledger::problem(&p, Clash::Overlaps(70), Some(("P10", "row 10", 10))).why,
            "input_registers 11 overlaps \"P10\" (row 10, address 10) — a profile defines each address once"
        );
    }

    /// A point at a table's first address starts there, whatever the key at the last address of
    /// the table before.
    #[test]
    fn a_point_at_a_table_s_first_address_starts_there() {
        let mut l = Ledger::default();
        assert_eq!(l.take(&point(Table::Coils, 65_535, ValueType::Bool, None), 1), Ok(()));
        assert_eq!(l.take(&point(Table::DiscreteInputs, 0, ValueType::Bool, None), 2), Ok(()));
        assert_eq!(l.in_order().collect::<Vec<_>>(), [1, 2]);
    }
}
