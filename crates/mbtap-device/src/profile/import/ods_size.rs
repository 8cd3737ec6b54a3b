//! What an OpenDocument spreadsheet's tables take once a reader expands them, from its
//! `content.xml` streamed with nothing kept but counters — so a workbook whose repeated rows
//! and cells would expand past memory is refused before such a reader opens it (an
//! 873-byte ODS, one row of 16 000 empty cells repeated 1 048 000 times above a value, took the
//! import past 17 GB).
//!
//! OpenDocument v1.2 part 1 §9.1.3 (`table:table-row`, `table:number-rows-repeated`) and §9.1.4
//! (`table:table-cell`, `table:number-columns-repeated`): one element stands for that many rows
//! or cells. The counts follow the reader mbtap opens workbooks with (calamine): it keeps one
//! copy of each row element's cells — a non-empty cell as many times as it repeats, the empty
//! cells before it too, trailing empty cells not at all — and then lays the used area out whole,
//! every repeat of every row between the first and the last non-empty one, as wide as the widest.
//! Every figure is a saturating count: no input overflows it, and the work is one pass over the
//! XML events.

use std::io::BufRead;

use quick_xml::events::{BytesStart, Event};

/// The expanded size of a workbook's tables, summed over all of them (the reader expands every
/// table when it opens the workbook, whichever is asked for).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct OdsSize {
    /// Tables in the workbook.
    pub tables: u64,
    /// Cells the reader keeps while reading the rows (repeats of non-empty cells included).
    pub cells_read: u64,
    /// Cells of the used areas laid out whole (rows × columns, repeats included).
    pub area_cells: u64,
    /// Bytes of cell text once repeated cells are copied.
    pub text_bytes: u64,
    /// The table with the largest used area, and its rows and columns (the name cut to 64
    /// characters: it goes into a message).
    pub largest: Option<(String, u64, u64)>,
}

/// The XML could not be read to its end.
#[derive(Debug, thiserror::Error)]
#[error("content.xml, byte {offset}: {message}")]
pub struct OdsSizeError {
    /// Where in `content.xml` (bytes).
    pub offset: u64,
    pub message: String,
}

/// One table's counters while its rows go by.
#[derive(Debug, Default)]
struct Table {
    name: String,
    /// Rows of the used area so far (from the first non-empty row through the last).
    rows: u64,
    /// Empty rows since the last non-empty one (laid out only if another non-empty row comes).
    pending_rows: u64,
    /// The used area's first and last+1 column.
    first_col: Option<u64>,
    end_col: u64,
}

/// The row being read.
#[derive(Debug, Default)]
struct Row {
    repeats: u64,
    /// Cells kept so far in this row's copy, and empty ones waiting for a non-empty one.
    pos: u64,
    pending: u64,
    first: Option<u64>,
}

/// The cell being read.
#[derive(Debug, Default)]
struct Cell {
    repeats: u64,
    valued: bool,
    text: u64,
    /// Elements open inside the cell (`text:p`, `text:span`…): the cell ends at depth 0.
    depth: u32,
}

/// A repeat count: absent is 1; unreadable also 1 (the reader then refuses the file itself).
fn repeats(e: &BytesStart<'_>, key: &[u8]) -> u64 {
    e.attributes()
        .flatten()
        .find(|a| a.key.as_ref() == key)
        .and_then(|a| std::str::from_utf8(&a.value).ok().and_then(|v| v.trim().parse::<u64>().ok()))
        .unwrap_or(1)
}

fn has(e: &BytesStart<'_>, key: &[u8]) -> bool {
    e.attributes().flatten().any(|a| a.key.as_ref() == key)
}

