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

pub use mbtap_proto::table::{TABLE_WORDS, is_bits, read_function, table_read_by, table_word};
