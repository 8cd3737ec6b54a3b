//! Annotating register and bit values with a profile: names, scaled values with units, enum
//! labels, set bits, strings, 32-bit pairs — and findings: values outside the document's
//! range, reserved or undocumented addresses, writes to read-only registers, half of a 32-bit
//! pair read alone, writes the device will clamp.
//!
//! Its `value_text` module shows one value: scaled, signed, a date or an enumeration's text, with
//! its notes.

use std::fmt;

use super::format::{Access, Table, ValueType, WordOrder};
use super::model::Profile;

mod value_text;
use value_text::{datetime, impossible_date_part, shown, signed16, trim};

/// How a value reads.
#[derive(Debug, Clone, PartialEq)]
pub enum Shown {
    /// A number; `decimals` is the precision its scale implies (1 for 0.1), `None` to print
    /// the shortest form (floats).
    Number {
        value: f64,
        unit: Option<String>,
        decimals: Option<u8>,
    },
    Label(String),
    /// Labels of the set bits (unnamed ones as `bit N`).
    Bits(Vec<String>),
    Text(String),
    /// A date/time group as one value (`2026-11-22 14:35`).
    Time(String),
    Bool {
        on: bool,
        label: Option<String>,
    },
    /// Nothing known about it: the raw value only.
    Raw,
}

/// Something worth flagging about one value.
#[derive(Debug, Clone, PartialEq)]
pub enum Note {
    OutOfRange {
        min: i64,
        max: i64,
    },
    /// A write out of range that the device clamps to this raw value.
    WillClamp {
        to: i64,
    },
    Reserved,
    Undocumented,
    WriteToReadOnly,
    /// One register of a two-register value read or written without the other.
    HalfOfPair,
    /// A write that is a command.
    Command(String),
    /// A value the enumeration does not list.
    UnknownLabel,
}

impl Note {
    /// A stable snake_case name.
    #[must_use]
    pub const fn kind(&self) -> &'static str {
        match self {
            Self::OutOfRange { .. } => "out_of_range",
            Self::WillClamp { .. } => "will_clamp",
            Self::Reserved => "reserved_address",
            Self::Undocumented => "undocumented_address",
            Self::WriteToReadOnly => "write_to_read_only",
            Self::HalfOfPair => "half_of_pair",
            Self::Command(_) => "command",
            Self::UnknownLabel => "unknown_label",
        }
    }
}

impl fmt::Display for Note {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OutOfRange { min, max } => write!(f, "outside the documented range {min}..={max}"),
            Self::WillClamp { to } => write!(f, "out of range: the device clamps it to {to}"),
            Self::Reserved => write!(f, "reserved address"),
            Self::Undocumented => write!(f, "address not in the device's map"),
            Self::WriteToReadOnly => write!(f, "write to a read-only register"),
            Self::HalfOfPair => write!(f, "half of a multi-register value, the other half not in this transaction"),
            Self::Command(c) => write!(f, "command: {c}"),
            Self::UnknownLabel => write!(f, "value not in the documented list"),
        }
    }
}

/// One annotated value (a register, a register pair or string, or a bit).
#[derive(Debug, Clone, PartialEq)]
pub struct Annotation {
    pub table: Table,
    pub address: u16,
    /// Registers covered (2 for a 32-bit pair).
    pub width: u16,
    pub name: Option<String>,
    pub name_ru: Option<String>,
    /// The raw value (a pair combined in its word order).
    pub raw: i64,
    pub shown: Shown,
    pub notes: Vec<Note>,
}

/// Which names to show.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Lang {
    #[default]
    En,
    /// The document's original (Russian) names, where the profile has them.
    Ru,
}

impl Annotation {
    /// The annotation as one line with names in `lang`.
    #[must_use]
    pub fn line(&self, lang: Lang) -> String {
        InLang(self, lang).to_string()
    }
}

/// An annotation shown in a language.
struct InLang<'a>(&'a Annotation, Lang);

impl fmt::Display for InLang<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.write(f, self.1)
    }
}

