//! The profile file format (TOML), as written by people: device metadata, line defaults, and
//! per table the points and registers a device has. Documented with a complete example in
//! `docs/profiles.md`. Unknown keys are errors, so a typo is caught at load time.

use std::collections::BTreeMap;

use serde::Deserialize;
use toml::Spanned;

/// A whole profile file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileFile {
    pub profile: Meta,
    #[serde(default)]
    pub line: Option<LineDefaults>,
    #[serde(default)]
    pub coils: Vec<Spanned<PointDef>>,
    #[serde(default)]
    pub discrete_inputs: Vec<Spanned<PointDef>>,
    #[serde(default)]
    pub holding_registers: Vec<Spanned<RegisterDef>>,
    #[serde(default)]
    pub input_registers: Vec<Spanned<RegisterDef>>,
    /// Groups of registers that repeat (log records, channels): declared once.
    #[serde(default)]
    pub blocks: Vec<Spanned<BlockDef>>,
    /// Address ranges the document reserves.
    #[serde(default)]
    pub reserved: Vec<Spanned<ReservedDef>>,
    /// Functions whose structure does not fix their frames' lengths (vendor codes), with the
    /// lengths this device uses: they decide CRC-`00` twins from the first frame on.
    #[serde(default)]
    pub vendor_functions: Vec<Spanned<VendorFunctionDef>>,
}

/// A vendor function's frame lengths, in bytes on the line (address and CRC included).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VendorFunctionDef {
    pub code: u8,
    #[serde(default)]
    pub request_length: Option<u16>,
    #[serde(default)]
    pub response_length: Option<u16>,
}

/// Who the device is and where its map comes from.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Meta {
    /// Short name used on the command line (`--device 1=NAME`).
    pub name: String,
    pub device: String,
    #[serde(default)]
    pub vendor: Option<String>,
    /// The document the map was made from.
    #[serde(default)]
    pub document: Option<String>,
    /// Function codes the device supports.
    #[serde(default)]
    pub functions: Vec<u8>,
    #[serde(default)]
    pub default_address: Option<u8>,
    /// Addresses the device also answers (the MKZP answers 247 as well as its own).
    #[serde(default)]
    pub also_answers: Vec<u8>,
    /// Out-of-range writes are clamped by the device rather than refused.
    #[serde(default)]
    pub clamps_writes: bool,
}

/// Serial defaults the document gives.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineDefaults {
    #[serde(default)]
    pub baud: Option<u32>,
    /// `8E1` style.
    #[serde(default)]
    pub framing: Option<String>,
    #[serde(default)]
    pub mode: Option<String>,
}

/// Read/write access.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
pub enum Access {
    #[serde(rename = "r")]
    #[default]
    Read,
    #[serde(rename = "rw")]
    ReadWrite,
    #[serde(rename = "w")]
    Write,
}

/// A coil or discrete input, or a run of them sharing one description (`addresses`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointDef {
    #[serde(default)]
    pub address: Option<u16>,
    /// Inclusive range `[first, last]`; `{n}` in names counts from 1.
    #[serde(default)]
    pub addresses: Option<[u16; 2]>,
    pub name: String,
    #[serde(default)]
    pub name_ru: Option<String>,
    #[serde(default)]
    pub description: Option<String>,
    #[serde(default)]
    pub access: Access,
    /// Labels for 1 and 0.
    #[serde(default)]
    pub on: Option<String>,
    #[serde(default)]
    pub off: Option<String>,
}

/// How a register's bits are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ValueType {
    #[default]
    U16,
    I16,
    /// Two registers.
    U32,
    I32,
    /// Four registers (energy totals: ABB's B-series meters, SunSpec's acc64).
    U64,
    I64,
    F32,
    Bool,
    /// Named bits (see `bits`).
    Bits,
    /// Named values (see `enum`).
    Enum,
    /// Characters, `chars_per_register` per register, over `length` registers.
    String,
    /// A date/time group: one register per part, in the order `parts` gives
    /// (`year`, `month`, `day`, `hour`, `minute`, `second`).
    Datetime,
}

/// Word order of 32- and 64-bit values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum WordOrder {
    #[default]
    HighFirst,
    LowFirst,
}

/// A register, a run of registers sharing one description, or a field of a block.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegisterDef {
    #[serde(default)]
    pub address: Option<u16>,
    #[serde(default)]
    pub addresses: Option<[u16; 2]>,
    /// Offset inside a block (blocks only).
    #[serde(default)]
    pub offset: Option<u16>,
    pub name: String,
    #[serde(default)]
    pub name_ru: Option<String>,
    #[serde(default)]
    pub description: Option<String>,
    #[serde(default)]
    pub access: Access,
    #[serde(default, rename = "type")]
    pub value_type: ValueType,
    #[serde(default)]
    pub word_order: WordOrder,
    /// Multiply the raw value by this (0.1 for tenths).
    #[serde(default)]
    pub scale: Option<f64>,
    #[serde(default)]
    pub unit: Option<String>,
    /// Valid raw range, inclusive.
    #[serde(default)]
    pub range: Option<[i64; 2]>,
    /// Value labels (type `enum`), keys are the raw values.
    #[serde(default, rename = "enum")]
    pub labels: BTreeMap<String, String>,
    /// Bit labels (type `bits`), keys are bit numbers 0–15.
    #[serde(default)]
    pub bits: BTreeMap<String, String>,
    /// Registers a string spans (type `string`).
    #[serde(default)]
    pub length: Option<u16>,
    #[serde(default)]
    pub chars_per_register: Option<u8>,
    /// The parts of a `datetime`, one register each, in register order.
    #[serde(default)]
    pub parts: Vec<DatePart>,
    /// Values that are commands (written to act, e.g. `30 = "clear alarm log"`).
    #[serde(default)]
    pub commands: BTreeMap<String, String>,
}

/// One part of a date/time group.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DatePart {
    Year,
    Month,
    Day,
    Hour,
    Minute,
    Second,
}

pub use mbtap_proto::Table;

/// How a profile names a table (`holding_registers`, …): [`Table`] lives in the protocol crate,
/// which knows nothing of serde, so the profile format reads it through this mirror.
#[derive(Deserialize)]
#[serde(remote = "Table", rename_all = "snake_case")]
enum TableName {
    Coils,
    DiscreteInputs,
    HoldingRegisters,
    InputRegisters,
}

/// A repeated group: `count` copies, `stride` registers apart, from `start`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockDef {
    #[serde(with = "TableName")]
    pub table: Table,
    pub start: u16,
    pub count: u16,
    pub stride: u16,
    /// Title of each copy; `{n}` counts from 1.
    pub title: String,
    pub fields: Vec<RegisterDef>,
}

/// Addresses the document reserves.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReservedDef {
    #[serde(with = "TableName")]
    pub table: Table,
    pub addresses: [u16; 2],
}