/// Streams `content.xml` from `xml` and counts what its tables expand to.
///
/// Contract: any bytes; memory bounded by the XML reader's buffer for one event (one element's
/// start tag or one text run) and a table's name; time linear in the input.
///
/// # Errors
/// The XML is malformed before its end (with the byte offset).
pub fn parse_ods_size<R: BufRead>(xml: R) -> Result<OdsSize, OdsSizeError> {
    let mut reader = quick_xml::Reader::from_reader(xml);
    let config = reader.config_mut();
    config.check_end_names = false;
    config.expand_empty_elements = true;
    let mut buf = Vec::new();
    let mut size = OdsSize::default();
    let mut table: Option<Table> = None;
    let mut row: Option<Row> = None;
    let mut cell: Option<Cell> = None;
    loop {
        let event = reader
            .read_event_into(&mut buf)
            .map_err(|e| OdsSizeError { offset: reader.buffer_position(), message: e.to_string() })?;
        match event {
            Event::Eof => break,
            Event::Start(e) => {
                if let Some(c) = cell.as_mut() {
                    c.depth = c.depth.saturating_add(1);
                } else if row.is_some()
                    && matches!(e.name().as_ref(), b"table:table-cell" | b"table:covered-table-cell")
                {
                    cell = Some(Cell {
                        repeats: repeats(&e, b"table:number-columns-repeated"),
                        valued: has(&e, b"office:value-type"),
                        ..Cell::default()
                    });
                } else if table.is_some() && e.name().as_ref() == b"table:table-row" {
                    row = Some(Row { repeats: repeats(&e, b"table:number-rows-repeated"), ..Row::default() });
                } else if table.is_none() && e.name().as_ref() == b"table:table" {
                    // A table inside a table is read by the workbook reader as rows of the outer
                    // one, until the first end of a table: counted so too.
                    let name = e
                        .attributes()
                        .flatten()
                        .find(|a| a.key.as_ref() == b"table:name")
                        .map(|a| String::from_utf8_lossy(&a.value).chars().take(64).collect())
                        .unwrap_or_default();
                    size.tables = size.tables.saturating_add(1);
                    table = Some(Table { name, ..Table::default() });
                }
            }
            Event::Text(t) => {
                if let Some(c) = cell.as_mut() {
                    let n = t.iter().filter(|b| !b.is_ascii_whitespace()).count();
                    c.text = c.text.saturating_add(u64::try_from(n).unwrap_or(u64::MAX));
                }
            }
            Event::CData(t) => {
                if let Some(c) = cell.as_mut() {
                    c.text = c.text.saturating_add(u64::try_from(t.len()).unwrap_or(u64::MAX));
                }
            }
            // Ended by name: a column declaration, a header-row group or a row group ends inside
            // a table without ending it.
            Event::End(e) => {
                if let Some(c) = cell.as_mut() {
                    if c.depth > 0 {
                        c.depth -= 1;
                    } else if let (Some(c), Some(r)) = (cell.take(), row.as_mut()) {
                        end_cell(&mut size, r, &c);
                    }
                } else if e.name().as_ref() == b"table:table-row" {
                    if let (Some(r), Some(t)) = (row.take(), table.as_mut()) {
                        end_row(t, &r);
                    }
                } else if e.name().as_ref() == b"table:table"
                    && let Some(t) = table.take()
                {
                    end_table(&mut size, t);
                }
            }
            _ => {}
        }
        buf.clear();
    }
    Ok(size)
}

/// A cell ends: a non-empty one is kept with the empty ones before it, as often as it repeats.
fn end_cell(size: &mut OdsSize, r: &mut Row, c: &Cell) {
    if c.valued || c.text > 0 {
        let kept = r.pending.saturating_add(c.repeats);
        size.cells_read = size.cells_read.saturating_add(kept);
        size.text_bytes = size.text_bytes.saturating_add(c.text.saturating_mul(c.repeats));
        r.first.get_or_insert(r.pos.saturating_add(r.pending));
        r.pos = r.pos.saturating_add(kept);
        r.pending = 0;
    } else {
        r.pending = r.pending.saturating_add(c.repeats);
    }
}

/// A row ends: a non-empty one widens the used area and lays out the empty rows before it.
fn end_row(t: &mut Table, r: &Row) {
    match r.first {
        Some(first) => {
            t.rows = t.rows.saturating_add(t.pending_rows);
            t.rows = t.rows.saturating_add(r.repeats);
            t.pending_rows = 0;
            t.first_col = Some(t.first_col.map_or(first, |f| f.min(first)));
            t.end_col = t.end_col.max(r.pos);
        }
        None if t.rows > 0 => t.pending_rows = t.pending_rows.saturating_add(r.repeats),
        None => {}
    }
}