impl fmt::Display for Annotation {
    /// `430 Phase A (L1) voltage = 230.5 V (raw 2305)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write(f, Lang::En)
    }
}

impl Annotation {
    /// The name in `lang` (the English one when the profile has no other).
    #[must_use]
    pub fn name_in(&self, lang: Lang) -> Option<&str> {
        match lang {
            Lang::Ru => self.name_ru.as_deref().or(self.name.as_deref()),
            Lang::En => self.name.as_deref(),
        }
    }

    /// The value as shown, with its unit: `230.5 V`, `running`, `"MK4"`.
    #[must_use]
    pub fn value_text(&self) -> String {
        let mut s = String::new();
        let _ = self.write_value(&mut s);
        s
    }

    fn write_value(&self, f: &mut dyn fmt::Write) -> fmt::Result {
        match &self.shown {
            Shown::Number { value, unit, decimals } => {
                match decimals {
                    Some(d) => write!(f, "{:.*}", usize::from(*d), value)?,
                    None => write!(f, "{}", trim(*value))?,
                }
                if let Some(u) = unit {
                    write!(f, " {u}")?;
                }
            }
            Shown::Label(l) => write!(f, "{l}")?,
            Shown::Bits(b) if b.is_empty() => write!(f, "(no bits set)")?,
            Shown::Bits(b) => write!(f, "{}", b.join(", "))?,
            Shown::Text(t) => write!(f, "{t:?}")?,
            Shown::Time(t) => write!(f, "{t}")?,
            Shown::Bool { on, label } => {
                write!(f, "{}", label.clone().unwrap_or_else(|| u8::from(*on).to_string()))?;
            }
            Shown::Raw => write!(f, "{}", self.raw)?,
        }
        Ok(())
    }

    fn write(&self, f: &mut fmt::Formatter<'_>, lang: Lang) -> fmt::Result {
        write!(f, "{} {} = ", self.address, self.name_in(lang).unwrap_or("?"))?;
        self.write_value(f)?;
        // A text or a time spans several registers: no single raw value to show.
        if !matches!(self.shown, Shown::Text(_) | Shown::Time(_)) {
            write!(f, " (raw {})", self.raw)?;
        }
        for n in &self.notes {
            write!(f, " [{n}]")?;
        }
        Ok(())
    }
}

