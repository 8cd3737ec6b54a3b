//! A loaded profile: every documented address of every table resolved to its description, so
//! annotation is a map lookup.

use std::collections::BTreeMap;

use super::format::{Access, LineDefaults, Meta, Table, ValueType, WordOrder};

/// One description, shared by every address it covers.
#[derive(Debug, Clone, PartialEq)]
pub struct Def {
    pub name: String,
    pub name_ru: Option<String>,
    pub description: Option<String>,
    pub access: Access,
    pub value_type: ValueType,
    pub word_order: WordOrder,
    pub scale: Option<f64>,
    pub unit: Option<String>,
    pub range: Option<(i64, i64)>,
    pub labels: BTreeMap<i64, String>,
    pub bits: BTreeMap<u8, String>,
    /// Registers the value spans (2 for 32-bit types, `length` for strings, else 1).
    pub width: u16,
    pub chars_per_register: u8,
    /// Parts of a date/time group, in register order.
    pub parts: Vec<super::format::DatePart>,
    pub commands: BTreeMap<i64, String>,
    /// Labels of 1 and 0 for points.
    pub on: Option<String>,
    pub off: Option<String>,
}

/// What an address is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Slot {
    /// Index into [`Profile::defs`].
    pub def: usize,
    /// Which register of a multi-register value this address is (0 = first on the wire).
    pub part: u16,
    /// The value's first address.
    pub first: u16,
    /// The name with `{n}` expanded, and the block title in front for block fields.
    pub name: String,
}

/// A loaded, checked profile.
#[derive(Debug, Clone)]
pub struct Profile {
    pub meta: Meta,
    pub line: Option<LineDefaults>,
    pub defs: Vec<Def>,
    pub tables: BTreeMap<Table, BTreeMap<u16, Slot>>,
    pub reserved: Vec<(Table, u16, u16)>,
    /// Vendor functions' frame lengths the document gives: `(code, request, response)`, in
    /// bytes on the line.
    pub vendor_lengths: Vec<(u8, Option<u16>, Option<u16>)>,
}

impl Profile {
    /// What `address` of `table` is, if documented.
    #[must_use]
    pub fn slot(&self, table: Table, address: u16) -> Option<(&Slot, &Def)> {
        let slot = self.tables.get(&table)?.get(&address)?;
        Some((slot, &self.defs[slot.def]))
    }

    /// Whether the document reserves `address` of `table`.
    #[must_use]
    pub fn is_reserved(&self, table: Table, address: u16) -> bool {
        self.reserved.iter().any(|&(t, a, b)| t == table && (a..=b).contains(&address))
    }

    /// Every documented address of `table`, in order.
    pub fn addresses(&self, table: Table) -> impl Iterator<Item = u16> + '_ {
        self.tables.get(&table).into_iter().flat_map(|m| m.keys().copied())
    }
}
