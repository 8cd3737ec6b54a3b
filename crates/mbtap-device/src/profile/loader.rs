//! Loading a profile: TOML parsed with spans, then checked — every mistake reported as
//! `file:line:column: what is wrong, what was expected`.

use std::collections::BTreeMap;
use std::ops::Range;

use thiserror::Error;
use toml::Spanned;

use super::format::{BlockDef, PointDef, ProfileFile, RegisterDef, Table, ValueType};
use super::model::{Def, Profile, Slot};

/// A profile that cannot be used, with where and why.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{file}:{line}:{column}: {message}")]
pub struct ProfileError {
    pub file: String,
    pub line: usize,
    pub column: usize,
    pub message: String,
}

/// 1-based line and column of byte offset `at` in `src`.
fn line_col(src: &str, at: usize) -> (usize, usize) {
    let before = &src[..at.min(src.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

struct Ctx<'a> {
    file: &'a str,
    src: &'a str,
}

impl Ctx<'_> {
    fn err(&self, span: Range<usize>, message: impl Into<String>) -> ProfileError {
        let (line, column) = line_col(self.src, span.start);
        ProfileError { file: self.file.to_owned(), line, column, message: message.into() }
    }
}

/// Parses and checks a profile. `file` names it in errors.
///
/// # Errors
/// [`ProfileError`] with the position of the first problem.
pub fn load(file: &str, src: &str) -> Result<Profile, ProfileError> {
    let cx = Ctx { file, src };
    let parsed: ProfileFile = toml::from_str(src).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        cx.err(span, e.message().trim().to_owned())
    })?;
    if let Some(line) = &parsed.line {
        check_line(&cx, line)?;
    }
    let mut p = Profile {
        meta: parsed.profile,
        line: parsed.line,
        defs: Vec::new(),
        tables: BTreeMap::new(),
        reserved: Vec::new(),
        vendor_lengths: Vec::new(),
    };
    // Where each address was defined, to name both places when two definitions collide.
    let mut origin: BTreeMap<(Table, u16), usize> = BTreeMap::new();
    for (table, points) in [(Table::Coils, &parsed.coils), (Table::DiscreteInputs, &parsed.discrete_inputs)] {
        for sp in points {
            add_point(&cx, &mut p, &mut origin, table, sp)?;
        }
    }
    for (table, regs) in
        [(Table::HoldingRegisters, &parsed.holding_registers), (Table::InputRegisters, &parsed.input_registers)]
    {
        for sp in regs {
            let span = sp.span();
            let r = sp.get_ref();
            if r.offset.is_some() {
                return Err(cx.err(span, "`offset` belongs to block fields; give `address` or `addresses`"));
            }
            let (first, last) = address_range(&cx, span.clone(), r.address, r.addresses)?;
            for (i, a) in (first..=last).enumerate() {
                let name = r.name.replace("{n}", &(i + 1).to_string());
                add_register(&cx, &mut p, &mut origin, table, a, &name, r, &span)?;
            }
        }
    }
    for sb in &parsed.blocks {
        add_block(&cx, &mut p, &mut origin, sb)?;
    }
    for sr in &parsed.reserved {
        let r = sr.get_ref();
        let [a, b] = r.addresses;
        if a > b {
            return Err(cx.err(sr.span(), format!("reserved range {a}..{b} runs backwards; write [low, high]")));
        }
        if let Some(((_, at), &pos)) = origin.range((r.table, a)..=(r.table, b)).next() {
            let (line, _) = line_col(src, pos);
            return Err(
                cx.err(sr.span(), format!("{} {at} is reserved here but defined at line {line}", r.table.name()))
            );
        }
        p.reserved.push((r.table, a, b));
    }
    for sv in &parsed.vendor_functions {
        let v = sv.get_ref();
        let fixed = {
            let fc = mbtap_proto::function::FunctionCode::from(v.code);
            fc.name().is_some() && !matches!(v.code, 0x08 | 0x11 | 0x2B)
        };
        if fixed || v.code == 0 || v.code & mbtap_proto::function::EXCEPTION_FLAG != 0 {
            return Err(cx.err(
                sv.span(),
                format!("code {:#04x}: vendor_functions are codes whose structure gives no length (vendor or user-defined codes, 08, 11, 2B)", v.code),
            ));
        }
        for (what, len) in [("request_length", v.request_length), ("response_length", v.response_length)] {
            if let Some(n) = len
                && !(4..=256).contains(&n)
            {
                return Err(cx.err(
                    sv.span(),
                    format!("{what} = {n}: an RTU frame is 4 to 256 bytes (address and CRC included)"),
                ));
            }
        }
        if v.request_length.is_none() && v.response_length.is_none() {
            return Err(
                cx.err(sv.span(), format!("code {:#04x}: give request_length, response_length or both", v.code))
            );
        }
        p.vendor_lengths.push((v.code, v.request_length, v.response_length));
    }
    Ok(p)
}

