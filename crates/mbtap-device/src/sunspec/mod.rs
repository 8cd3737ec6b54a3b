//! SunSpec devices describe themselves (SunSpec Information Model Specification): a `SunS`
//! marker at 40000 (or 0, or 50000), then a chain of models — ID, length, that many registers —
//! until ID `0xFFFF`. The models' definitions are the SunSpec Alliance's JSON, as pysunspec2
//! ships it (Apache-2.0), condensed by `contrib/sunspec-models.py` into `models.json`: each
//! model's top-level points and its first repeating group.
//!
//! Pure: the edge reads registers; this module says where the chain goes, decodes a model's
//! registers into points scaled by their `sf` points, shows "not implemented" values (0x8000,
//! 0xFFFF, 0x80000000, NaN, …) as absent, and resolves names like `common.Mn`, `103.W`,
//! `inverter_three_phase[2].W`, `mppt.module[1].DCA`.

mod decode;
mod names;

pub use decode::{Shown, Value, decode_model};
pub use names::{ModelSel, PointRef, parse_point_ref};

use std::sync::OnceLock;

use serde::Deserialize;

/// Where the `SunS` marker is looked for, in order (SunSpec Information Model Specification
/// §6.1.3: base register 40000, alternatively 0 or 50000 — as Modicon 40001, 1, 50001).
pub const BASES: [u16; 3] = [40000, 0, 50000];
/// `SunS` as two registers.
pub const MARKER: [u16; 2] = [0x5375, 0x6E53];
/// The ID that ends the chain.
pub const END_ID: u16 = 0xFFFF;
/// Models followed at most (a device's chain has a dozen; a loop must end).
pub const MAX_MODELS: usize = 64;

/// One point of a model.
#[derive(Debug, Clone, Deserialize)]
#[serde(from = "(String, String, u16, Option<Sf>, Option<String>)")]
pub struct PointDef {
    pub name: String,
    /// SunSpec's type name (`uint16`, `int16`, `acc32`, `float32`, `string`, `sunssf`, …).
    pub kind: String,
    /// Registers.
    pub size: u16,
    /// This point's scale factor: the point holding it, or (in a few models) a fixed one.
    pub sf: Option<Sf>,
    pub units: Option<String>,
}

/// A scale factor: a point's name, or fixed.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(untagged)]
pub enum Sf {
    Fixed(i16),
    Point(String),
}

impl From<(String, String, u16, Option<Sf>, Option<String>)> for PointDef {
    fn from((name, kind, size, sf, units): (String, String, u16, Option<Sf>, Option<String>)) -> Self {
        Self { name, kind, size, sf, units }
    }
}

/// How often a model's repeating group repeats.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum Count {
    /// `0`: as often as the model's length holds; else that many times.
    Fixed(u16),
    /// As often as the named point says.
    Point(String),
}

/// A repeating group (an MPPT's modules, a curve's points).
#[derive(Debug, Clone, Deserialize)]
pub struct Repeat {
    pub name: String,
    pub count: Count,
    pub points: Vec<PointDef>,
}

/// A model's definition.
#[derive(Debug, Clone, Deserialize)]
pub struct ModelDef {
    pub id: u16,
    /// The group name (`common`, `inverter_three_phase`).
    pub name: String,
    pub points: Vec<PointDef>,
    #[serde(default)]
    pub repeat: Option<Repeat>,
}

#[derive(Debug, Deserialize)]
struct Models {
    source: String,
    models: Vec<ModelDef>,
}

fn models() -> &'static Models {
    static MODELS: OnceLock<Models> = OnceLock::new();
    MODELS.get_or_init(|| {
        // Built in and checked by a test: a failure here is a build defect, and an empty set
        // still leaves every model shown raw by its ID.
        serde_json::from_str(include_str!("models.json"))
            .unwrap_or_else(|_| Models { source: String::new(), models: Vec::new() })
    })
}

/// Where the model definitions came from (for `--help` and the docs).
#[must_use]
pub fn source() -> &'static str {
    &models().source
}

/// The definition of model `id`, if known.
#[must_use]
pub fn model(id: u16) -> Option<&'static ModelDef> {
    models().models.iter().find(|m| m.id == id)
}

/// The definition named `name` (its group name), if known.
#[must_use]
pub fn model_named(name: &str) -> Option<&'static ModelDef> {
    models().models.iter().find(|m| m.name.eq_ignore_ascii_case(name))
}

/// A model found in a device's chain: its ID, the address of its ID register, and its length
/// (registers after the ID and length registers).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Found {
    pub id: u16,
    pub address: u16,
    pub len: u16,
}

impl Found {
    /// The registers the model's block covers (ID and length included).
    #[must_use]
    pub fn registers(&self) -> u32 {
        u32::from(self.len) + 2
    }

    /// The model's group name, or its ID for a model not known.
    #[must_use]
    pub fn name(&self) -> String {
        model(self.id).map_or_else(|| self.id.to_string(), |m| m.name.clone())
    }
}

/// The next step of a chain walk after the model header `(id, len)` read at `at`: the next
/// header's address, or `None` at the end (ID `0xFFFF`, the address space or [`MAX_MODELS`]).
#[must_use]
pub fn next_header(at: u16, id: u16, len: u16, found_so_far: usize) -> Option<u16> {
    if id == END_ID || found_so_far >= MAX_MODELS {
        return None;
    }
    u16::try_from(u32::from(at) + 2 + u32::from(len)).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_models_load_with_their_names() {
        let parsed: Result<Models, _> = serde_json::from_str(include_str!("models.json"));
        assert!(parsed.is_ok(), "{:?}", parsed.err());
        assert!(source().contains("pysunspec2"), "{}", source());
        assert_eq!(model(1).map(|m| m.name.as_str()), Some("common"));
        assert_eq!(model(103).map(|m| m.name.as_str()), Some("inverter_three_phase"));
        assert_eq!(model_named("mppt").map(|m| m.id), Some(160));
        assert!(model(160).and_then(|m| m.repeat.as_ref()).is_some());
        assert!(model(64_999).is_none());
    }

    #[test]
    fn the_chain_ends_at_ffff_at_the_top_of_the_address_space_and_after_max_models() {
        assert_eq!(next_header(40002, 1, 66, 0), Some(40070));
        assert_eq!(next_header(40070, END_ID, 0, 1), None);
        assert_eq!(next_header(65530, 1, 66, 1), None);
        assert_eq!(next_header(40002, 1, 66, MAX_MODELS), None);
    }
}
