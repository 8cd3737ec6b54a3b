//! What `learn` writes: a draft profile per unit (TOML in the format of `docs/profiles.md`, each
//! entry named `reg_<table>_<address>` with a comment giving its evidence and confidence), and
//! the same findings as text or JSON.

use std::fmt::Write as _;

use super::infer::{Guess, Kind};
use super::{Learner, Unit};
use mbtap_device::profile::Table;
use mbtap_device::profile::escape::{comment, toml_str};
use mbtap_device::query::rows::short_table;

const TABLES: [Table; 4] = [Table::Coils, Table::DiscreteInputs, Table::HoldingRegisters, Table::InputRegisters];

/// The draft profile of `unit`, learned from `source` (a capture or port, for the comments);
/// `hints` (values read off the device's display) fix scales.
#[must_use]
pub fn profile_toml(unit: u8, u: &Unit, source: &str, hints: &[super::hint::Hint]) -> String {
    let mut s = String::new();
    let _ =
        writeln!(s, "# Drafted by `mbtap learn` from {} — check every entry before relying on it:", comment(source));
    let _ =
        writeln!(s, "# names are placeholders; each comment says what the traffic showed and how sure the guess is.");
    let _ = writeln!(s, "\n[profile]\nname = \"learned-unit-{unit}\"");
    let _ = writeln!(s, "device = {}", toml_str(&format!("unit {unit} (drafted by mbtap learn)")));
    let functions: Vec<String> = u.functions.iter().filter(|&&f| f & 0x80 == 0).map(u8::to_string).collect();
    let _ = writeln!(s, "functions = [{}]\ndefault_address = {unit}", functions.join(", "));
    for table in TABLES {
        let guesses = if u.tables().contains(&table) { u.guesses(table) } else { Vec::new() };
        for g in &guesses {
            let hint = hints.iter().find(|h| h.unit == unit && h.table == table && h.address == g.address);
            entry(&mut s, table, g, u, hint);
        }
        // Written but never read: a setpoint or command register.
        for (&(t, a), values) in u.writes.range((table, 0)..=(table, u16::MAX)) {
            if guesses.iter().any(|g| (g.address..g.address.saturating_add(g.kind.width())).contains(&a)) {
                continue;
            }
            let shown: Vec<String> = values.iter().map(u16::to_string).collect();
            let _ = writeln!(
                s,
                "\n# written, never read back: values {}\n[[{}]]\naddress = {a}\nname = \"reg_{}_{a}\"\naccess = \"w\"",
                shown.join(", "),
                t.name(),
                short_table(t)
            );
        }
    }
    s
}