fn address_range(
    cx: &Ctx<'_>,
    span: Range<usize>,
    one: Option<u16>,
    range: Option<[u16; 2]>,
) -> Result<(u16, u16), ProfileError> {
    match (one, range) {
        (Some(a), None) => Ok((a, a)),
        (None, Some([a, b])) if a <= b => Ok((a, b)),
        (None, Some([a, b])) => Err(cx.err(span, format!("addresses [{a}, {b}] run backwards; write [first, last]"))),
        (Some(_), Some(_)) => Err(cx.err(span, "give either `address` or `addresses`, not both")),
        (None, None) => Err(cx.err(span, "missing `address` (or `addresses = [first, last]`)")),
    }
}

fn claim(
    cx: &Ctx<'_>,
    origin: &mut BTreeMap<(Table, u16), usize>,
    table: Table,
    address: u16,
    span: &Range<usize>,
) -> Result<(), ProfileError> {
    if let Some(&prev) = origin.get(&(table, address)) {
        let (line, _) = line_col(cx.src, prev);
        return Err(cx.err(span.clone(), format!("{} {address} is already defined at line {line}", table.name())));
    }
    origin.insert((table, address), span.start);
    Ok(())
}

fn add_point(
    cx: &Ctx<'_>,
    p: &mut Profile,
    origin: &mut BTreeMap<(Table, u16), usize>,
    table: Table,
    sp: &Spanned<PointDef>,
) -> Result<(), ProfileError> {
    let span = sp.span();
    let d = sp.get_ref();
    let (first, last) = address_range(cx, span.clone(), d.address, d.addresses)?;
    let def = Def {
        name: d.name.clone(),
        name_ru: d.name_ru.clone(),
        description: d.description.clone(),
        access: d.access,
        value_type: ValueType::Bool,
        word_order: super::format::WordOrder::HighFirst,
        scale: None,
        unit: None,
        range: None,
        labels: BTreeMap::new(),
        bits: BTreeMap::new(),
        width: 1,
        chars_per_register: 2,
        parts: Vec::new(),
        commands: BTreeMap::new(),
        on: d.on.clone(),
        off: d.off.clone(),
    };
    p.defs.push(def);
    let idx = p.defs.len() - 1;
    for (i, a) in (first..=last).enumerate() {
        claim(cx, origin, table, a, &span)?;
        let name = d.name.replace("{n}", &(i + 1).to_string());
        p.tables.entry(table).or_default().insert(a, Slot { def: idx, part: 0, first: a, name });
    }
    Ok(())
}

fn int_keys<T: TryFrom<i64> + Ord>(
    cx: &Ctx<'_>,
    span: &Range<usize>,
    what: &str,
    map: &BTreeMap<String, String>,
) -> Result<BTreeMap<T, String>, ProfileError> {
    let mut out = BTreeMap::new();
    for (k, v) in map {
        let n: i64 = k.trim().parse().map_err(|_| cx.err(span.clone(), format!("{what} key {k:?} is not a number")))?;
        let key = T::try_from(n).map_err(|_| cx.err(span.clone(), format!("{what} key {n} is out of range")))?;
        out.insert(key, v.clone());
    }
    Ok(out)
}

/// The byte range of `key`'s value inside the `[line]` table, to point at it (the table is not
/// spanned by the parser; the key is found in its lines).
fn line_key_span(src: &str, key: &str) -> Range<usize> {
    let Some(table) = src.find("[line]") else { return 0..0 };
    let mut at = table;
    for l in src[table..].split_inclusive('\n').skip(1) {
        at += l.len();
        let t = l.trim_start();
        if t.starts_with('[') {
            break;
        }
        if let Some(rest) = t.strip_prefix(key)
            && rest.trim_start().starts_with('=')
        {
            let line_start = at - l.len();
            let value = l.find('=').map_or(0, |i| i + 1);
            let skip = l[value..].len() - l[value..].trim_start().len();
            let v = line_start + value + skip;
            return v..line_start + l.trim_end().len();
        }
    }
    table..table + "[line]".len()
}

/// `[line]` values a serial line can have: a baud rate above 0, a character frame like `8E1`,
/// the mode `rtu` or `ascii` (Modbus over Serial Line v1.02 §2.5).
fn check_line(cx: &Ctx<'_>, line: &crate::profile::format::LineDefaults) -> Result<(), ProfileError> {
    if line.baud == Some(0) {
        return Err(
            cx.err(line_key_span(cx.src, "baud"), "baud = 0: a line's baud rate is above 0, e.g. 9600 or 19200")
        );
    }
    if let Some(f) = &line.framing
        && format!("9600 {f}").parse::<mbtap_proto::serial_line::LineSettings>().is_err()
    {
        return Err(cx.err(
            line_key_span(cx.src, "framing"),
            format!("framing = {f:?}: expected data bits, parity and stop bits like \"8E1\", \"8N2\" or \"7E1\""),
        ));
    }
    if let Some(m) = &line.mode
        && !matches!(m.to_ascii_lowercase().as_str(), "rtu" | "ascii")
    {
        return Err(cx.err(
            line_key_span(cx.src, "mode"),
            format!("mode = {m:?}: a serial line's mode is \"rtu\" or \"ascii\""),
        ));
    }
    Ok(())
}

