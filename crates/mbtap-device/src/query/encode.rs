//! A value to write, checked against the profile and encoded, before anything is sent.
//!
//! Refused with the reason (each forceable one only with `--force`): a read-only register, an
//! address the profile does not document, a value outside the documented range, a label the
//! enumeration does not list. Never forceable: a number the scale cannot represent (1.234 at
//! 0.01), a number the type cannot hold, text longer than the string, a table that cannot be
//! written (discrete inputs, input registers — MAP v1.1b3 §4.3: read-only tables).

use super::resolve::Target;
use super::{QueryError, is_bits};
use crate::profile::format::{Access, DatePart, ValueType, WordOrder};
use crate::profile::model::Def;
use crate::profile::{Profile, Table};
use mbtap_proto::{Bits, Registers, Request};

/// A checked write.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Write {
    pub table: Table,
    pub address: u16,
    /// Registers to write, in wire order; for a coil one word, 0 or 1.
    pub words: Vec<u16>,
    /// 0x05, 0x06 or 0x10 (MAP v1.1b3 §6.5, §6.6, §6.12).
    pub function: u8,
    /// Checks `--force` overrode, said to the user.
    pub overridden: Vec<String>,
}

impl Write {
    /// The request PDU (function code first).
    #[must_use]
    pub fn pdu(&self) -> Vec<u8> {
        let bytes: Vec<u8> = self.words.iter().flat_map(|w| w.to_be_bytes()).collect();
        let first = self.words.first().copied().unwrap_or(0);
        let request = match self.function {
            // §6.5: ON is 0xFF00, OFF 0x0000.
            0x05 => Request::WriteSingleCoil { address: self.address, value: if first == 0 { 0 } else { 0xFF00 } },
            0x06 => Request::WriteSingleRegister { address: self.address, value: first },
            0x0F => Request::WriteMultipleCoils {
                address: self.address,
                quantity: u16::try_from(self.words.len()).unwrap_or(0),
                values: Bits::new(&[]),
            },
            _ => Request::WriteMultipleRegisters {
                address: self.address,
                quantity: u16::try_from(self.words.len()).unwrap_or(0),
                values: Registers::new(&bytes),
            },
        };
        let mut out = Vec::new();
        // Encoding fails only on lengths the checks above already bound (≤ 123 registers).
        let _ = request.encode(&mut out);
        out
    }
}

struct Check<'a> {
    item: &'a str,
    force: bool,
    overridden: Vec<String>,
}

impl Check<'_> {
    fn hard(&self, problem: impl Into<String>) -> QueryError {
        QueryError::BadValue { item: self.item.to_owned(), problem: problem.into(), forceable: false }
    }

    /// A check `--force` may override: refused without it, remembered with it.
    fn soft(&mut self, problem: String) -> Result<(), QueryError> {
        if self.force {
            self.overridden.push(problem);
            Ok(())
        } else {
            Err(QueryError::BadValue { item: self.item.to_owned(), problem, forceable: true })
        }
    }
}

fn parse_int(s: &str) -> Option<i64> {
    let s = s.trim();
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => i64::from_str_radix(h, 16).ok(),
        None => s.parse().ok(),
    }
}

fn parse_bool(s: &str, def: Option<&Def>) -> Option<bool> {
    let s = s.trim();
    if let Some(d) = def {
        if d.on.as_deref().is_some_and(|on| on.eq_ignore_ascii_case(s)) {
            return Some(true);
        }
        if d.off.as_deref().is_some_and(|off| off.eq_ignore_ascii_case(s)) {
            return Some(false);
        }
    }
    match s.to_ascii_lowercase().as_str() {
        "1" | "on" | "true" => Some(true),
        "0" | "off" | "false" => Some(false),
        _ => None,
    }
}