fn entry(s: &mut String, table: Table, g: &Guess, u: &Unit, hint: Option<&super::hint::Hint>) {
    let a = g.address;
    let _ = writeln!(s, "\n# {} — {} (confidence {:.2})", g.kind.name(), comment(&g.evidence), g.confidence);
    // A hint fixes the scale of a number (not of text, labels or bits).
    let numeric = matches!(
        g.kind,
        Kind::Constant | Kind::Counter | Kind::U16 | Kind::I16 | Kind::U32 { .. } | Kind::I32 { .. } | Kind::F32 { .. }
    ) && matches!(table, Table::HoldingRegisters | Table::InputRegisters);
    let scale = match (hint, numeric) {
        (Some(h), true) => u.last_raw(table, g).map(|raw| {
            let (scale, said) = super::hint::scale_from(h.value, raw, matches!(g.kind, Kind::F32 { .. }));
            let _ = writeln!(s, "# hint: {}", comment(&said));
            scale
        }),
        (Some(h), false) => {
            let _ = writeln!(s, "# hint: the device showed {} (no scale for a {})", h.value, g.kind.name());
            None
        }
        (None, _) => None,
    }
    .flatten();
    if let Some(values) = u.writes.get(&(table, a)) {
        let shown: Vec<String> = values.iter().map(u16::to_string).collect();
        let _ = writeln!(s, "# the master wrote: {}", shown.join(", "));
    }
    let _ = writeln!(s, "[[{}]]\naddress = {a}\nname = \"reg_{}_{a}\"", table.name(), short_table(table));
    let writable = matches!(table, Table::Coils | Table::HoldingRegisters) && u.writes.contains_key(&(table, a));
    if writable {
        let _ = writeln!(s, "access = \"rw\"");
    }
    if matches!(table, Table::Coils | Table::DiscreteInputs) {
        return;
    }
    if let Some(scale) = scale {
        let _ = writeln!(s, "scale = {scale}");
    }
    let order = |h: bool| if h { "high_first" } else { "low_first" };
    match &g.kind {
        Kind::Constant | Kind::Counter | Kind::U16 => {}
        Kind::I16 => {
            let _ = writeln!(s, "type = \"i16\"");
        }
        Kind::Enum(values) => {
            let labels: Vec<String> = values.iter().map(|v| format!("{v} = \"value {v}\"")).collect();
            let _ = writeln!(s, "type = \"enum\"\nenum = {{ {} }}", labels.join(", "));
        }
        Kind::Bits(mask) => {
            let labels: Vec<String> =
                (0..16).filter(|b| mask & (1 << b) != 0).map(|b| format!("{b} = \"bit {b}\"")).collect();
            let _ = writeln!(s, "type = \"bits\"\nbits = {{ {} }}", labels.join(", "));
        }
        Kind::U32 { high_first, .. } => {
            let _ = writeln!(s, "type = \"u32\"\nword_order = \"{}\"", order(*high_first));
        }
        Kind::I32 { high_first } => {
            let _ = writeln!(s, "type = \"i32\"\nword_order = \"{}\"", order(*high_first));
        }
        Kind::F32 { high_first } => {
            let _ = writeln!(s, "type = \"f32\"\nword_order = \"{}\"", order(*high_first));
        }
        Kind::Text { registers, .. } => {
            let _ = writeln!(s, "type = \"string\"\nlength = {registers}\nchars_per_register = 2");
        }
    }
}

/// What was heard and not learned past the learner's bounds, when anything was: what to do.
#[must_use]
pub fn not_kept_note(l: &Learner) -> Option<String> {
    let mut parts = Vec::new();
    if l.not_kept_registers > 0 {
        parts.push(format!(
            "{} values of registers past the first {} kept",
            l.not_kept_registers,
            super::MAX_REGISTERS
        ));
    }
    if l.not_kept_other > 0 {
        parts.push(format!(
            "{} reads, exceptions or writes of blocks and addresses past the first {} kept",
            l.not_kept_other,
            super::MAX_OTHER
        ));
    }
    (!parts.is_empty())
        .then(|| format!("{} were heard and not learned: learn one unit at a time (--unit N)", parts.join(" and ")))
}

/// The findings for people: per unit, the blocks polled, writes, exceptions and each guess.
#[must_use]
pub fn text(l: &Learner) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "learned from {} answered transactions", l.transactions);
    if let Some(note) = not_kept_note(l) {
        let _ = writeln!(s, "{note}");
    }
    for (unit, u) in &l.units {
        let functions: Vec<String> = u.functions.iter().map(|f| format!("{f:02X}")).collect();
        let _ = writeln!(s, "\nunit {unit}: functions {}", functions.join(", "));
        for (&(t, first, q), b) in &u.blocks {
            let period = b.period_ns().map_or_else(|| "once".to_owned(), |p| format!("every {:.2} s", ms(p) / 1000.0));
            let _ = writeln!(
                s,
                "  polls {} {first}..{} ({q}), {} times, {period}",
                short_table(t),
                (u32::from(first) + u32::from(q)).saturating_sub(1),
                b.polls
            );
        }
        for (&(t, first, q), code) in &u.exceptions {
            let _ = writeln!(
                s,
                "  {} {first} ({q}): exception {code:02X}{}",
                short_table(t),
                if *code == 2 { " — no such address" } else { "" }
            );
        }
        for (&(t, a), values) in &u.writes {
            let shown: Vec<String> = values.iter().map(u16::to_string).collect();
            let _ = writeln!(s, "  wrote {} {a}: {}", short_table(t), shown.join(", "));
        }
        for t in u.tables() {
            for g in u.guesses(t) {
                let _ = writeln!(
                    s,
                    "  {} {}: {} — {} (confidence {:.2})",
                    short_table(t),
                    g.address,
                    g.kind.name(),
                    comment(&g.evidence),
                    g.confidence
                );
            }
        }
    }
    s
}

