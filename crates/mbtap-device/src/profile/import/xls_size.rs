//! An XLS workbook's size as the workbook reader lays it out, counted from its BIFF records
//! before the reader opens it (issue 39). calamine parses every sheet of an XLS as it opens the
//! file, each into a dense range from its first used cell to its last (and another for its
//! formulas), after reserving what the sheet's `Dimensions` record claims: a 5.6 kB file with
//! cells at A1 and IV65536 took 1.05 GB, and one whose `Dimensions` claims 2³² rows aborted the
//! process on a 343 GB allocation. This reads the workbook stream's records with counters only.
//!
//! Records as [MS-XLS] 2.1.4 lays them out: a type (u16), a size (u16), the data. The workbook
//! globals come first, up to their `EOF`; each `BoundSheet8` there names the offset of a sheet's
//! records in the same stream, which run to the sheet's own `EOF`.

/// `EOF` [MS-XLS] 2.4.103: ends the globals and each sheet.
const EOF: u16 = 0x000A;
/// `BoundSheet8` [MS-XLS] 2.4.28: a sheet's stream offset (u32), state, type, name.
const BOUND_SHEET: u16 = 0x0085;
/// `Dimensions` [MS-XLS] 2.4.90: the sheet's used rows and columns, first and last-plus-one.
const DIMENSIONS: u16 = 0x0200;
/// `Formula` [MS-XLS] 2.4.127: a cell's formula, and its value when not a string.
const FORMULA: u16 = 0x0006;
/// `MulRk` [MS-XLS] 2.4.175: a run of numbers in one row (row, first column, 6 bytes each,
/// last column).
const MUL_RK: u16 = 0x00BD;
/// The records with a cell at their start (row u16, column u16) the reader keeps: `Number`
/// (2.4.180), `Label` (2.4.148), `BoolErr` (2.4.24), `RK` (2.4.220), `LabelSst` (2.4.149).
const CELLS: [u16; 5] = [0x0203, 0x0204, 0x0205, 0x027E, 0x00FD];

/// What opening the workbook lays out.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct XlsSize {
    /// Cells of every sheet's value range and formula range together (each range spans its
    /// first used row and column to its last).
    pub cells: u64,
    /// The most cells one sheet's `Dimensions` record reserves.
    pub reserved: u64,
    /// The sheet laying out the most cells: its number (from 0), rows and columns.
    pub largest: Option<(usize, u64, u64)>,
    pub sheets: usize,
}

/// A workbook stream the reader would crash on or loop over.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum XlsSizeError {
    #[error("record {typ:#06x} at offset {offset} of the workbook stream: {why}")]
    Malformed { offset: usize, typ: u16, why: &'static str },
    #[error(
        "sheet {sheet}'s records start at offset {at}, past the workbook stream's {len} bytes (or inside another sheet's)"
    )]
    SheetOutside { sheet: usize, at: usize, len: usize },
}

/// One record: type, data, offset of the next. `None` past the stream's last whole record
/// (the reader stops there too, with an error).
fn record(stream: &[u8], at: usize) -> Option<(u16, &[u8], usize)> {
    let head = stream.get(at..at.checked_add(4)?)?;
    let typ = u16::from_le_bytes([head[0], head[1]]);
    let len = usize::from(u16::from_le_bytes([head[2], head[3]]));
    let end = at.checked_add(4)?.checked_add(len)?;
    Some((typ, stream.get(at + 4..end)?, end))
}

fn u16_at(data: &[u8], at: usize) -> Option<u32> {
    data.get(at..at + 2).map(|b| u32::from(u16::from_le_bytes([b[0], b[1]])))
}

/// The smallest box around the cells seen.
#[derive(Default)]
struct Extent(Option<(u32, u32, u32, u32)>);

impl Extent {
    fn add(&mut self, row: u32, col: u32) {
        self.0 = Some(match self.0 {
            None => (row, row, col, col),
            Some((r0, r1, c0, c1)) => (r0.min(row), r1.max(row), c0.min(col), c1.max(col)),
        });
    }

    /// Rows and columns of the box.
    fn shape(&self) -> (u64, u64) {
        self.0.map_or((0, 0), |(r0, r1, c0, c1)| (u64::from(r1 - r0) + 1, u64::from(c1 - c0) + 1))
    }
}

