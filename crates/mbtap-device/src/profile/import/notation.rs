//! The notations vendor register sheets use, each read into the profile's terms or refused with
//! a reason: addresses (`2000`, `0x2000`, `2000H`, Modicon `40001`/`400001`), tables, value
//! types, word orders, scales, units in names, access.

use crate::profile::Table;
use crate::profile::format::{Access, ValueType, WordOrder};

/// A cell's text normalised for matching: lower case, trimmed, inner runs of spaces, `_` and
/// `-` as one space.
#[must_use]
pub fn norm(s: &str) -> String {
    let lower = s.trim().to_lowercase();
    let mut out = String::with_capacity(lower.len());
    for c in lower.chars() {
        let c = if c == '_' || c == '-' || c.is_whitespace() { ' ' } else { c };
        if c == ' ' && (out.is_empty() || out.ends_with(' ')) {
            continue;
        }
        out.push(c);
    }
    out.trim_end().to_owned()
}

/// An address as written in a sheet: the number and whether it was written as a plain decimal
/// of five or six digits (a candidate for Modicon notation, decided per sheet).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawAddress {
    pub value: u32,
    /// Digits as written (for Modicon: `40001` has 5, `400001` 6).
    pub digits: usize,
    pub decimal: bool,
}

/// Reads `0x2000`, `2000H`/`2000h`, `$2000` (hexadecimal) or `2000` (decimal); a trailing `.0`
/// (spreadsheets store numbers as floats) is accepted.
///
/// # Errors
/// What is wrong with the text, for the problem list.
pub fn parse_address(s: &str) -> Result<RawAddress, String> {
    let t = s.trim();
    let t = t.strip_suffix(".0").unwrap_or(t);
    let hex = t
        .strip_prefix("0x")
        .or_else(|| t.strip_prefix("0X"))
        .or_else(|| t.strip_prefix('$'))
        .or_else(|| t.strip_suffix('H'))
        .or_else(|| t.strip_suffix('h'));
    let (digits, radix) = match hex {
        Some(h) => (h, 16),
        None => (t, 10),
    };
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return Err(format!("{t:?} is not an address (decimal, 0x…, …H or a Modicon number like 40001)"));
    }
    let value = u32::from_str_radix(digits, radix).map_err(|_| format!("{t:?} is too large for an address"))?;
    Ok(RawAddress { value, digits: digits.len(), decimal: radix == 10 })
}

/// A Modicon register number (`40001` → holding register 0; `300001` → input register 0;
/// the leading digit names the table, the rest counts from 1), if `a` reads as one.
#[must_use]
pub fn modicon(a: RawAddress) -> Option<(Table, u16)> {
    if !a.decimal || !(a.digits == 5 || a.digits == 6) {
        return None;
    }
    let base = if a.digits == 5 { 10_000 } else { 100_000 };
    let table = match a.value / base {
        0 => Table::Coils,
        1 => Table::DiscreteInputs,
        3 => Table::InputRegisters,
        4 => Table::HoldingRegisters,
        _ => return None,
    };
    let n = a.value % base;
    // 1-based: x0000 is not a Modicon number.
    let address = u16::try_from(n.checked_sub(1)?).ok()?;
    Some((table, address))
}

/// A table named in a sheet's table or function column.
///
/// # Errors
/// The text not understood.
pub fn parse_table(s: &str) -> Result<Table, String> {
    let n = norm(s);
    let n = n.trim_end_matches('s');
    Ok(match n {
        "holding" | "holding register" | "holding reg" | "hr" | "4x" | "4" | "03" | "3" | "fc3" | "fc03" | "0x03"
        | "r/w register" | "holding registers" => Table::HoldingRegisters,
        "input" | "input register" | "input reg" | "ir" | "3x" | "04" | "fc4" | "fc04" | "0x04" | "input registers" => {
            Table::InputRegisters
        }
        "coil" | "0x" | "01" | "1" | "fc1" | "fc01" | "0x01" | "output coil" => Table::Coils,
        "discrete input" | "discrete" | "di" | "1x" | "02" | "2" | "fc2" | "fc02" | "0x02" | "input status"
        | "digital input" => Table::DiscreteInputs,
        _ => {
            return Err(format!(
                "{:?} is not a table (holding, input, coil, discrete input, 3x, 4x, 03, 04…)",
                s.trim()
            ));
        }
    })
}

