//! A device's register values as a recording or an image gave them: dense pages of 256
//! addresses per table, each with a bitmap of the addresses present. A unit read over its whole
//! holding and input tables takes 2 × 256 pages of [`PAGE_BYTES`] (272 KiB), so every unit a
//! recording shows keeps its values within a bound a caller can count in bytes (a map of one
//! entry per value costs about 12 bytes a value).

use std::collections::BTreeMap;

use mbtap_device::profile::format::Table;

/// Addresses per page.
const PAGE: usize = 256;

/// The memory one page takes (its values and its bitmap), for budgets in bytes.
pub const PAGE_BYTES: usize = PAGE * 2 + PAGE / 8;

#[derive(Debug, Clone, PartialEq, Eq)]
struct Page {
    present: [u64; PAGE / 64],
    words: [u16; PAGE],
}

impl Default for Page {
    fn default() -> Self {
        Self { present: [0; PAGE / 64], words: [0; PAGE] }
    }
}

/// Where `address` lives: its page's number and its place in it.
const fn place(address: u16) -> (u8, usize) {
    let [page, at] = address.to_be_bytes();
    (page, at as usize)
}

/// One device's values by table and address.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Values {
    pages: BTreeMap<(Table, u8), Box<Page>>,
}

impl Values {
    /// The value at `address` of `table`, if known.
    #[must_use]
    pub fn get(&self, table: Table, address: u16) -> Option<u16> {
        let (page, at) = place(address);
        let p = self.pages.get(&(table, page))?;
        let known = p.present.get(at / 64).is_some_and(|bits| bits >> (at % 64) & 1 == 1);
        if known { p.words.get(at).copied() } else { None }
    }

    /// Whether `address` of `table` is known.
    #[must_use]
    pub fn contains(&self, table: Table, address: u16) -> bool {
        self.get(table, address).is_some()
    }

    /// Whether setting `address` of `table` needs a page the store does not have yet.
    #[must_use]
    pub fn needs_page(&self, table: Table, address: u16) -> bool {
        !self.pages.contains_key(&(table, place(address).0))
    }

    /// Sets `address` of `table` to `value`.
    pub fn insert(&mut self, table: Table, address: u16, value: u16) {
        let (page, at) = place(address);
        let p = self.pages.entry((table, page)).or_default();
        if let (Some(bits), Some(word)) = (p.present.get_mut(at / 64), p.words.get_mut(at)) {
            *bits |= 1 << (at % 64);
            *word = value;
        }
    }

    /// How many addresses of `table` are known.
    #[must_use]
    pub fn count(&self, table: Table) -> usize {
        self.pages
            .range((table, 0)..=(table, u8::MAX))
            .map(|(_, p)| p.present.iter().map(|b| b.count_ones() as usize).sum::<usize>())
            .sum()
    }

    /// The pages held (each [`PAGE_BYTES`]).
    #[must_use]
    pub fn pages(&self) -> usize {
        self.pages.len()
    }
}

impl FromIterator<((Table, u16), u16)> for Values {
    fn from_iter<I: IntoIterator<Item = ((Table, u16), u16)>>(iter: I) -> Self {
        let mut v = Self::default();
        for ((table, address), value) in iter {
            v.insert(table, address, value);
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_kept_by_table_and_address_at_the_edges_too() {
        let mut v = Values::default();
        for a in [0, 63, 64, 255, 256, u16::MAX] {
            v.insert(Table::HoldingRegisters, a, a ^ 0x5A5A);
        }
        v.insert(Table::InputRegisters, 0, 7);
        for a in [0, 63, 64, 255, 256, u16::MAX] {
            assert_eq!(v.get(Table::HoldingRegisters, a), Some(a ^ 0x5A5A));
        }
        assert_eq!(v.get(Table::HoldingRegisters, 1), None);
        assert_eq!(v.get(Table::InputRegisters, 0), Some(7));
        assert_eq!(v.get(Table::Coils, 0), None);
        assert_eq!((v.count(Table::HoldingRegisters), v.count(Table::InputRegisters)), (6, 1));
        assert_eq!(v.pages(), 4);
    }

    #[test]
    fn a_whole_table_takes_256_pages() {
        let v: Values = (0..=u16::MAX).map(|a| ((Table::InputRegisters, a), a)).collect();
        assert_eq!((v.pages(), v.count(Table::InputRegisters)), (256, 65_536));
        assert_eq!(v.get(Table::InputRegisters, 40_000), Some(40_000));
    }
}