/// The rows × columns a `Dimensions` record reserves, as the reader reads it: a first column
/// past 255 or after the last counts from 0; a last row or column of 0 reserves one cell.
fn dimensions(data: &[u8], offset: usize) -> Result<u64, XlsSizeError> {
    let bad = |why| XlsSizeError::Malformed { offset, typ: DIMENSIONS, why };
    let u32_at = |at: usize| data.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let (first_row, last_row, first_col, last_col) = match data.len() {
        10 => (u16_at(data, 0), u16_at(data, 2), u16_at(data, 4), u16_at(data, 6)),
        14 => (u32_at(0), u32_at(4), u16_at(data, 8), u16_at(data, 10)),
        // The reader refuses the file.
        _ => return Ok(0),
    };
    let (Some(rf), Some(rl), Some(mut cf), Some(cl)) = (first_row, last_row, first_col, last_col) else {
        return Ok(0);
    };
    if cf > 0xFF || cl < cf {
        cf = 0;
    }
    if rl == 0 || cl == 0 {
        return Ok(1);
    }
    // Last row before the first: the reader's subtraction wraps to ~2³² rows.
    let rows = (rl - 1).checked_sub(rf).ok_or_else(|| bad("its last row comes before its first"))?;
    let cols = (cl - 1).checked_sub(cf).ok_or_else(|| bad("its last column comes before its first"))?;
    Ok((u64::from(rows) + 1) * (u64::from(cols) + 1))
}

/// One sheet's records from `at` to its `EOF`: the cells its ranges lay out (values, formulas),
/// what its `Dimensions` reserve, and the offset where its records end.
fn sheet(stream: &[u8], mut at: usize) -> Result<(Extent, Extent, u64, usize), XlsSizeError> {
    let (mut values, mut formulas, mut reserved) = (Extent::default(), Extent::default(), 0u64);
    while let Some((typ, data, next)) = record(stream, at) {
        let cell = || Some((u16_at(data, 0)?, u16_at(data, 2)?));
        match typ {
            EOF => return Ok((values, formulas, reserved, next)),
            DIMENSIONS => reserved = reserved.max(dimensions(data, at)?),
            t if CELLS.contains(&t) => {
                if let Some((r, c)) = cell() {
                    values.add(r, c);
                }
            }
            FORMULA => {
                if let (Some((r, c)), true) = (cell(), data.len() >= 20) {
                    values.add(r, c);
                    formulas.add(r, c);
                }
            }
            MUL_RK if data.len() >= 6 => {
                // As the reader takes it: the cells are there only when the record's length
                // matches its columns.
                if let (Some((r, first)), Some(last)) = (cell(), u16_at(data, data.len() - 2)) {
                    let n = last.checked_sub(first).map(|d| d + 1);
                    if n.is_some_and(|n| 6 + 6 * n as usize == data.len()) {
                        values.add(r, first);
                        values.add(r, last);
                    }
                }
            }
            _ => {}
        }
        at = next;
    }
    Ok((values, formulas, reserved, stream.len()))
}