/// Annotates register values read from (or written to) `table` from `start`.
#[must_use]
pub fn annotate_registers(p: &Profile, table: Table, start: u16, values: &[u16], write: bool) -> Vec<Annotation> {
    let mut out = Vec::new();
    let mut i = 0usize;
    while i < values.len() {
        let Some(address) = u16::try_from(i).ok().and_then(|i| start.checked_add(i)) else { break };
        let v = values[i];
        let Some((slot, def)) = p.slot(table, address) else {
            let note = if p.is_reserved(table, address) { Note::Reserved } else { Note::Undocumented };
            out.push(Annotation {
                table,
                address,
                width: 1,
                name: None,
                name_ru: None,
                raw: i64::from(v),
                shown: Shown::Raw,
                notes: vec![note],
            });
            i += 1;
            continue;
        };
        let width = usize::from(def.width);
        // Every register of the value present, in order, starting at its first?
        let whole = slot.part == 0 && i + width <= values.len();
        let (raw, bits32, used, mut notes) = if width == 1 {
            let raw = if def.value_type == ValueType::I16 { signed16(v) } else { i64::from(v) };
            (raw, None, 1, Vec::new())
        } else if !whole {
            (i64::from(v), None, 1, vec![Note::HalfOfPair])
        } else if matches!(def.value_type, ValueType::U64 | ValueType::I64) {
            let mut regs: Vec<u16> = values[i..i + width].to_vec();
            if def.word_order == WordOrder::LowFirst {
                regs.reverse();
            }
            let bits = regs.iter().fold(0u64, |acc, &w| (acc << 16) | u64::from(w));
            // A raw value is an i64: a u64 past its range (ABB's "not available", all ones) is
            // held at i64::MAX and said out of range.
            let (raw, notes) = match (def.value_type, i64::try_from(bits)) {
                (ValueType::I64, _) => (bits.cast_signed(), Vec::new()),
                (_, Ok(raw)) => (raw, Vec::new()),
                (_, Err(_)) => (i64::MAX, vec![Note::OutOfRange { min: 0, max: i64::MAX }]),
            };
            (raw, None, width, notes)
        } else if matches!(def.value_type, ValueType::Datetime | ValueType::String) {
            // A value spread over several registers: shown whole, no single raw value.
            let regs = &values[i..i + width];
            let (shown, notes) = if def.value_type == ValueType::Datetime {
                (Shown::Time(datetime(&def.parts, regs)), impossible_date_part(&def.parts, regs).into_iter().collect())
            } else {
                let text: String = regs
                    .iter()
                    .flat_map(|r| {
                        let [hi, lo] = r.to_be_bytes();
                        if def.chars_per_register == 1 { vec![lo] } else { vec![hi, lo] }
                    })
                    .take_while(|&c| c != 0)
                    .map(char::from)
                    .collect();
                (Shown::Text(text), Vec::new())
            };
            out.push(Annotation {
                table,
                address,
                width: def.width,
                name: Some(slot.name.clone()),
                name_ru: def.name_ru.clone(),
                raw: 0,
                shown,
                notes,
            });
            i += width;
            continue;
        } else {
            let (hi, lo) = match def.word_order {
                WordOrder::HighFirst => (values[i], values[i + 1]),
                WordOrder::LowFirst => (values[i + 1], values[i]),
            };
            let bits = (u32::from(hi) << 16) | u32::from(lo);
            let raw = if def.value_type == ValueType::I32 {
                i64::from(i32::from_ne_bytes(bits.to_ne_bytes()))
            } else {
                i64::from(bits)
            };
            (raw, Some(bits), 2, Vec::new())
        };
        let (shown, more) =
            if notes.contains(&Note::HalfOfPair) { (Shown::Raw, Vec::new()) } else { shown(def, raw, bits32) };
        notes.extend(more);
        if let Some((min, max)) = def.range
            && !notes.contains(&Note::HalfOfPair)
            && !(min..=max).contains(&raw)
        {
            notes.push(if write && p.meta.clamps_writes {
                Note::WillClamp { to: raw.clamp(min, max) }
            } else {
                Note::OutOfRange { min, max }
            });
        }
        if write && def.access == Access::Read {
            notes.push(Note::WriteToReadOnly);
        }
        if write && let Some(c) = def.commands.get(&raw) {
            notes.push(Note::Command(c.clone()));
        }
        out.push(Annotation {
            table,
            address: slot.first,
            width: u16::try_from(used).unwrap_or(1),
            name: Some(slot.name.clone()),
            name_ru: def.name_ru.clone(),
            raw,
            shown,
            notes,
        });
        i += used;
    }
    out
}

/// Annotates bits (coils or discrete inputs) from `start`.
#[must_use]
pub fn annotate_bits(p: &Profile, table: Table, start: u16, bits: &[bool], write: bool) -> Vec<Annotation> {
    let mut out = Vec::with_capacity(bits.len());
    for (i, &on) in bits.iter().enumerate() {
        let Some(address) = u16::try_from(i).ok().and_then(|i| start.checked_add(i)) else { break };
        let a = match p.slot(table, address) {
            Some((slot, def)) => {
                let mut notes = Vec::new();
                if write && def.access == Access::Read {
                    notes.push(Note::WriteToReadOnly);
                }
                let label = if on { def.on.clone() } else { def.off.clone() };
                Annotation {
                    table,
                    address,
                    width: 1,
                    name: Some(slot.name.clone()),
                    name_ru: def.name_ru.clone(),
                    raw: i64::from(on),
                    shown: Shown::Bool { on, label },
                    notes,
                }
            }
            None => Annotation {
                table,
                address,
                width: 1,
                name: None,
                name_ru: None,
                raw: i64::from(on),
                shown: Shown::Bool { on, label: None },
                notes: vec![if p.is_reserved(table, address) { Note::Reserved } else { Note::Undocumented }],
            },
        };
        out.push(a);
    }
    out
}
