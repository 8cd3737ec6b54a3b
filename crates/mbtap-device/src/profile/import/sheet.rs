//! Vendor register sheets: rows of cells (from CSV or XLSX, read at the edge) with a header row
//! somewhere near the top — below title rows, above blank and section rows — whose columns are
//! found by their names (English, German, Chinese), or given with `--columns`.

pub use super::fields::Field;
use super::fields::field_of;
use std::ops::ControlFlow;

use super::grid::{Grid, Row};
use super::notation::{
    modicon, norm, parse_access, parse_address, parse_scale, parse_table, parse_type, parse_word_order, unit_from_name,
};
use super::{Imported, Point, Problem, Sink};
use crate::profile::Table;
use crate::profile::format::{Access, ValueType, WordOrder};

/// How to read a sheet beyond what its header says.
#[derive(Debug, Clone, Default)]
pub struct SheetOptions {
    /// Columns given by the user: field → a letter (`B`), a 1-based number or a header text.
    pub columns: Vec<(Field, String)>,
    /// The table where the sheet does not say (no table column, no Modicon numbers).
    pub table: Option<Table>,
    /// The word order of 32-bit values where the sheet does not say.
    pub word_order: Option<WordOrder>,
    /// The type of registers where the sheet does not say (`--type f32`: the vendor's prose
    /// says "all registers are floats"), with a string's length.
    pub value_type: Option<(ValueType, Option<u16>)>,
}

/// Parses `address=B,name=A,type=D` (`--columns`).
///
/// # Errors
/// An unknown field or a pair without `=`, named.
pub fn parse_columns(s: &str) -> Result<Vec<(Field, String)>, String> {
    s.split(',')
        .filter(|p| !p.trim().is_empty())
        .map(|p| {
            let (k, v) = p.split_once('=').ok_or_else(|| format!("{p:?}: expected FIELD=COLUMN"))?;
            let f = Field::parse_key(k).ok_or_else(|| {
                let keys: Vec<&str> = Field::ALL.iter().map(|f| f.key()).collect();
                format!("{k:?} is not a column field (one of {})", keys.join(", "))
            })?;
            Ok((f, v.trim().to_owned()))
        })
        .collect()
}

/// The spreadsheet letter of 0-based column `i` (`A`, …, `Z`, `AA`).
#[must_use]
pub fn letter(i: usize) -> String {
    let mut n = i + 1;
    let mut out = Vec::new();
    while n > 0 {
        let r = u8::try_from((n - 1) % 26).unwrap_or(0);
        out.push(char::from(b'A' + r));
        n = (n - 1) / 26;
    }
    out.iter().rev().collect()
}

/// Column `spec` (a letter, a 1-based number, or a header text found in `header`).
fn column_of(spec: &str, header: Option<Row<'_>>) -> Option<usize> {
    let t = spec.trim();
    if let Ok(n) = t.parse::<usize>() {
        return n.checked_sub(1);
    }
    if !t.is_empty() && t.len() <= 3 && t.chars().all(|c| c.is_ascii_alphabetic()) {
        return Some(t.to_ascii_uppercase().bytes().fold(0usize, |acc, b| acc * 26 + usize::from(b - b'A' + 1)) - 1);
    }
    header?.iter().position(|h| norm(h) == norm(t))
}

/// The trimmed, non-empty text of cell `i` of `r`.
fn cell_at<'a>(r: &[&'a str], i: Option<usize>) -> Option<&'a str> {
    i.and_then(|i| r.get(i)).map(|c| c.trim()).filter(|s| !s.is_empty())
}

/// Rows searched for the header.
const HEADER_SEARCH: usize = 50;

/// Rows of a sheet, read from the start as often as asked: the import reads a sheet up to three
/// times (its header, its address notation, its rows), so a CSV is streamed from its file, never
/// held (a grid of a sheet of tiny cells is 2.5× the file).
pub trait SheetRows {
    /// Why the rows could not be read.
    type Error;

