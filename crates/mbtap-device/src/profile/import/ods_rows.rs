//! An OpenDocument spreadsheet's rows streamed from its `content.xml`: the workbook
//! reader (calamine) expands every table of the file into memory when it opens it — ~66 bytes a
//! cell, 84× a 655 kB sheet — so the import reads the table it wants itself, a row at a time,
//! holding one row.
//!
//! The cells read as calamine 0.32 reads them, so a sheet imports the same either way
//! (OpenDocument v1.2 part 1 §9.1.3–§9.1.4, §19.385–§19.389): a cell's value is its
//! `office:value` (a number), `office:string-value`, `office:date-value`, `office:time-value` or
//! `office:boolean-value`, the first present; a cell typed `string` without a string value is its
//! paragraphs (`text:p`, joined by line breaks; `text:s` a run of spaces; annotations left out); a
//! cell with none of these is empty. `table:number-columns-repeated` and
//! `table:number-rows-repeated` repeat a cell or a row. Rows are numbered as the sheet shows them;
//! empty rows after the last non-empty one are not handed on (a spreadsheet program writes a
//! million of them), nor empty cells after a row's last value.

use std::io::BufRead;
use std::ops::ControlFlow;

use quick_xml::events::{BytesStart, Event};

use super::grid::{MAX_COLUMNS, MAX_ROWS};

/// The most text one cell may hold (a register sheet's cells are words; the rest is cut).
const MAX_CELL_TEXT: usize = 1 << 16;

/// Why the rows could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OdsRowsError {
    #[error("content.xml, byte {offset}: {message}")]
    Xml { offset: u64, message: String },
    #[error("no sheet {0:?} (it has: {1})")]
    NoSheet(String, String),
    #[error("no sheets")]
    NoSheets,
    #[error("more than {MAX_ROWS} rows (at row {0}): not a register sheet")]
    TooManyRows(u64),
}

/// What a pass found besides its rows.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct OdsRows {
    /// Non-empty cells past [`MAX_COLUMNS`], not handed on.
    pub cut_cells: u64,
}

fn attr(e: &BytesStart<'_>, key: &[u8]) -> Option<String> {
    e.attributes().flatten().find(|a| a.key.as_ref() == key).map(|a| unescaped(&a.value))
}

/// An attribute's value with its entities resolved (kept as written where one is unknown).
fn unescaped(raw: &[u8]) -> String {
    let text = String::from_utf8_lossy(raw);
    quick_xml::escape::unescape(&text).map_or_else(|_| text.to_string(), std::borrow::Cow::into_owned)
}

/// A repeat count: absent or unreadable is 1.
fn repeats(e: &BytesStart<'_>, key: &[u8]) -> u64 {
    attr(e, key).and_then(|v| v.trim().parse::<u64>().ok()).unwrap_or(1).max(1)
}

/// A number as a sheet shows it: whole numbers without `.0` (the import's text of a cell).
fn number_text(v: &str) -> String {
    v.trim().parse::<f64>().map_or_else(|_| v.trim().to_owned(), super::grid::number_text)
}

/// The cell a start tag opens: its value from its attributes, or `None` when its paragraphs are
/// its value (a `string` cell without `office:string-value`).
fn value_of(e: &BytesStart<'_>) -> Option<String> {
    let mut string = false;
    for a in e.attributes().flatten() {
        let text = || unescaped(&a.value);
        match a.key.as_ref() {
            b"office:value" => return Some(number_text(&text())),
            b"office:string-value" | b"office:date-value" | b"office:time-value" => return Some(text()),
            b"office:boolean-value" => {
                return Some(if matches!(&*a.value, b"TRUE" | b"true") { "true" } else { "false" }.to_owned());
            }
            b"office:value-type" => string = &*a.value == b"string",
            _ => {}
        }
    }
    if string { None } else { Some(String::new()) }
}

/// The cell being read.
struct Cell {
    repeats: u64,
    value: String,
    /// Its paragraphs are its value (read as they come).
    from_text: bool,
    /// Elements open inside it, and the depth of an annotation being skipped.
    depth: u32,
    annotation: Option<u32>,
    first_paragraph: bool,
}

impl Cell {
    fn open(&mut self, e: &BytesStart<'_>) {
        self.depth += 1;
        let name = e.name();
        if self.annotation.is_some() || !self.from_text {
            return;
        }
        match name.as_ref() {
            b"office:annotation" => self.annotation = Some(self.depth),
            b"text:p" => {
                if !self.first_paragraph {
                    self.push("\n");
                }
                self.first_paragraph = false;
            }
            b"text:s" => {
                let n = attr(e, b"text:c").map_or(Some(1), |v| v.trim().parse::<usize>().ok()).unwrap_or(1);
                let room = MAX_CELL_TEXT.saturating_sub(self.value.len());
                self.value.extend(std::iter::repeat_n(' ', n.min(room)));
            }
            _ => {}
        }
    }

    /// An element inside the cell ends; `false` when it was the cell itself.
    fn close(&mut self) -> bool {
        if self.depth == 0 {
            return false;
        }
        if self.annotation == Some(self.depth) {
            self.annotation = None;
        }
        self.depth -= 1;
        true
    }

    fn reading(&self) -> bool {
        self.from_text && self.annotation.is_none()
    }

    fn push(&mut self, s: &str) {
        let room = MAX_CELL_TEXT.saturating_sub(self.value.len());
        self.value.extend(s.chars().take(room));
    }
}