/// A number at the register's scale: `1.50` at 0.01 is raw 150.
fn scaled(c: &Check<'_>, text: &str, def: &Def) -> Result<i64, QueryError> {
    let v: f64 = text.trim().parse().map_err(|_| c.hard(format!("{text:?} is not a number")))?;
    if !v.is_finite() {
        return Err(c.hard(format!("{text:?} is not a finite number")));
    }
    let scale = def.scale.unwrap_or(1.0);
    let raw = v / scale;
    let rounded = raw.round();
    if !rounded.is_finite() || (raw - rounded).abs() > 1e-6 * rounded.abs().max(1.0) {
        return Err(c.hard(format!(
            "{text} cannot be written at this register's scale {scale}: the nearest values are {} and {}",
            trim(raw.floor() * scale),
            trim(raw.ceil() * scale)
        )));
    }
    // Within i64 (checked above as finite; the type bounds are checked by the caller).
    #[allow(clippy::cast_possible_truncation)]
    Ok(rounded as i64)
}

fn trim(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The type's bounds on the raw value.
fn bounds(t: ValueType) -> (i64, i64) {
    match t {
        ValueType::I16 => (i64::from(i16::MIN), i64::from(i16::MAX)),
        ValueType::U32 => (0, i64::from(u32::MAX)),
        ValueType::I32 => (i64::from(i32::MIN), i64::from(i32::MAX)),
        // A raw value is an i64: a u64 register takes what an i64 holds (9.2 × 10¹⁸ is beyond
        // any meter's counter).
        ValueType::U64 => (0, i64::MAX),
        ValueType::I64 => (i64::MIN, i64::MAX),
        _ => (0, i64::from(u16::MAX)),
    }
}

/// The low 16 bits of a raw value in two's complement (-1 → 0xFFFF).
fn word(raw: i64) -> u16 {
    u16::try_from(raw.rem_euclid(1 << 16)).unwrap_or(0)
}

/// The low 32 bits of a raw value in two's complement.
fn bits32(raw: i64) -> u32 {
    u32::try_from(raw.rem_euclid(1 << 32)).unwrap_or(0)
}

/// Four registers, most significant first unless the profile says the low word comes first.
fn words64(raw: i64, order: WordOrder) -> Vec<u16> {
    let bits = raw.cast_unsigned();
    let mut words: Vec<u16> = (0..4).rev().map(|i| u16::try_from((bits >> (16 * i)) & 0xFFFF).unwrap_or(0)).collect();
    if order == WordOrder::LowFirst {
        words.reverse();
    }
    words
}

fn words32(bits: u32, order: WordOrder) -> Vec<u16> {
    let hi = u16::try_from(bits >> 16).unwrap_or(0);
    let lo = u16::try_from(bits & 0xFFFF).unwrap_or(0);
    match order {
        WordOrder::HighFirst => vec![hi, lo],
        WordOrder::LowFirst => vec![lo, hi],
    }
}

/// Raw value of a register holding a number, an enum, bits or a bool.
fn raw_of(c: &mut Check<'_>, text: &str, def: &Def) -> Result<i64, QueryError> {
    let label = |m: &std::collections::BTreeMap<i64, String>| {
        m.iter().find(|(_, l)| l.eq_ignore_ascii_case(text.trim())).map(|(&k, _)| k)
    };
    if let Some(k) = label(&def.labels).or_else(|| label(&def.commands)) {
        return Ok(k);
    }
    match def.value_type {
        ValueType::Enum => {
            let raw = parse_int(text).ok_or_else(|| {
                c.hard(format!(
                    "{text:?} is not one of {}",
                    def.labels.values().map(|l| format!("{l:?}")).collect::<Vec<_>>().join(", ")
                ))
            })?;
            if !def.labels.contains_key(&raw) && !def.commands.contains_key(&raw) {
                c.soft(format!("{raw} is not one of the documented values"))?;
            }
            Ok(raw)
        }
        ValueType::Bits => {
            parse_int(text).ok_or_else(|| c.hard(format!("{text:?} is not a number (bits: decimal or 0x hex)")))
        }
        ValueType::Bool => parse_bool(text, Some(def))
            .map(i64::from)
            .ok_or_else(|| c.hard(format!("{text:?} is not on/off, true/false or 1/0"))),
        _ => scaled(c, text, def),
    }
}

fn encode_def(c: &mut Check<'_>, text: &str, def: &Def, p: &Profile) -> Result<Vec<u16>, QueryError> {
    match def.value_type {
        ValueType::F32 => {
            let v: f64 = text.trim().parse().map_err(|_| c.hard(format!("{text:?} is not a number")))?;
            // The register's scale applies as when it is read (see `encode_number`).
            #[allow(clippy::cast_possible_truncation)]
            let v = (v / def.scale.unwrap_or(1.0)) as f32;
            if !v.is_finite() {
                return Err(c.hard(format!(
                    "{text:?} does not fit the register's 32-bit float (a finite number within ±{:e})",
                    f32::MAX
                )));
            }
            Ok(words32(v.to_bits(), def.word_order))
        }
        ValueType::String => {
            let per = usize::from(def.chars_per_register.max(1));
            let room = usize::from(def.width) * per;
            if !text.is_ascii() || text.len() > room {
                return Err(c.hard(format!("the text must be ASCII, at most {room} characters")));
            }
            if let Some(bad) = text.bytes().find(u8::is_ascii_control) {
                return Err(c.hard(format!(
                    "the text holds the control character 0x{bad:02X}: only printable ASCII is written"
                )));
            }
            let mut bytes: Vec<u8> = text.bytes().collect();
            bytes.resize(room, 0);
            Ok(bytes
                .chunks(per)
                .map(|ch| if per == 1 { u16::from(ch[0]) } else { u16::from_be_bytes([ch[0], ch[1]]) })
                .collect())
        }
        ValueType::Datetime => {
            let numbers: Vec<u16> = text
                .split(|ch: char| !ch.is_ascii_digit())
                .filter(|s| !s.is_empty())
                .filter_map(|s| s.parse().ok())
                .collect();
            // Typed in calendar order (year first), stored in the register order the profile gives.
            let mut natural = def.parts.clone();
            natural.sort_by_key(|p| match p {
                DatePart::Year => 0,
                DatePart::Month => 1,
                DatePart::Day => 2,
                DatePart::Hour => 3,
                DatePart::Minute => 4,
                DatePart::Second => 5,
            });
            if numbers.len() != natural.len() {
                return Err(c.hard(format!(
                    "a date here has {} parts ({}), {} given",
                    natural.len(),
                    natural.iter().map(|p| format!("{p:?}").to_lowercase()).collect::<Vec<_>>().join(" "),
                    numbers.len()
                )));
            }
            Ok(def.parts.iter().map(|part| natural.iter().position(|q| q == part).map_or(0, |i| numbers[i])).collect())
        }
        t => {
            let raw = raw_of(c, text, def)?;
            let (lo, hi) = bounds(t);
            if !(lo..=hi).contains(&raw) {
                return Err(c.hard(format!("raw value {raw} does not fit the register's type ({lo}..={hi})")));
            }
            // A command register (its documented values are commands) takes those values, and
            // numbers in its documented range if it has one — like an enumeration's labels
            // (no other number reaches the line).
            if !def.commands.is_empty()
                && !def.commands.contains_key(&raw)
                && !def.labels.contains_key(&raw)
                && def.range.is_none_or(|(min, max)| !(min..=max).contains(&raw))
            {
                c.soft(format!(
                    "{raw} is not one of the documented commands ({})",
                    def.commands.iter().map(|(k, v)| format!("{k} = {v:?}")).collect::<Vec<_>>().join(", ")
                ))?;
            }
            if let Some((min, max)) = def.range
                && !(min..=max).contains(&raw)
                && !def.commands.contains_key(&raw)
            {
                let clamp = if p.meta.clamps_writes { "; the device would clamp it" } else { "" };
                c.soft(format!("raw {raw} is outside the documented range {min}..={max}{clamp}"))?;
            }
            Ok(match t {
                // Two's complement in one or two registers (MAP v1.1b3 §4.2 leaves signedness
                // to the device; the profile's type says it).
                ValueType::U32 | ValueType::I32 => words32(bits32(raw), def.word_order),
                ValueType::U64 | ValueType::I64 => words64(raw, def.word_order),
                _ => vec![word(raw)],
            })
        }
    }
}

/// A number as the registers of `def` hold it, rounded to the register's scale (a value computed
/// by mbtap — a mirrored device's — or set by a client of the emulator: `--values-from`, MQTT).
///
/// # Errors
/// What the register cannot hold, with its range in the value's units: not finite, outside the
/// type's bounds at the register's scale (never clamped), beyond a 32-bit float, or a text or
/// date register.
pub fn encode_number(value: f64, def: &Def) -> Result<Vec<u16>, String> {
    if !value.is_finite() {
        return Err(format!("{value} is not a finite number"));
    }
    match def.value_type {
        ValueType::F32 => {
            // A float register's scale applies as it does when the value is read (the annotator
            // multiplies the float by it): Chint's DTSU666 holds 230.0 V as 2300.0 at scale 0.1.
            // Rounded to the nearest f32 (IEEE 754 binary32), as any device holding one would;
            // beyond its range it would be infinity, which is no measurement.
            #[allow(clippy::cast_possible_truncation)]
            let v = (value / def.scale.unwrap_or(1.0)) as f32;
            if v.is_finite() {
                Ok(words32(v.to_bits(), def.word_order))
            } else {
                Err(format!("{value} does not fit the register's 32-bit float (within ±{:e})", f32::MAX))
            }
        }
        ValueType::String | ValueType::Datetime => Err("a text or date register takes no number".to_owned()),
        t => {
            let (lo, hi) = bounds(t);
            let scale = def.scale.unwrap_or(1.0);
            let raw = (value / scale).round();
            #[allow(clippy::cast_precision_loss)]
            if !raw.is_finite() || raw < lo as f64 || raw > hi as f64 {
                #[allow(clippy::cast_precision_loss)]
                let (a, b) = (trim(lo as f64 * scale), trim(hi as f64 * scale));
                let (a, b) = if a <= b { (a, b) } else { (b, a) };
                return Err(format!("{value} is outside what the register holds ({a} to {b})"));
            }
            // Within i64: checked against the type's bounds just above.
            #[allow(clippy::cast_possible_truncation)]
            let raw = raw as i64;
            Ok(match t {
                ValueType::U32 | ValueType::I32 => words32(bits32(raw), def.word_order),
                ValueType::U64 | ValueType::I64 => words64(raw, def.word_order),
                _ => vec![word(raw)],
            })
        }
    }
}

/// Checks and encodes the write `target` asks for. See the module documentation.
pub fn encode_write(target: &Target, p: Option<&Profile>, force: bool) -> Result<Write, QueryError> {
    let item = target.item.text.as_str();
    let mut c = Check { item, force, overridden: Vec::new() };
    let Some(text) = target.item.value.as_deref() else {
        return Err(c.hard("nothing to write: give NAME=VALUE or ADDRESS=VALUE"));
    };
    if matches!(target.table, Table::DiscreteInputs | Table::InputRegisters) {
        return Err(QueryError::NotWritable { item: item.to_owned(), table: target.table.name() });
    }
    let slot = p.and_then(|p| p.slot(target.table, target.first).map(|(s, d)| (p, s, d)));
    if let Some((_, _, def)) = slot
        && def.access == Access::Read
    {
        c.soft("the profile documents this register as read-only".to_owned())?;
    }
    if let Some(p) = p
        && slot.is_none()
    {
        c.soft(format!("address {} is not in the {} profile", target.first, p.meta.name))?;
    }
    let words: Vec<u16> = if is_bits(target.table) {
        let on = parse_bool(text, slot.map(|(_, _, d)| d)).ok_or_else(|| c.hard(format!("{text:?} is not on/off")))?;
        vec![u16::from(on)]
    } else if let Some((p, _, def)) = slot {
        encode_def(&mut c, text, def, p)?
    } else {
        // Without a profile: raw 16-bit values, comma-separated for a range.
        text.split(',')
            .map(|v| {
                parse_int(v)
                    .filter(|r| (i64::from(i16::MIN)..=i64::from(u16::MAX)).contains(r))
                    .map(word)
                    .ok_or_else(|| c.hard(format!("{v:?} is not a 16-bit number (-32768..=65535)")))
            })
            .collect::<Result<_, _>>()?
    };
    if u32::try_from(words.len()).ok() != Some(target.count())
        && !(slot.is_some() && target.count() as usize >= words.len())
    {
        return Err(c.hard(format!("{} values for {} registers", words.len(), target.count())));
    }
    // MAP v1.1b3 §6.12: at most 123 registers in one write.
    if words.len() > 123 {
        return Err(c.hard("more than 123 registers in one write"));
    }
    let functions = p.map(|p| p.meta.functions.as_slice()).unwrap_or_default();
    let can = |f: u8| functions.is_empty() || functions.contains(&f);
    let function = if is_bits(target.table) {
        0x05
    } else if words.len() == 1 && (can(0x06) || !can(0x10)) {
        0x06
    } else {
        0x10
    };
    if !can(function) {
        c.soft(format!("the device's document lists no function {function:02X}"))?;
    }
    Ok(Write { table: target.table, address: target.first, words, function, overridden: c.overridden })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::super::items::parse_item;
    use super::super::resolve::resolve;
    use super::*;

    fn write(text: &str, force: bool) -> Result<Write, QueryError> {
        let mk4 = crate::profile::builtin::get("mk4").unwrap().unwrap();
        encode_write(&resolve(&parse_item(text, None).unwrap(), Some(&mk4)).unwrap(), Some(&mk4), force)
    }

    #[test]
    fn a_set_point_at_its_scale() {
        let w = write("Level 2 set point=1.50", false).unwrap();
        assert_eq!(
            (w.table, w.address, w.words.as_slice(), w.function),
            (Table::HoldingRegisters, 105, &[150u16][..], 0x06)
        );
        // Function 06, address 105 (0x0069), value 150 (0x0096).
        assert_eq!(w.pdu(), [0x06, 0x00, 0x69, 0x00, 0x96]);
    }

    /// A command register takes its documented commands only, as an enumeration takes its
    /// list.
    #[test]
    fn a_command_register_takes_its_documented_commands_only() {
        // MK4 holding 126 "Clear alarm log": 30 = clear the alarm log.
        let w = write("Clear alarm log=30", false).unwrap();
        assert_eq!(w.pdu(), [0x06, 0x00, 0x7E, 0x00, 0x1E]);
        assert_eq!(write("Clear alarm log=clear the alarm log", false).unwrap().words, [30]);
        let e = write("Clear alarm log=31", false).unwrap_err().to_string();
        assert!(e.contains("not one of the documented commands") && e.contains("30") && e.contains("--force"), "{e}");
        assert_eq!(write("Clear alarm log=31", true).unwrap().words, [31], "--force still sends it");
    }

    #[test]
    fn refused_before_sending_with_the_reason() {
        let e = write("Level 2 set point=150", false).unwrap_err().to_string();
        assert!(e.contains("outside the documented range 0..=10000") && e.contains("--force"), "{e}");
        assert!(write("Level 2 set point=150", true).unwrap().overridden.len() == 1);
        let e = write("Level 2 set point=1.234", true).unwrap_err().to_string();
        assert!(e.contains("nearest values are 1.23 and 1.24"), "{e}");
        let e = write("Phase A (L1) voltage=230", false).unwrap_err().to_string();
        assert!(e.contains("cannot be written"), "{e}");
        let e = write("Operating mode=sideways", false).unwrap_err().to_string();
        assert!(e.contains("\"fill by level sensors\""), "{e}");
    }

    /// A number register of `value_type` at `scale`, as a profile would give it.
    fn number_def(value_type: ValueType, scale: Option<f64>) -> Def {
        let text = format!(
            "[profile]\nname = \"t\"\ndevice = \"t\"\n\n[[holding_registers]]\naddress = 0\nname = \"X\"\ntype = \"{}\"\n{}",
            match value_type {
                ValueType::F32 => "f32",
                ValueType::I16 => "i16",
                ValueType::U32 => "u32",
                ValueType::U64 => "u64",
                _ => "u16",
            },
            scale.map(|s| format!("scale = {s}\n")).unwrap_or_default()
        );
        let p = crate::profile::loader::load("t.toml", &text).unwrap();
        p.slot(Table::HoldingRegisters, 0).unwrap().1.clone()
    }

    #[test]
    fn a_value_the_register_cannot_hold_is_refused_with_its_range_never_clamped() {
        let e = encode_number(229e9, &number_def(ValueType::U16, None)).unwrap_err();
        assert!(e.contains("0 to 65535"), "{e}");
        let e = encode_number(-1.0, &number_def(ValueType::U16, None)).unwrap_err();
        assert!(e.contains("0 to 65535"), "{e}");
        let e = encode_number(229.0, &number_def(ValueType::U16, Some(0.001))).unwrap_err();
        assert!(e.contains("0 to 65.535"), "{e}");
        let e = encode_number(-40_000.0, &number_def(ValueType::I16, None)).unwrap_err();
        assert!(e.contains("-32768 to 32767"), "{e}");
        assert!(encode_number(5e9, &number_def(ValueType::U32, None)).is_err());
        let e = encode_number(1e39, &number_def(ValueType::F32, None)).unwrap_err();
        assert!(e.contains("32-bit float"), "{e}");
        assert!(encode_number(f64::INFINITY, &number_def(ValueType::F32, None)).is_err());
        assert!(encode_number(f64::NAN, &number_def(ValueType::U16, None)).is_err());
        // A 64-bit counter in four registers, high word first; the low word first reversed.
        assert_eq!(encode_number(123_456.78, &number_def(ValueType::U64, Some(0.01))), Ok(vec![0, 0, 0x00BC, 0x614E]));
        // A float register's scale applies as it does when read: 230 V at scale 0.1 is 2300.0.
        assert_eq!(encode_number(230.0, &number_def(ValueType::F32, Some(0.1))), Ok(vec![0x450F, 0xC000]));
        // In range: held exactly.
        assert_eq!(encode_number(229.5, &number_def(ValueType::U16, Some(0.1))), Ok(vec![2295]));
        assert_eq!(encode_number(-81.0, &number_def(ValueType::I16, None)), Ok(vec![0xFFAF]));
    }

    #[test]
    fn a_typed_value_that_is_not_finite_or_holds_a_control_character_is_refused() {
        let e = write("Level 2 set point=NaN", true).unwrap_err().to_string();
        assert!(e.contains("not a finite number") && !e.contains("nearest"), "{e}");
        let e = write("Device name in SMS=\u{1b}[2J", true).unwrap_err().to_string();
        assert!(e.contains("control character 0x1B"), "{e}");
    }

    #[test]
    fn labels_and_coils() {
        assert_eq!(write("Operating mode=fill by level sensors", false).unwrap().words, [1]);
        let w = write("Motor M1=on", false).unwrap();
        assert_eq!((w.function, w.pdu()), (0x05, vec![0x05, 0x00, 0x00, 0xFF, 0x00]));
    }

    #[test]
    fn text_and_dates_are_written_whole() {
        // MK4 256–267: one character per register, padded with 0.
        let w = write("Device name in SMS=PUMP-7", false).unwrap();
        assert_eq!((w.address, w.function, w.words.len()), (256, 0x10, 12));
        assert_eq!(&w.words[..7], &[u16::from(b'P'), 85, 77, 80, 45, 55, 0]);
        let e = write("Device name in SMS=a name much too long", false).unwrap_err().to_string();
        assert!(e.contains("at most 12 characters"), "{e}");
        // A date typed in calendar order lands in the profile's register order.
        let mkzp = crate::profile::builtin::get("mkzp").unwrap().unwrap();
        let slot_address = mkzp
            .tables
            .values()
            .flat_map(|m| m.iter())
            .find(|(_, s)| mkzp.defs[s.def].value_type == ValueType::Datetime && s.part == 0)
            .map(|(a, _)| *a)
            .expect("the MKZP's trip records have a date");
        let t = resolve(&parse_item(&format!("holding {slot_address}=11-22 14:35:07"), None).unwrap(), Some(&mkzp))
            .unwrap();
        let w = encode_write(&t, Some(&mkzp), true).unwrap();
        // Parts month, day, hour, minute, second (MKZP document), typed month-day hour:minute:second.
        assert_eq!(w.words, [11, 22, 14, 35, 7]);
    }

    #[test]
    fn without_a_profile_raw_values() {
        let t = resolve(&parse_item("holding 10..12=1,-1,0x10", None).unwrap(), None).unwrap();
        let w = encode_write(&t, None, false).unwrap();
        assert_eq!((w.words.as_slice(), w.function), (&[1, 0xFFFF, 16][..], 0x10));
    }
}
