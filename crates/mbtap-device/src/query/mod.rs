//! What `mbtap read`, `write` and `watch` ask of a device, worked out before anything is sent:
//! the items a user typed (names, addresses, ranges, `NAME=VALUE`) resolved against a profile
//! ([`resolve`]), split into requests the spec and the device allow ([`plan`]), written values
//! checked and encoded ([`encode`]), and the answers turned into named, scaled rows ([`rows`]).
//!
//! Pure: no I/O and no transport. The edge (`src/master/`) sends the requests with
//! tokio-modbus and hands the answers back here.

pub mod encode;
pub mod items;
pub mod plan;
pub mod resolve;
pub mod rows;

use crate::profile::Table;

/// Why an item cannot be read or written. Each says what was wrong, where, and what to do.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum QueryError {
    #[error("{item:?}: {problem}")]
    Syntax { item: String, problem: String },
    #[error("{item:?}: no register or point of this name in the {profile} profile{}", suggestion.as_ref().map(|s| format!(" — did you mean {s:?}?")).unwrap_or_default())]
    UnknownName { item: String, profile: String, suggestion: Option<String> },
    #[error(
        "{item:?}: a name needs a device profile (--device NAME); without one, give a table and an address, e.g. `holding 100`"
    )]
    NameWithoutProfile { item: String },
    #[error(
        "{item:?}: which table? {why}; put one of coils, discrete, holding, input before it (e.g. `holding {item}`)"
    )]
    TableNeeded { item: String, why: String },
    #[error("{item:?}: {name:?} is in more than one table ({tables}); put the table before it")]
    AmbiguousName { item: String, name: String, tables: String },
    #[error("{item:?}: {table} cannot be written (only coils and holding registers can)")]
    NotWritable { item: String, table: &'static str },
    #[error("{item:?}: {problem}{}", if *forceable { " (--force sends it anyway)" } else { "" })]
    BadValue { item: String, problem: String, forceable: bool },
    #[error("{item:?}: every address in it is reserved by the device's document; nothing to read")]
    AllReserved { item: String },
}

/// The table words users type, and the table each means.
pub const TABLE_WORDS: &[(&str, Table)] = &[
    ("coils", Table::Coils),
    ("coil", Table::Coils),
    ("discrete", Table::DiscreteInputs),
    ("discrete_inputs", Table::DiscreteInputs),
    ("holding", Table::HoldingRegisters),
    ("holding_registers", Table::HoldingRegisters),
    ("input", Table::InputRegisters),
    ("input_registers", Table::InputRegisters),
];

/// The table a word names, if it names one.
#[must_use]
pub fn table_word(word: &str) -> Option<Table> {
    TABLE_WORDS.iter().find(|(w, _)| w.eq_ignore_ascii_case(word)).map(|&(_, t)| t)
}

/// The function code that reads `table` (MAP v1.1b3 §6.1–§6.4).
#[must_use]
pub const fn read_function(table: Table) -> u8 {
    match table {
        Table::Coils => 0x01,
        Table::DiscreteInputs => 0x02,
        Table::HoldingRegisters => 0x03,
        Table::InputRegisters => 0x04,
    }
}

/// The table a read function code reads, when it is one (MAP v1.1b3 §6.1–§6.4).
#[must_use]
pub const fn table_read_by(function: u8) -> Option<Table> {
    match function {
        0x01 => Some(Table::Coils),
        0x02 => Some(Table::DiscreteInputs),
        0x03 => Some(Table::HoldingRegisters),
        0x04 => Some(Table::InputRegisters),
        _ => None,
    }
}

/// Whether a table holds bits (coils, discrete inputs) rather than 16-bit registers.
#[must_use]
pub const fn is_bits(table: Table) -> bool {
    matches!(table, Table::Coils | Table::DiscreteInputs)
}