fn end_table(size: &mut OdsSize, t: Table) {
    let cols = t.end_col.saturating_sub(t.first_col.unwrap_or(0));
    let area = t.rows.saturating_mul(cols);
    size.area_cells = size.area_cells.saturating_add(area);
    if size.largest.as_ref().is_none_or(|(_, r, c)| r.saturating_mul(*c) < area) {
        size.largest = Some((t.name, t.rows, cols));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `content.xml` around `rows` (the table named "Regs").
    fn content(rows: &str) -> String {
        format!(
            r#"<?xml version="1.0" encoding="UTF-8"?>
<office:document-content xmlns:office="urn:oasis:names:tc:opendocument:xmlns:office:1.0" xmlns:table="urn:oasis:names:tc:opendocument:xmlns:table:1.0" xmlns:text="urn:oasis:names:tc:opendocument:xmlns:text:1.0"><office:body><office:spreadsheet><table:table table:name="Regs">{rows}</table:table></office:spreadsheet></office:body></office:document-content>"#
        )
    }

    /// A header row of two text cells.
    const HEADER: &str = r#"<table:table-row><table:table-cell office:value-type="string"><text:p>Address</text:p></table:table-cell><table:table-cell office:value-type="string"><text:p>Name</text:p></table:table-cell></table:table-row>"#;
    /// A row of 16 000 empty cells, repeated 1 048 000 times (an 873-byte workbook).
    const EMPTY_PLAIN: &str = r#"<table:table-row table:number-rows-repeated="1048000"><table:table-cell table:number-columns-repeated="16000"/></table:table-row>"#;
    /// One value in column A.
    const VALUE_ROW: &str = r#"<table:table-row><table:table-cell office:value-type="float" office:value="101"><text:p>101</text:p></table:table-cell></table:table-row>"#;

    #[test]
    fn a_plain_sheet_counts_its_cells() {
        let s = parse_ods_size(content(HEADER).as_bytes()).unwrap_or_default();
        assert_eq!(
            s,
            OdsSize { tables: 1, cells_read: 2, area_cells: 2, text_bytes: 11, largest: Some(("Regs".into(), 1, 2)) }
        );
    }

    /// Trailing empty rows and cells (what spreadsheet programs write to a sheet's end) are
    /// never laid out: no cost.
    #[test]
    fn trailing_empty_rows_and_cells_cost_nothing() {
        let s = parse_ods_size(content(&format!("{HEADER}{EMPTY_PLAIN}")).as_bytes()).unwrap_or_default();
        assert_eq!((s.cells_read, s.area_cells), (2, 2));
    }

    /// Empty rows between two non-empty ones are laid out whole, as wide as the widest
    /// row — the 873-byte workbook's 1 048 000 rows, counted without being expanded.
    #[test]
    fn repeated_empty_rows_between_values_are_counted_as_laid_out() {
        let s = parse_ods_size(content(&format!("{HEADER}{EMPTY_PLAIN}{VALUE_ROW}")).as_bytes()).unwrap_or_default();
        assert_eq!(s.area_cells, (1 + 1_048_000 + 1) * 2);
        // A value after 16 000 empty cells widens every row of the area.
        let wide = r#"<table:table-row><table:table-cell table:number-columns-repeated="16000"/><table:table-cell office:value-type="string"><text:p>x</text:p></table:table-cell></table:table-row>"#;
        let s = parse_ods_size(content(&format!("{HEADER}{EMPTY_PLAIN}{wide}")).as_bytes()).unwrap_or_default();
        assert_eq!(s.area_cells, (1 + 1_048_000 + 1) * 16_001);
        assert_eq!(s.cells_read, 2 + 16_001);
    }

    /// A non-empty cell repeated is copied as often, text and all.
    #[test]
    fn a_repeated_value_is_counted_with_its_text_each_time() {
        let row = r#"<table:table-row table:number-rows-repeated="1000"><table:table-cell table:number-columns-repeated="5000" office:value-type="string"><text:p>abcd</text:p></table:table-cell></table:table-row>"#;
        let s = parse_ods_size(content(row).as_bytes()).unwrap_or_default();
        assert_eq!((s.cells_read, s.text_bytes, s.area_cells), (5000, 20_000, 5_000_000));
    }

    #[test]
    fn counts_saturate_and_malformed_xml_says_where() {
        let row = r#"<table:table-row table:number-rows-repeated="18446744073709551615"><table:table-cell table:number-columns-repeated="18446744073709551615" office:value-type="float"/></table:table-row>"#;
        let s = parse_ods_size(content(&format!("{row}{row}")).as_bytes()).unwrap_or_default();
        assert_eq!(s.area_cells, u64::MAX);
        let e = parse_ods_size(&b"<a><b></c"[..]).err();
        assert!(e.is_some_and(|e| e.to_string().starts_with("content.xml, byte ")));
    }

    /// The column declarations spreadsheet programs write before the rows, or a header-row group,
    /// do not end a table's count: rows end at their own end tag, tables at theirs, so no row after
    /// them is hidden from the count.
    #[test]
    fn column_declarations_and_row_groups_do_not_end_the_count() {
        let rows = format!(
            r#"<table:table-column table:number-columns-repeated="3"/><table:table-header-rows>{HEADER}</table:table-header-rows>{EMPTY_PLAIN}{VALUE_ROW}"#
        );
        let s = parse_ods_size(content(&rows).as_bytes()).unwrap_or_default();
        assert_eq!(s.area_cells, (1 + 1_048_000 + 1) * 2);
        // A table opened inside a table is more rows of the outer one.
        let nested = format!(r#"{HEADER}<table:table table:name="In">{EMPTY_PLAIN}{VALUE_ROW}</table:table>"#);
        let s = parse_ods_size(content(&nested).as_bytes()).unwrap_or_default();
        assert_eq!((s.tables, s.area_cells), (1, (1 + 1_048_000 + 1) * 2));
    }
}