/// A value type and, for strings written like `string(10)` or `STRING[10]`, their length in
/// registers.
///
/// # Errors
/// The text not understood, or a type the profile format cannot hold (64-bit values).
pub fn parse_type(s: &str) -> Result<(ValueType, Option<u16>), String> {
    let n = norm(s).replace(' ', "");
    // `string(10)`, `string[10]`, `char[20]`: a length in registers (or characters: said below).
    let (base, len) = match n.find(['(', '[']) {
        Some(i) => {
            let inner = n[i + 1..].trim_end_matches([')', ']']);
            (&n[..i], inner.parse::<u16>().ok())
        }
        None => (n.as_str(), None),
    };
    let t = match base {
        "float" | "float32" | "real" | "ieee754" | "ieee" | "f32" | "fp32" | "single" | "float32ieee" => ValueType::F32,
        "int16" | "signed" | "short" | "sint16" | "i16" | "s16" | "int" | "signed16" | "integer" | "sword" => {
            ValueType::I16
        }
        // A sheet gives no labels for its bits or values: plain registers, labelled by hand.
        "uint16" | "unsigned" | "word" | "u16" | "ushort" | "uint" | "unsigned16" | "uword" | "bitfield" | "bits"
        | "bitmap" | "flags" | "enum" | "enumeration" => ValueType::U16,
        "int32" | "dint" | "long" | "i32" | "s32" | "sint32" | "signed32" | "sdword" => ValueType::I32,
        "uint32" | "dword" | "udint" | "u32" | "ulong" | "unsigned32" | "unsignedlong" => ValueType::U32,
        "string" | "ascii" | "char" | "str" | "text" => ValueType::String,
        "bit" | "bool" | "boolean" | "coil" | "binary" => ValueType::Bool,
        "int64" | "lint" | "i64" | "s64" | "sint64" | "signed64" => ValueType::I64,
        "uint64" | "ulint" | "u64" | "unsigned64" | "qword" | "uqword" => ValueType::U64,
        "float64" | "double" | "lreal" | "f64" => {
            return Err(format!("{:?}: 64-bit floats are not in the profile format", s.trim()));
        }
        _ => return Err(format!("{:?} is not a type (float32, int16, uint16, int32, uint32, string, bit…)", s.trim())),
    };
    Ok((t, len))
}

/// A word order for 32-bit values.
///
/// # Errors
/// The text not understood, or a byte-swapped order the profile format cannot hold.
pub fn parse_word_order(s: &str) -> Result<WordOrder, String> {
    let n = norm(s);
    Ok(match n.as_str() {
        "abcd" | "big endian" | "bigendian" | "be" | "msw first" | "high first" | "high word first" | "normal"
        | "no swap" | "none" | "1234" | "msb" | "hi lo" | "hilo" => WordOrder::HighFirst,
        "cdab" | "word swapped" | "word swap" | "swapped" | "lsw first" | "low first" | "low word first"
        | "little endian word" | "word" | "3412" | "lo hi" | "lohi" | "little endian" | "le" => WordOrder::LowFirst,
        "badc" | "dcba" | "byte swapped" | "byte swap" | "2143" | "4321" | "word byte" => {
            return Err(format!("{:?}: byte-swapped orders are not in the profile format", s.trim()));
        }
        _ => return Err(format!("{:?} is not a word order (ABCD, CDAB, big endian, word swapped…)", s.trim())),
    })
}