/// Counts what opening the XLS workbook `stream` (its `Workbook` or `Book` stream) lays out.
///
/// Contract: any bytes; work linear in the stream (a sheet's records are walked once: sheets
/// whose records overlap are refused, as no writer makes them); no allocation but a list of
/// the sheets' offsets.
///
/// # Errors
/// A `BoundSheet8` too short to hold its offset, a sheet starting past the stream or inside
/// another sheet's records, a `Dimensions` record whose last row or column comes before its
/// first: what the reader would crash on.
pub fn parse_xls_size(stream: &[u8]) -> Result<XlsSize, XlsSizeError> {
    let mut offsets = Vec::new();
    let mut at = 0;
    while let Some((typ, data, next)) = record(stream, at) {
        match typ {
            EOF => break,
            BOUND_SHEET => {
                // The reader reads the offset, the state and the type without looking at the
                // length: shorter is an out-of-bounds read.
                let Some(b) = data.get(..6) else {
                    return Err(XlsSizeError::Malformed { offset: at, typ, why: "shorter than its 6 fixed bytes" });
                };
                offsets.push(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
            }
            _ => {}
        }
        at = next;
    }
    let mut size = XlsSize { sheets: offsets.len(), ..XlsSize::default() };
    // The sheets' records walked so far, start → end: disjoint, so the walk is linear in the
    // stream however many sheets name the same records.
    let mut walked: std::collections::BTreeMap<usize, usize> = std::collections::BTreeMap::new();
    for (n, &start) in offsets.iter().enumerate() {
        let outside = XlsSizeError::SheetOutside { sheet: n, at: start, len: stream.len() };
        if start > stream.len() || walked.range(..=start).next_back().is_some_and(|(_, &end)| start < end) {
            return Err(outside);
        }
        let (values, formulas, reserved, end) = sheet(stream, start)?;
        // A sheet whose records run over another's start: the reader walks those twice.
        if walked.range(start..end).next().is_some() {
            return Err(outside);
        }
        walked.insert(start, end.max(start + 1));
        let ((vr, vc), (fr, fc)) = (values.shape(), formulas.shape());
        let cells = vr * vc + fr * fc;
        size.cells = size.cells.saturating_add(cells);
        size.reserved = size.reserved.max(reserved);
        if size.largest.is_none_or(|(_, r, c)| r * c < vr * vc) {
            size.largest = Some((n, vr, vc));
        }
    }
    Ok(size)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A record as bytes: type, size, data.
    fn rec(typ: u16, data: &[u8]) -> Vec<u8> {
        let mut v = typ.to_le_bytes().to_vec();
        v.extend(u16::try_from(data.len()).unwrap().to_le_bytes());
        v.extend(data);
        v
    }

    /// `Number` at (row, col): row, column, format index, an f64.
    fn number(row: u16, col: u16) -> Vec<u8> {
        let mut d = row.to_le_bytes().to_vec();
        d.extend(col.to_le_bytes());
        d.extend([0, 0]);
        d.extend(1.5f64.to_le_bytes());
        rec(0x0203, &d)
    }

    /// `BoundSheet8` for a sheet at `pos`: offset, visible, worksheet, a 1-character name.
    fn bound(pos: u32) -> Vec<u8> {
        let mut d = pos.to_le_bytes().to_vec();
        d.extend([0, 0, 1, 0, b'S']);
        rec(BOUND_SHEET, &d)
    }

    /// A workbook stream: globals naming one sheet, then the sheet's records.
    fn workbook(sheet_records: &[Vec<u8>]) -> Vec<u8> {
        let globals_len = bound(0).len() + rec(EOF, &[]).len();
        let mut s = bound(u32::try_from(globals_len).unwrap());
        s.extend(rec(EOF, &[]));
        for r in sheet_records {
            s.extend(r);
        }
        s.extend(rec(EOF, &[]));
        s
    }

    #[test]
    fn a_sheet_lays_out_the_box_around_its_cells() {
        let s = workbook(&[number(0, 0), number(1, 1)]);
        let size = parse_xls_size(&s).unwrap();
        assert_eq!((size.cells, size.sheets, size.largest), (4, 1, Some((0, 2, 2))));
    }

    /// Issue 39: cells at A1 and IV65536 (5.6 kB) took the import to 1.05 GB.
    #[test]
    fn regression_issue_39_two_far_cells_count_the_whole_box() {
        let s = workbook(&[number(0, 0), number(65_535, 255)]);
        assert_eq!(parse_xls_size(&s).unwrap().cells, 65_536 * 256);
    }

    /// Issue 39: a `Dimensions` record whose last row comes before its first made the reader
    /// reserve ~2³² rows (the process aborted); a huge but ordered one is counted.
    #[test]
    fn regression_issue_39_dimensions_that_wrap_are_refused_and_huge_ones_counted() {
        let mut d = 5u32.to_le_bytes().to_vec();
        d.extend(2u32.to_le_bytes());
        d.extend([0, 0, 2, 0, 0, 0]);
        assert!(matches!(
            parse_xls_size(&workbook(&[rec(DIMENSIONS, &d)])),
            Err(XlsSizeError::Malformed { typ: DIMENSIONS, .. })
        ));
        let mut d = 0u32.to_le_bytes().to_vec();
        d.extend(u32::MAX.to_le_bytes());
        d.extend([0, 0, 0, 1, 0, 0]);
        assert_eq!(parse_xls_size(&workbook(&[rec(DIMENSIONS, &d)])).unwrap().reserved, u64::from(u32::MAX) * 256);
    }

    #[test]
    fn sheets_outside_the_stream_or_inside_another_are_refused() {
        let mut s = bound(1 << 20);
        s.extend(rec(EOF, &[]));
        assert!(matches!(parse_xls_size(&s), Err(XlsSizeError::SheetOutside { .. })));
        let one = workbook(&[number(0, 0)]);
        let start = bound(0).len() * 2 + rec(EOF, &[]).len();
        let mut twice = bound(u32::try_from(start).unwrap());
        twice.extend(bound(u32::try_from(start).unwrap()));
        twice.extend(rec(EOF, &[]));
        twice.extend(&one[bound(0).len() + 4..]);
        assert!(matches!(parse_xls_size(&twice), Err(XlsSizeError::SheetOutside { sheet: 1, .. })));
        assert!(matches!(parse_xls_size(&rec(BOUND_SHEET, &[1, 2])), Err(XlsSizeError::Malformed { .. })));
    }

    #[test]
    fn runs_of_numbers_count_their_columns_and_cut_records_end_the_walk() {
        // MulRk: row 3, columns 2..=4, three 6-byte values, last column.
        let mut d = 3u16.to_le_bytes().to_vec();
        d.extend(2u16.to_le_bytes());
        d.extend([0u8; 18]);
        d.extend(4u16.to_le_bytes());
        assert_eq!(parse_xls_size(&workbook(&[rec(MUL_RK, &d)])).unwrap().cells, 3);
        let mut cut = workbook(&[number(0, 0)]);
        cut.truncate(cut.len() - 3);
        assert_eq!(parse_xls_size(&cut).unwrap().cells, 1);
        assert_eq!(parse_xls_size(&[]).unwrap(), XlsSize::default());
    }
}