    /// Calls `each` with every row in order (its 0-based number, its cells) until it breaks.
    ///
    /// # Errors
    /// The rows cannot be read (the file, a record, a bound).
    fn each_row(&mut self, each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>) -> Result<(), Self::Error>;

    /// Cells past [`super::grid::MAX_COLUMNS`] not read, as counted by the last whole pass.
    fn cut_cells(&self) -> u64;
}

impl SheetRows for Grid {
    type Error = std::convert::Infallible;

    fn each_row(&mut self, each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>) -> Result<(), Self::Error> {
        let mut cells = Vec::new();
        for (i, r) in self.rows().enumerate() {
            cells.clear();
            cells.extend(r.iter());
            if each(i, &cells).is_break() {
                break;
            }
        }
        Ok(())
    }

    fn cut_cells(&self) -> u64 {
        self.cut_cells
    }
}

/// Bytes of cell text, in the columns the import reads, that a sheet may make it build: a
/// register map of 65 536 rows with a 200-byte description each is 13 MB; the profile written
/// from it stays under the 16 MiB said in the README.
pub const MAX_TEXT_PRODUCED: usize = 16 << 20;

/// Reads `rows` (cells as text; row numbers in problems are 1-based, as a spreadsheet shows).
#[must_use]
pub fn parse_sheet(rows: &Grid, opts: &SheetOptions) -> Imported {
    let mut out = Imported::default();
    let mut rows = rows.clone();
    match read_sheet(&mut rows, opts, &mut out) {
        Ok(()) => {}
        Err(never) => match never {},
    }
    out
}

