//! The addresses an import has taken, for every sink of points alike (issue 39): each address of
//! the four tables holds the number of the point defined there (a flat 1 MiB table, allocated at
//! the first point), so an overlap is one lookup per address the new point covers and points come
//! out in address order by walking the table — no scan of the points, no per-point map node.

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

/// The table whose addresses start at flat index `i`'s block.
const fn table_at(i: usize) -> Table {
    match i / ADDRESSES {
        0 => Table::Coils,
        1 => Table::DiscreteInputs,
        2 => Table::HoldingRegisters,
        _ => Table::InputRegisters,
    }
}

/// Why a point was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clash {
    /// It runs past address 65535.
    PastEnd,
    /// Point number `n` already holds one of its addresses.
    Overlaps(u32),
}

/// The addresses taken so far and where each point starts.
#[derive(Debug, Clone, Default)]
pub struct Ledger {
    /// Point number + 1 at each address of the four tables; 0 where free. Empty until the first
    /// point.
    slots: Vec<u32>,
    /// Each point's first address, as a flat index.
    starts: Vec<u32>,
}

impl Ledger {
    /// Points taken.
    #[must_use]
    pub fn len(&self) -> usize {
        self.starts.len()
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.starts.is_empty()
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

    /// Takes `p`'s addresses and returns its point number, or says why it cannot be taken.
    ///
    /// # Errors
    /// It runs past 65535 or overlaps a point taken before.
    pub fn take(&mut self, p: &Point) -> Result<u32, Clash> {
        let span = Self::span(p)?;
        if let Some(&n) = self.slots.get(span.clone()).and_then(|s| s.iter().find(|&&n| n != 0)) {
            return Err(Clash::Overlaps(n - 1));
        }
        // Four tables' worth of points at most (no address twice), so the number fits.
        let n = u32::try_from(self.starts.len()).map_err(|_| Clash::PastEnd)?;
        if self.slots.is_empty() {
            self.slots = vec![0; 4 * ADDRESSES];
        }
        for s in self.slots.get_mut(span.clone()).into_iter().flatten() {
            *s = n + 1;
        }
        self.starts.push(u32::try_from(span.start).unwrap_or(u32::MAX));
        Ok(n)
    }

    /// Point `n`'s table and first address.
    #[must_use]
    pub fn start(&self, n: u32) -> Option<(Table, u16)> {
        let i = *self.starts.get(usize::try_from(n).ok()?)? as usize;
        Some((table_at(i), u16::try_from(i % ADDRESSES).ok()?))
    }

    /// Point numbers in the order a profile lists them: by table, then address.
    pub fn in_order(&self) -> impl Iterator<Item = u32> + '_ {
        self.slots.iter().enumerate().filter_map(|(i, &s)| {
            let n = s.checked_sub(1)?;
            (self.starts.get(n as usize).map(|&st| st as usize) == Some(i)).then_some(n)
        })
    }

    /// Points per table, in the tables' order.
    #[must_use]
    pub fn counts(&self) -> [usize; 4] {
        let mut c = [0; 4];
        for &s in &self.starts {
            if let Some(k) = c.get_mut(s as usize / ADDRESSES) {
                *k += 1;
            }
        }
        c
    }

    /// The problem `clash` makes of `p`; `other` is the clashing point's name and origin.
    #[must_use]
    pub fn problem(&self, p: &Point, clash: Clash, other: Option<(&str, &str)>) -> Problem {
        let why = match clash {
            Clash::PastEnd => format!("{} at {} runs past address 65535", type_name(p.value_type), p.address),
            Clash::Overlaps(n) => {
                let (name, origin) = other.unwrap_or(("?", "?"));
                let address = self.start(n).map_or(0, |(_, a)| a);
                format!(
                    "{} {} overlaps {name:?} ({origin}, address {address}) — a profile defines each address once",
                    p.table.name(),
                    p.address,
                )
            }
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
        assert_eq!(l.take(&point(Table::InputRegisters, 10, ValueType::F32, None)), Ok(0));
        assert_eq!(l.take(&point(Table::Coils, 10, ValueType::Bool, None)), Ok(1));
        assert_eq!(l.take(&point(Table::InputRegisters, 11, ValueType::U16, None)), Err(Clash::Overlaps(0)));
        assert_eq!(l.take(&point(Table::InputRegisters, 9, ValueType::U32, None)), Err(Clash::Overlaps(0)));
        assert_eq!(l.take(&point(Table::InputRegisters, 65_535, ValueType::F32, None)), Err(Clash::PastEnd));
        assert_eq!(l.take(&point(Table::InputRegisters, 65_534, ValueType::String, Some(2))), Ok(2));
        assert_eq!(l.take(&point(Table::InputRegisters, 12, ValueType::U16, None)), Ok(3));
        assert_eq!(l.in_order().collect::<Vec<_>>(), [1, 0, 3, 2]);
        assert_eq!(l.counts(), [1, 0, 0, 3]);
        assert_eq!(l.start(0), Some((Table::InputRegisters, 10)));
        let p = point(Table::InputRegisters, 11, ValueType::U16, None);
        assert_eq!(
            l.problem(&p, Clash::Overlaps(0), Some(("P10", "row 10"))).why,
            "input_registers 11 overlaps \"P10\" (row 10, address 10) — a profile defines each address once"
        );
    }
}