/// A scale as a multiplier: `0.1`, `*0.1`, `x0.1`, `/10`, `÷100`, `1/10`, `x10^-2`, `10^-2`,
/// `1e-2`, `10E-1`; `1` and empty are no scale.
///
/// # Errors
/// The text not understood, or a scale of zero.
pub fn parse_scale(s: &str) -> Result<Option<f64>, String> {
    let t: String = s.trim().chars().filter(|c| !c.is_whitespace()).collect();
    if t.is_empty() || t == "-" || t == "—" {
        return Ok(None);
    }
    let bad = || format!("{:?} is not a scale (0.1, /10, ÷100, x10^-2…)", s.trim());
    let number = |x: &str| -> Result<f64, String> {
        let x = x.replace(',', ".");
        if let Some((b, e)) = x.split_once('^') {
            let b: f64 = b.parse().map_err(|_| bad())?;
            let e: i32 = e.trim_matches(['(', ')']).parse().map_err(|_| bad())?;
            return Ok(b.powi(e));
        }
        x.parse::<f64>().map_err(|_| bad())
    };
    let v = if let Some(d) = t.strip_prefix('/').or_else(|| t.strip_prefix('÷')) {
        1.0 / number(d)?
    } else if let Some((a, b)) = t.split_once('/') {
        number(a)? / number(b)?
    } else {
        let m = t.strip_prefix(['x', 'X', '*', '×']).unwrap_or(&t);
        number(m)?
    };
    if !v.is_finite() || v == 0.0 {
        return Err(bad());
    }
    Ok(if (v - 1.0).abs() < f64::EPSILON { None } else { Some(v) })
}

/// Access as sheets write it.
///
/// # Errors
/// The text not understood.
pub fn parse_access(s: &str) -> Result<Access, String> {
    let n = norm(s);
    Ok(match n.as_str() {
        "r" | "ro" | "read" | "read only" | "readonly" | "read-only" | "只读" | "lesen" => Access::Read,
        "rw" | "r/w" | "read/write" | "read write" | "readwrite" | "w/r" | "wr" | "r w" | "读写"
        | "lesen/schreiben" | "l/s" => Access::ReadWrite,
        "w" | "wo" | "write" | "write only" | "writeonly" | "只写" | "schreiben" => Access::Write,
        _ => return Err(format!("{:?} is not an access (R, RW, R/W, read only, W)", s.trim())),
    })
}