/// Reads `rows` into `out`: the header found in the first rows, the address notation decided
/// from every address, then each row a point or a problem.
///
/// # Errors
/// The rows cannot be read.
#[allow(clippy::too_many_lines)]
pub fn read_sheet<S: SheetRows>(rows: &mut S, opts: &SheetOptions, out: &mut impl Sink) -> Result<(), S::Error> {
    // The first rows, where the header is looked for.
    let mut head = Grid::new();
    rows.each_row(&mut |i, cells| {
        if i >= HEADER_SEARCH || head.push_row(cells.iter()).is_err() {
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    })?;
    // The header: the first row naming an address column and at least one other.
    let header = head
        .rows()
        .position(|r| {
            let fields: Vec<Field> = r.iter().filter_map(field_of).collect();
            fields.contains(&Field::Address) && fields.len() >= 2
        })
        .or_else(|| {
            // Columns given by header texts the usual names missed: the row holding them.
            let texts: Vec<String> = opts
                .columns
                .iter()
                .map(|(_, spec)| norm(spec))
                .filter(|t| t.parse::<usize>().is_err() && (t.len() > 3 || !t.chars().all(|c| c.is_ascii_alphabetic())))
                .collect();
            (!texts.is_empty()).then_some(())?;
            head.rows().position(|r| texts.iter().all(|t| r.iter().any(|c| norm(c) == *t)))
        });
    let mut columns: Vec<(Field, usize)> = Vec::new();
    if let Some(h) = header {
        for (i, c) in head.row(h).iter().enumerate() {
            if let Some(f) = field_of(c)
                && !columns.iter().any(|(g, _)| *g == f)
            {
                columns.push((f, i));
            }
        }
    }
    for (f, spec) in &opts.columns {
        match column_of(spec, header.map(|h| head.row(h))) {
            Some(i) => {
                columns.retain(|(g, _)| g != f);
                columns.push((*f, i));
            }
            None => out.problem(Problem {
                at: "--columns".into(),
                column: Some(f.key().into()),
                why: format!("{spec:?} is not a column (a letter, a number from 1, or a header text)"),
            }),
        }
    }
    // Without a name column, a description names the register.
    if !columns.iter().any(|(f, _)| *f == Field::Name)
        && let Some(&(_, i)) = columns.iter().find(|(f, _)| *f == Field::Description)
    {
        columns.retain(|(f, _)| *f != Field::Description);
        columns.push((Field::Name, i));
    }
    columns.sort();
    let col = |f: Field| columns.iter().find(|(g, _)| *g == f).map(|&(_, i)| i);
    let Some(address_col) = col(Field::Address) else {
        out.problem(Problem {
            at: format!("rows 1–{}", head.len()),
            column: None,
            why: "no header row naming an address column and another (name, type, …): give the columns with --columns address=B,name=A,…".into(),
        });
        return Ok(());
    };
    let described: Vec<String> = columns.iter().map(|(f, i)| format!("{}={}", f.key(), letter(*i))).collect();
    out.note(match header {
        Some(h) => format!("header on row {}: {}", h + 1, described.join(", ")),
        None => format!("no header row; columns given: {}", described.join(", ")),
    });
    // Nothing is guessed silently (a sheet of floats with no type column, the type
    // said in the vendor's prose, came in as u16 without a word).
    if col(Field::Type).is_none() && opts.value_type.is_none() {
        out.note(
            "warning: no type column — every register is read as u16 (coils and discrete inputs as bits); \
             if the document says otherwise (\"all values are floats\"), give --type f32 (and --word-order)"
                .into(),
        );
    }
    let first_data = header.map_or(0, |h| h + 1);

    // Modicon numbers are a property of the sheet: every address reads as one (5 or 6 digits,
    // the table's digit first, counted from 1) and the sheet names no table of its own.
    let mut use_modicon = None;
    if col(Field::Table).is_none() {
        rows.each_row(&mut |i, cells| {
            let Some(a) =
                (i >= first_data).then(|| cells.get(address_col)).flatten().and_then(|a| parse_address(a).ok())
            else {
                return ControlFlow::Continue(());
            };
            let this = modicon(a).is_some();
            use_modicon = Some(this);
            if this { ControlFlow::Continue(()) } else { ControlFlow::Break(()) }
        })?;
    }
    let use_modicon = use_modicon == Some(true);
    if use_modicon {
        out.note(
            "addresses are Modicon register numbers (30001 = input register 0, 40001 = holding register 0)".into(),
        );
    }
    // What the rows make the import build, counted as it is built — a shared string counts at
    // each cell citing it, a repeated row at each repeat — whatever the file's size says.
    let mut produced = 0usize;
    rows.each_row(&mut |i, r| {
        if i < first_data {
            return ControlFlow::Continue(());
        }
        produced = columns.iter().filter_map(|&(_, c)| r.get(c)).fold(produced, |n, c| n.saturating_add(c.len()));
        if produced > MAX_TEXT_PRODUCED {
            out.over_budget(Problem {
                at: format!("row {}", i + 1),
                column: None,
                why: format!(
                    "the rows up to here hold {produced} bytes of text in the columns read, over the {MAX_TEXT_PRODUCED} a profile may be built from (one very long cell, or the same long text cited by many cells?); nothing imported"
                ),
            });
            return ControlFlow::Break(());
        }
        read_row(i, r, &columns, address_col, use_modicon, opts, out);
        ControlFlow::Continue(())
    })?;
    if rows.cut_cells() > 0 {
        out.note(format!(
            "{} cell(s) past column {} not read (a register sheet has a dozen columns)",
            rows.cut_cells(),
            letter(super::grid::MAX_COLUMNS - 1)
        ));
    }
    Ok(())
}

/// Row `i`'s cells `r`: a point, a problem, or nothing (an empty row).
fn read_row(
    i: usize,
    r: &[&str],
    columns: &[(Field, usize)],
    address_col: usize,
    use_modicon: bool,
    opts: &SheetOptions,
    out: &mut impl Sink,
) {
    let col = |f: Field| columns.iter().find(|(g, _)| *g == f).map(|&(_, i)| i);
    let at = format!("row {}", i + 1);
    if r.iter().all(|c| c.trim().is_empty()) {
        return;
    }
    let problem = |column: Option<Field>, why: String| Problem {
        at: at.clone(),
        column: column.and_then(|f| col(f).map(|c| format!("column {} ({})", letter(c), f.key()))),
        why,
    };
    let Some(addr_text) = cell_at(r, col(Field::Address)) else {
        let text: Vec<&str> = r.iter().map(|c| c.trim()).filter(|c| !c.is_empty()).collect();
        out.problem(problem(
            Some(Field::Address),
            format!("no address (a section title or a note?): {:?}", text.join(" | ")),
        ));
        return;
    };
    // `40001-40002` or `100~101`: a range, its first address.
    let addr_text = addr_text.split(['-', '~', '–']).next().unwrap_or(addr_text).trim();
    let raw = match parse_address(addr_text) {
        Ok(a) => a,
        Err(e) => {
            // Text alone in the row: a section heading (merged across the row).
            let alone = r.iter().enumerate().all(|(j, c)| j == address_col || c.trim().is_empty());
            let why = if alone { format!("no address (a section title or a note?): {addr_text:?}") } else { e };
            out.problem(problem(Some(Field::Address), why));
            return;
        }
    };
    let row_table = match cell_at(r, col(Field::Table)).map(parse_table) {
        Some(Err(e)) => {
            out.problem(problem(Some(Field::Table), e));
            return;
        }
        Some(Ok(t)) => Some(t),
        None => None,
    };
    let (table, address) = match (use_modicon.then(|| modicon(raw)).flatten(), row_table.or(opts.table)) {
        (Some((t, a)), _) => (t, a),
        (None, Some(t)) => {
            let Ok(a) = u16::try_from(raw.value) else {
                out.problem(problem(Some(Field::Address), format!("{addr_text:?} is past 65535")));
                return;
            };
            (t, a)
        }
        (None, None) => {
            out.problem(problem(
                Some(Field::Address),
                format!("{addr_text:?}: the sheet does not say which table; give --table holding|input|coils|discrete"),
            ));
            return;
        }
    };
    let (value_type, type_len) = match cell_at(r, col(Field::Type)).map(parse_type) {
        Some(Err(e)) => {
            out.problem(problem(Some(Field::Type), e));
            return;
        }
        Some(Ok(t)) => t,
        None if matches!(table, Table::Coils | Table::DiscreteInputs) => (ValueType::Bool, None),
        None => opts.value_type.unwrap_or((ValueType::U16, None)),
    };
    let length = match cell_at(r, col(Field::Length)).map(|l| l.trim_end_matches(".0").parse::<u16>()) {
        Some(Ok(n)) if n > 0 => Some(n),
        Some(_) => {
            out.problem(problem(Some(Field::Length), "not a number of registers".into()));
            return;
        }
        None => type_len,
    };
    if value_type == ValueType::String && length.is_none() {
        out.problem(problem(
            Some(Field::Type),
            "a string needs its length in registers (a length column, or string(N))".into(),
        ));
        return;
    }
    let word_order = match cell_at(r, col(Field::WordOrder)).map(parse_word_order) {
        Some(Err(e)) => {
            out.problem(problem(Some(Field::WordOrder), e));
            return;
        }
        Some(Ok(w)) => w,
        None => opts.word_order.unwrap_or_default(),
    };
    let scale = match cell_at(r, col(Field::Scale)).map(parse_scale) {
        Some(Err(e)) => {
            out.problem(problem(Some(Field::Scale), e));
            return;
        }
        Some(Ok(s)) => s,
        None => None,
    };
    let access = match cell_at(r, col(Field::Access)).map(parse_access) {
        Some(Err(e)) => {
            out.problem(problem(Some(Field::Access), e));
            return;
        }
        Some(Ok(a)) => a,
        None => Access::Read,
    };
    let (name, unit_in_name) = unit_from_name(cell_at(r, col(Field::Name)).unwrap_or(""));
    let name = if name.is_empty() { format!("reg_{}_{address}", table.word()) } else { name };
    // Spelled as Home Assistant and the exports want it (`Volts` → `V`, `kWH` → `kWh`); a
    // unit not known is kept as written.
    let unit = cell_at(r, col(Field::Unit))
        .map(str::to_owned)
        .or(unit_in_name)
        .map(|u| crate::profile::ha_classes::ha_class(&u).map_or(u, |c| c.unit.to_owned()));
    let description = cell_at(r, col(Field::Description)).map(str::to_owned).filter(|d| *d != name);
    out.point(Point {
        table,
        address,
        name,
        value_type,
        word_order,
        scale,
        unit,
        access,
        length: if value_type == ValueType::String { length } else { None },
        description,
        origin: at,
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(text: &str) -> Grid {
        Grid::from_rows(text.lines().map(|l| l.split('|').map(str::trim)))
    }

    #[test]
    fn the_header_is_found_below_title_rows_and_bad_rows_are_named() {
        let sheet = rows(
            "ACME EM-24 Modbus map|||\n\
             Firmware 1.2|||\n\
             |||\n\
             Register|Parameter|Data Type|Scale\n\
             30001|Voltage L1 [V]|FLOAT|\n\
             30003|Current L1 (A)|float32|\n\
             Energy|||\n\
             30005|Energy|UINT32|/100\n\
             30007|Serial|STRING[4]|\n\
             30011|Broken|float64|",
        );
        let r = parse_sheet(&sheet, &SheetOptions::default());
        assert_eq!(r.points.len(), 4, "{:?}", r.problems);
        assert_eq!(r.points[0].table, Table::InputRegisters);
        assert_eq!(r.points[0].address, 0);
        assert_eq!(r.points[0].unit.as_deref(), Some("V"));
        assert_eq!(r.points[2].scale, Some(0.01));
        assert_eq!(r.points[3].length, Some(4));
        assert_eq!(r.problems.len(), 2, "{:?}", r.problems);
        assert_eq!(r.problems[0].at, "row 7");
        assert_eq!(
            r.problems[1].to_string(),
            "row 10, column C (type): \"float64\": 64-bit floats are not in the profile format"
        );
        assert!(r.notes[0].starts_with("header on row 4"), "{:?}", r.notes);
    }

    #[test]
    fn plain_addresses_need_a_table_and_overlaps_are_refused() {
        let sheet = rows("addr|name|type\n0x0010|A|int32\n0x0011|B|uint16\n12H|C|");
        let r = parse_sheet(&sheet, &SheetOptions::default());
        assert_eq!(r.points.len(), 0);
        assert!(r.problems[0].why.contains("--table"), "{:?}", r.problems);
        let opts = SheetOptions { table: Some(Table::HoldingRegisters), ..SheetOptions::default() };
        let r = parse_sheet(&sheet, &opts);
        assert_eq!(r.points.iter().map(|p| p.address).collect::<Vec<_>>(), [0x10, 0x12]);
        assert!(r.problems[0].why.contains("overlaps"), "{:?}", r.problems);
    }

    #[test]
    fn columns_can_be_given_by_letter_number_or_header() {
        assert_eq!(letter(0), "A");
        assert_eq!(letter(27), "AB");
        let cols = parse_columns("address=B,name=1,type=Kind").unwrap();
        let sheet = rows("Label|Where|Kind\nFlow|100|float\n");
        let r = parse_sheet(
            &sheet,
            &SheetOptions { columns: cols, table: Some(Table::InputRegisters), ..SheetOptions::default() },
        );
        assert_eq!(r.points.len(), 1, "{:?}", r.problems);
        assert_eq!(
            (r.points[0].name.as_str(), r.points[0].address, r.points[0].value_type),
            ("Flow", 100, ValueType::F32)
        );
        assert!(parse_columns("adress=B").unwrap_err().contains("not a column field"));
    }
}