fn compile(cx: &Ctx<'_>, span: &Range<usize>, r: &RegisterDef) -> Result<Def, ProfileError> {
    if let Some(s) = r.scale
        && (!s.is_finite() || s == 0.0)
    {
        return Err(cx.err(span.clone(), format!("scale = {s}: a scale is a finite number other than 0, e.g. 0.1")));
    }
    let labels = int_keys::<i64>(cx, span, "enum", &r.labels)?;
    let bits = int_keys::<u8>(cx, span, "bits", &r.bits)?;
    if bits.keys().any(|&b| b > 15) {
        return Err(cx.err(span.clone(), "bit numbers go from 0 to 15"));
    }
    match r.value_type {
        ValueType::Enum if labels.is_empty() => {
            return Err(cx.err(span.clone(), "type \"enum\" needs `enum = { 0 = \"label\", ... }`"));
        }
        ValueType::Bits if bits.is_empty() => {
            return Err(cx.err(span.clone(), "type \"bits\" needs `bits = { 0 = \"label\", ... }`"));
        }
        ValueType::String if r.length.is_none() => {
            return Err(cx.err(span.clone(), "type \"string\" needs `length` (registers it spans)"));
        }
        ValueType::Datetime if r.parts.is_empty() => {
            return Err(
                cx.err(span.clone(), "type \"datetime\" needs `parts = [\"day\", \"month\", ...]` in register order")
            );
        }
        _ => {}
    }
    let width = match r.value_type {
        ValueType::U32 | ValueType::I32 | ValueType::F32 => 2,
        ValueType::U64 | ValueType::I64 => 4,
        ValueType::String => r.length.unwrap_or(1).max(1),
        ValueType::Datetime => u16::try_from(r.parts.len()).unwrap_or(1).max(1),
        _ => 1,
    };
    let chars_per_register = r.chars_per_register.unwrap_or(2);
    if !(1..=2).contains(&chars_per_register) {
        return Err(cx.err(span.clone(), "chars_per_register is 1 or 2"));
    }
    if let Some([a, b]) = r.range
        && a > b
    {
        return Err(cx.err(span.clone(), format!("range [{a}, {b}] runs backwards; write [min, max]")));
    }
    Ok(Def {
        name: r.name.clone(),
        name_ru: r.name_ru.clone(),
        description: r.description.clone(),
        access: r.access,
        value_type: r.value_type,
        word_order: r.word_order,
        scale: r.scale,
        unit: r.unit.clone(),
        range: r.range.map(|[a, b]| (a, b)),
        labels,
        bits,
        width,
        chars_per_register,
        parts: r.parts.clone(),
        commands: int_keys::<i64>(cx, span, "commands", &r.commands)?,
        on: None,
        off: None,
    })
}

#[allow(clippy::too_many_arguments)]
fn add_register(
    cx: &Ctx<'_>,
    p: &mut Profile,
    origin: &mut BTreeMap<(Table, u16), usize>,
    table: Table,
    first: u16,
    name: &str,
    r: &RegisterDef,
    span: &Range<usize>,
) -> Result<(), ProfileError> {
    let def = compile(cx, span, r)?;
    let width = def.width;
    p.defs.push(def);
    let idx = p.defs.len() - 1;
    for part in 0..width {
        let a = first.checked_add(part).ok_or_else(|| cx.err(span.clone(), "the value runs past address 65535"))?;
        claim(cx, origin, table, a, span)?;
        p.tables.entry(table).or_default().insert(a, Slot { def: idx, part, first, name: name.to_owned() });
    }
    Ok(())
}

fn add_block(
    cx: &Ctx<'_>,
    p: &mut Profile,
    origin: &mut BTreeMap<(Table, u16), usize>,
    sb: &Spanned<BlockDef>,
) -> Result<(), ProfileError> {
    let span = sb.span();
    let b = sb.get_ref();
    if matches!(b.table, Table::Coils | Table::DiscreteInputs) {
        return Err(cx.err(span, "blocks are for holding_registers or input_registers"));
    }
    for n in 0..b.count {
        let base = n
            .checked_mul(b.stride)
            .and_then(|o| b.start.checked_add(o))
            .ok_or_else(|| cx.err(span.clone(), "the block runs past address 65535"))?;
        let title = b.title.replace("{n}", &(n + 1).to_string());
        for f in &b.fields {
            let Some(off) = f.offset else {
                return Err(cx.err(span.clone(), format!("block field {:?} needs `offset`", f.name)));
            };
            if off >= b.stride {
                return Err(cx.err(
                    span.clone(),
                    format!("block field {:?} offset {off} is not below the stride {}", f.name, b.stride),
                ));
            }
            let a = base.checked_add(off).ok_or_else(|| cx.err(span.clone(), "the block runs past address 65535"))?;
            add_register(cx, p, origin, b.table, a, &format!("{title}: {}", f.name), f, &span)?;
        }
    }
    Ok(())
}