/// A unit written in a name, `Voltage [V]` or `Power (kW)`: the name without it and the unit.
/// Only short bracketed text without spaces counts (`Pump (phase A)` keeps its name).
#[must_use]
pub fn unit_from_name(name: &str) -> (String, Option<String>) {
    let t = name.trim();
    for (open, close) in [('[', ']'), ('(', ')')] {
        if let Some(inner) = t.strip_suffix(close)
            && let Some(i) = inner.rfind(open)
        {
            let unit = inner[i + open.len_utf8()..].trim();
            if !unit.is_empty() && unit.chars().count() <= 6 && !unit.contains(' ') {
                return (inner[..i].trim().to_owned(), Some(unit.to_owned()));
            }
        }
    }
    (t.to_owned(), None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_in_every_notation() {
        assert_eq!(parse_address("0x2000").map(|a| a.value), Ok(0x2000));
        assert_eq!(parse_address("2000H").map(|a| a.value), Ok(0x2000));
        assert_eq!(parse_address("2000").map(|a| a.value), Ok(2000));
        assert_eq!(parse_address("30001.0").map(|a| a.value), Ok(30001));
        assert!(parse_address("abc").is_err());
        assert!(parse_address("").is_err());
        let m = |s: &str| modicon(parse_address(s).unwrap());
        assert_eq!(m("40001"), Some((Table::HoldingRegisters, 0)));
        assert_eq!(m("30010"), Some((Table::InputRegisters, 9)));
        assert_eq!(m("400001"), Some((Table::HoldingRegisters, 0)));
        assert_eq!(m("465536"), Some((Table::HoldingRegisters, 65535)));
        assert_eq!(m("10001"), Some((Table::DiscreteInputs, 0)));
        assert_eq!(m("00005"), Some((Table::Coils, 4)));
        assert_eq!(m("40000"), None, "1-based: x0000 is not Modicon");
        assert_eq!(m("0x4001"), None);
        assert_eq!(m("2000"), None);
    }

    #[test]
    fn types_word_orders_scales_and_access_in_their_many_spellings() {
        for t in ["float", "Float", "float32", "REAL", "IEEE754"] {
            assert_eq!(parse_type(t), Ok((ValueType::F32, None)), "{t}");
        }
        for t in ["int16", "signed", "INT"] {
            assert_eq!(parse_type(t).map(|t| t.0), Ok(ValueType::I16), "{t}");
        }
        for t in ["uint16", "unsigned", "WORD"] {
            assert_eq!(parse_type(t).map(|t| t.0), Ok(ValueType::U16), "{t}");
        }
        for t in ["int32", "DINT", "long"] {
            assert_eq!(parse_type(t).map(|t| t.0), Ok(ValueType::I32), "{t}");
        }
        assert_eq!(parse_type("DWORD").map(|t| t.0), Ok(ValueType::U32));
        assert_eq!(parse_type("STRING[10]"), Ok((ValueType::String, Some(10))));
        assert_eq!(parse_type("ASCII").map(|t| t.0), Ok(ValueType::String));
        assert_eq!(parse_type("bit").map(|t| t.0), Ok(ValueType::Bool));
        assert!(parse_type("float64").unwrap_err().contains("64-bit"));
        assert_eq!(parse_word_order("ABCD"), Ok(WordOrder::HighFirst));
        assert_eq!(parse_word_order("big endian"), Ok(WordOrder::HighFirst));
        assert_eq!(parse_word_order("CDAB"), Ok(WordOrder::LowFirst));
        assert_eq!(parse_word_order("Word Swapped"), Ok(WordOrder::LowFirst));
        assert_eq!(parse_word_order("LSW first"), Ok(WordOrder::LowFirst));
        assert!(parse_word_order("BADC").is_err());
        assert_eq!(parse_scale("0.1"), Ok(Some(0.1)));
        assert_eq!(parse_scale("/10"), Ok(Some(0.1)));
        assert_eq!(parse_scale("÷100"), Ok(Some(0.01)));
        assert_eq!(parse_scale("x10^-2"), Ok(Some(0.01)));
        assert_eq!(parse_scale("1/1000"), Ok(Some(0.001)));
        assert_eq!(parse_scale("1"), Ok(None));
        assert_eq!(parse_scale(""), Ok(None));
        assert_eq!(parse_scale("0,01"), Ok(Some(0.01)));
        assert!(parse_scale("0").is_err());
        assert!(parse_scale("ten").is_err());
        assert_eq!(parse_access("R"), Ok(Access::Read));
        assert_eq!(parse_access("R/W"), Ok(Access::ReadWrite));
        assert_eq!(parse_access("read only"), Ok(Access::Read));
        assert_eq!(parse_access("RW"), Ok(Access::ReadWrite));
        assert!(parse_access("maybe").is_err());
    }

    #[test]
    fn units_come_out_of_names_but_descriptions_stay() {
        assert_eq!(unit_from_name("Voltage [V]"), ("Voltage".into(), Some("V".into())));
        assert_eq!(unit_from_name("Active power (kW)"), ("Active power".into(), Some("kW".into())));
        assert_eq!(unit_from_name("Pump (phase A)"), ("Pump (phase A)".into(), None));
        assert_eq!(parse_table("Holding Register"), Ok(Table::HoldingRegisters));
        assert_eq!(parse_table("04"), Ok(Table::InputRegisters));
        assert_eq!(parse_table("Coils"), Ok(Table::Coils));
    }
}