/// Streams `xml` (a `content.xml`), handing `each` every row of the table named `sheet`
/// (case-insensitive; `None`: the first) with its 0-based row number, until `each` breaks.
///
/// Contract: any bytes; memory is one row of at most [`MAX_COLUMNS`] cells of at most
/// 64 KiB each (`MAX_CELL_TEXT`), and the XML reader's buffer for one event; rows past
/// [`MAX_ROWS`] are an error; time linear in the input.
///
/// # Errors
/// Malformed XML before the table's end (with its offset), no such table, too many rows.
pub fn parse_ods_rows<R: BufRead>(
    xml: R,
    sheet: Option<&str>,
    each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>,
) -> Result<OdsRows, OdsRowsError> {
    let mut reader = quick_xml::Reader::from_reader(xml);
    let config = reader.config_mut();
    config.check_end_names = false;
    config.expand_empty_elements = true;
    let mut buf = Vec::new();
    let mut names: Vec<String> = Vec::new();
    let mut out = OdsRows::default();
    let mut in_table = false;
    // The row being read: its repeats and cells; empty cells waiting for a value after them.
    let mut row: Option<(u64, Vec<String>)> = None;
    let mut pending_cells = 0u64;
    let mut cell: Option<Cell> = None;
    // Empty rows waiting for a row after them; the number of the next row handed on.
    let (mut pending_rows, mut next_row) = (0u64, 0u64);
    loop {
        let event = reader
            .read_event_into(&mut buf)
            .map_err(|e| OdsRowsError::Xml { offset: reader.buffer_position(), message: e.to_string() })?;
        match event {
            Event::Eof => break,
            Event::Start(e) => {
                let name = e.name();
                if let Some(c) = cell.as_mut() {
                    c.open(&e);
                } else if row.is_some() && matches!(name.as_ref(), b"table:table-cell" | b"table:covered-table-cell") {
                    let value = value_of(&e);
                    cell = Some(Cell {
                        repeats: repeats(&e, b"table:number-columns-repeated"),
                        from_text: value.is_none(),
                        value: value.unwrap_or_default(),
                        depth: 0,
                        annotation: None,
                        first_paragraph: true,
                    });
                } else if in_table && name.as_ref() == b"table:table-row" {
                    row = Some((repeats(&e, b"table:number-rows-repeated"), Vec::new()));
                    pending_cells = 0;
                } else if !in_table && name.as_ref() == b"table:table" {
                    let table = attr(&e, b"table:name").unwrap_or_default();
                    in_table = sheet.map_or(names.is_empty(), |s| table.eq_ignore_ascii_case(s));
                    names.push(table);
                }
            }
            Event::Text(t) => {
                if let Some(c) = cell.as_mut().filter(|c| c.reading()) {
                    let s = t
                        .xml10_content()
                        .map_err(|e| OdsRowsError::Xml { offset: reader.buffer_position(), message: e.to_string() })?;
                    c.push(&s);
                }
            }
            Event::GeneralRef(r) => {
                if let Some(c) = cell.as_mut().filter(|c| c.reading()) {
                    let resolved = match r.resolve_char_ref() {
                        Ok(Some(ch)) => Some(ch.to_string()),
                        _ => quick_xml::escape::resolve_predefined_entity(&String::from_utf8_lossy(&r))
                            .map(str::to_owned),
                    };
                    if let Some(s) = resolved {
                        c.push(&s);
                    }
                }
            }
            Event::End(e) => {
                if let Some(c) = cell.as_mut() {
                    if !c.close()
                        && let (Some(c), Some((_, cells))) = (cell.take(), row.as_mut())
                    {
                        end_cell(&mut out, cells, &mut pending_cells, &c);
                    }
                } else if e.name().as_ref() == b"table:table-row" {
                    if let Some((repeat, cells)) = row.take() {
                        if cells.is_empty() {
                            pending_rows = pending_rows.saturating_add(repeat);
                        } else {
                            if next_row.saturating_add(pending_rows).saturating_add(repeat) > MAX_ROWS as u64 {
                                return Err(OdsRowsError::TooManyRows(MAX_ROWS as u64 + 1));
                            }
                            let refs: Vec<&str> = cells.iter().map(String::as_str).collect();
                            let rows = std::iter::repeat_n(&[][..], usize::try_from(pending_rows).unwrap_or(0))
                                .chain(std::iter::repeat_n(&refs[..], usize::try_from(repeat).unwrap_or(0)));
                            for r in rows {
                                let i = usize::try_from(next_row).unwrap_or(usize::MAX);
                                next_row += 1;
                                if each(i, r).is_break() {
                                    return Ok(out);
                                }
                            }
                            pending_rows = 0;
                        }
                    }
                } else if in_table && e.name().as_ref() == b"table:table" {
                    return Ok(out);
                }
            }
            _ => {}
        }
        buf.clear();
    }
    match sheet {
        _ if names.is_empty() => Err(OdsRowsError::NoSheets),
        Some(s) => Err(OdsRowsError::NoSheet(s.to_owned(), names.join(", "))),
        None => Ok(out),
    }
}

/// A cell ends: a value is placed after the empty cells before it, as often as it repeats, up
/// to [`MAX_COLUMNS`] (the rest counted); an empty one waits for a value after it.
fn end_cell(out: &mut OdsRows, cells: &mut Vec<String>, pending: &mut u64, c: &Cell) {
    if c.value.is_empty() {
        *pending = pending.saturating_add(c.repeats);
        return;
    }
    let start = u64::try_from(cells.len()).unwrap_or(u64::MAX).saturating_add(*pending);
    let end = start.saturating_add(c.repeats);
    let max = MAX_COLUMNS as u64;
    out.cut_cells = out.cut_cells.saturating_add(end.saturating_sub(start.max(max)));
    if start < max {
        cells.resize(usize::try_from(start).unwrap_or(MAX_COLUMNS), String::new());
        for _ in start..end.min(max) {
            cells.push(c.value.clone());
        }
    }
    *pending = 0;
}