#[allow(clippy::cast_precision_loss)]
fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// The same as JSON: `{"transactions": N, "not_kept": {"registers", "other"}, "units": [{"unit", "functions", "blocks", "writes",
/// "exceptions", "registers": [{"table", "address", "type", "width", "confidence", "evidence"}]}]}`,
/// serialised as it goes — one register's object at a time, never the whole tree (a
/// capture of 400 000 registers took 1.8 GB as one tree). `serde_json::to_value` of it gives the
/// tree where one is wanted.
#[derive(Debug, Clone, Copy)]
pub struct Json<'a>(pub &'a Learner);

/// One unit of [`Json`].
struct UnitJson<'a>(u8, &'a Unit);

/// A unit's register guesses, table by table.
struct Registers<'a>(&'a Unit);

impl serde::Serialize for Json<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap as _;
        let mut m = s.serialize_map(Some(3))?;
        m.serialize_entry("transactions", &self.0.transactions)?;
        m.serialize_entry(
            "not_kept",
            &serde_json::json!({"registers": self.0.not_kept_registers, "other": self.0.not_kept_other}),
        )?;
        m.serialize_entry("units", &Units(self.0))?;
        m.end()
    }
}

struct Units<'a>(&'a Learner);

impl serde::Serialize for Units<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.units.iter().map(|(&unit, u)| UnitJson(unit, u)))
    }
}

impl serde::Serialize for UnitJson<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap as _;
        let UnitJson(unit, u) = *self;
        // Each element built and written in turn: never all of a unit's blocks as one tree.
        let blocks = Each(|| {
            u.blocks.iter().map(|(&(t, first, q), b)| {
                serde_json::json!({"table": t.name(), "first": first, "quantity": q, "polls": b.polls, "period_ns": b.period_ns()})
            })
        });
        let writes = Each(|| {
            u.writes.iter().map(|(&(t, a), v)| serde_json::json!({"table": t.name(), "address": a, "values": v}))
        });
        let exceptions = Each(|| {
            u.exceptions.iter().map(
                |(&(t, first, q), c)| serde_json::json!({"table": t.name(), "first": first, "quantity": q, "code": c}),
            )
        });
        let mut m = s.serialize_map(Some(6))?;
        m.serialize_entry("unit", &unit)?;
        m.serialize_entry("functions", &u.functions)?;
        m.serialize_entry("blocks", &blocks)?;
        m.serialize_entry("writes", &writes)?;
        m.serialize_entry("exceptions", &exceptions)?;
        m.serialize_entry("registers", &Registers(u))?;
        m.end()
    }
}

/// A sequence serialised from a fresh iterator, one element at a time.
struct Each<F>(F);

impl<F, I> serde::Serialize for Each<F>
where
    F: Fn() -> I,
    I: Iterator<Item = serde_json::Value>,
{
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq((self.0)())
    }
}

impl serde::Serialize for Registers<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq as _;
        let mut seq = s.serialize_seq(None)?;
        for t in self.0.tables() {
            for g in self.0.guesses(t) {
                seq.serialize_element(&serde_json::json!({
                    "table": t.name(), "address": g.address, "type": g.kind.name(), "width": g.kind.width(),
                    "confidence": g.confidence, "evidence": g.evidence,
                }))?;
            }
        }
        seq.end()
    }
}

/// [`Json`] as a tree.
#[must_use]
pub fn json(l: &Learner) -> serde_json::Value {
    serde_json::to_value(Json(l)).unwrap_or_default()
}
