//! An XLS workbook's sheet read as rows from its workbook stream: the workbook reader
//! (calamine) lays out every sheet of an XLS as dense ranges when it opens the file — 8.7× a
//! 4.4 MB sheet, and 1 GB for cells at A1 and IV65536 — so the import reads the records itself:
//! the globals once (sheet names and offsets, the shared strings), then the sheet's cells in the
//! order the file holds them, a row at a time, nothing laid out.
//!
//! Records as [MS-XLS] 2.1.4 lays them out: a type (u16), a size (u16), the data; a record too
//! long for one is carried on in `Continue` records (2.4.58). The globals run to their first
//! `EOF`; each `BoundSheet8` there names a sheet and the offset of its records in the stream,
//! which run to the sheet's own `EOF`. Cells read as calamine 0.32 reads them, so a sheet imports
//! as it does through calamine: numbers (`Number`, `RK`, `MulRk`, a formula's cached number) as the sheet shows
//! them, whole ones without `.0` (a date is its serial number); text from `LabelSst`
//! (a shared string), `Label` and a formula's `String`; `BoolErr` as `true`/`false` or `#Div0`…
//! Where calamine went wrong it is not followed: BIFF8 text is Unicode whatever the `CodePage`
//! record says ([MS-XLS] 2.5.294), BIFF5 text is read in the file's code page.

use std::io::{Read, Seek, SeekFrom};
use std::ops::ControlFlow;

use super::cell_rows::rows_from_cells;
use super::grid::number_text;
pub use super::xls_records::XlsRowsError;
use super::xls_records::{Records, SST, Strings, biff8_text, shared_strings, u16_at, u32_at};

/// `Formula` [MS-XLS] 2.4.127: row, column, format, the cached value (8 bytes), flags, formula.
const FORMULA: u16 = 0x0006;
/// `EOF` [MS-XLS] 2.4.103: ends the globals and each sheet.
const EOF: u16 = 0x000A;
/// `FilePass` [MS-XLS] 2.4.117: the workbook is encrypted.
const FILE_PASS: u16 = 0x002F;
/// `CodePage` [MS-XLS] 2.4.52: the code page of BIFF5 text.
const CODE_PAGE: u16 = 0x0042;
/// `BoundSheet8` [MS-XLS] 2.4.28: a sheet's stream offset (u32), state, type, name.
const BOUND_SHEET: u16 = 0x0085;
/// `MulRk` [MS-XLS] 2.4.175: a run of numbers in one row (row, first column, 6 bytes each,
/// last column).
const MUL_RK: u16 = 0x00BD;
/// `LabelSst` [MS-XLS] 2.4.149: row, column, format, a shared string's index (u32).
const LABEL_SST: u16 = 0x00FD;
/// `Number` [MS-XLS] 2.4.180: row, column, format, an f64.
const NUMBER: u16 = 0x0203;
/// `Label` [MS-XLS] 2.4.148: row, column, format, a string.
const LABEL: u16 = 0x0204;
/// `BoolErr` [MS-XLS] 2.4.24: row, column, format, the value, whether it is an error.
const BOOL_ERR: u16 = 0x0205;
/// `String` [MS-XLS] 2.4.268: the text a formula gave, after its `Formula`.
const STRING: u16 = 0x0207;
/// `RK` [MS-XLS] 2.4.220: row, column, format, an `RkNumber` (2.5.218).
const RK: u16 = 0x027E;
/// `BOF` [MS-XLS] 2.4.21: the BIFF version (u16), the substream's type.
const BOF: u16 = 0x0809;

/// A sheet the workbook names: its name, and where its records start in the stream.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct XlsSheet {
    pub name: String,
    pub offset: u64,
}

/// A workbook's globals: its sheets and its shared strings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct XlsBook {
    pub sheets: Vec<XlsSheet>,
    strings: Strings,
    /// BIFF8 (Excel 97 on), else BIFF5: how text is written.
    biff8: bool,
    /// The code page of BIFF5 text (1200, UTF-16, when the workbook names none).
    code_page: u16,
}

/// What a pass over a sheet found besides its rows.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct XlsRows {
    /// Cells past [`super::grid::MAX_COLUMNS`], not handed on.
    pub cut_cells: u64,
}

impl XlsBook {
    /// `cch` characters of text from `d` (after the length, at the flags for BIFF8): for BIFF8
    /// per its flags byte, for BIFF5 bytes in the workbook's code page.
    fn text(&self, d: &[u8], cch: usize) -> Result<String, XlsRowsError> {
        let mut s = String::new();
        if self.biff8 {
            let Some((&flags, rest)) = d.split_first() else { return Ok(s) };
            biff8_text(rest, cch, flags & 1 != 0, &mut s);
            return Ok(s);
        }
        let bytes = &d[..cch.min(d.len())];
        let encoding = codepage::to_encoding(self.code_page).ok_or(XlsRowsError::CodePage(self.code_page))?;
        if encoding == encoding_rs::UTF_16LE || encoding == encoding_rs::UTF_16BE {
            // No code page named: 8-bit text is its byte values.
            s.extend(bytes.iter().map(|&b| char::from(b)));
        } else {
            s.push_str(&encoding.decode_without_bom_handling(bytes).0);
        }
        Ok(s)
    }

    /// An `XLUnicodeString` ([MS-XLS] 2.5.294: a u16 length, BIFF8 a flags byte, the text), as
    /// `Label` and `String` hold it. Two zero bytes are the empty string.
    fn string(&self, d: &[u8]) -> Option<String> {
        let cch = usize::from(u16_at(d, 0)?);
        if d.len() < if self.biff8 { 3 } else { 2 } {
            return (d == [0, 0]).then(String::new);
        }
        self.text(&d[2..], cch).ok()
    }
}

/// Reads a workbook stream's globals: its sheets (names and offsets) and shared strings.
///
/// Contract: any bytes; work and memory linear in the stream (the shared strings are kept as
/// one text and an offset each, ≤ 2× their bytes); the records read one at a time.
///
/// # Errors
/// The stream cannot be read, ends inside a record, is encrypted, or holds a record the sheet
/// cannot be read past (what, and at which offset).
pub fn parse_xls_book<R: Read>(stream: R) -> Result<XlsBook, XlsRowsError> {
    let mut recs = Records::new(stream);
    let mut book = XlsBook { sheets: Vec::new(), strings: Strings::default(), biff8: true, code_page: 1200 };
    while recs.next()? {
        match recs.typ {
            EOF => break,
            FILE_PASS => {
                let v = u16_at(&recs.data, 0).ok_or_else(|| recs.malformed("shorter than its 2 bytes"))?;
                if v != 0 {
                    return Err(XlsRowsError::Password);
                }
            }
            CODE_PAGE => {
                book.code_page = u16_at(&recs.data, 0).ok_or_else(|| recs.malformed("shorter than its 2 bytes"))?;
            }
            BOF => {
                let version = u16_at(&recs.data, 0).ok_or_else(|| recs.malformed("shorter than its 2 bytes"))?;
                let kind = u16_at(&recs.data, 2).unwrap_or(0);
                // [MS-XLS] 2.4.21: 0x0600 is BIFF8; earlier versions below it; a version of 0
                // with a BIFF5 workbook type (0x1000) is BIFF5, as calamine takes it.
                book.biff8 = match version {
                    0x0002 | 0x0007 | 0x0200 | 0x0300 | 0x0400 | 0x0500 => false,
                    0 => kind != 0x1000,
                    _ => true,
                };
            }
            BOUND_SHEET => {
                let d = &recs.data;
                let (Some(offset), Some(&cch)) = (u32_at(d, 0), d.get(6)) else {
                    return Err(recs.malformed("shorter than its offset, state, type and name"));
                };
                let mut name = book.text(d.get(7..).unwrap_or_default(), usize::from(cch))?;
                name.retain(|c| c != '\0');
                book.sheets.push(XlsSheet { name, offset: u64::from(offset) });
            }
            SST => shared_strings(&mut recs, &mut book.strings)?,
            _ => {}
        }
    }
    Ok(book)
}

/// An `RkNumber` ([MS-XLS] 2.5.218) as the sheet shows it: bit 0 says ÷ 100, bit 1 a 30-bit
/// integer, else the top 30 bits of an f64.
fn rk_text(rk: u32) -> String {
    let d100 = rk & 1 != 0;
    if rk & 2 != 0 {
        let v = i64::from(i32::from_le_bytes(rk.to_le_bytes()) >> 2);
        #[allow(clippy::cast_precision_loss)] // 30 bits: exact.
        if d100 && v % 100 != 0 { number_text(v as f64 / 100.0) } else { (if d100 { v / 100 } else { v }).to_string() }
    } else {
        let v = f64::from_bits(u64::from(rk & 0xFFFF_FFFC) << 32);
        number_text(if d100 { v / 100.0 } else { v })
    }
}

/// A cell error's text ([MS-XLS] 2.5.97 `BErr`), as the workbook reader names it.
fn error_text(code: u8) -> Option<&'static str> {
    Some(match code {
        0x00 => "#Null",
        0x07 => "#Div0",
        0x0F => "#Value",
        0x17 => "#Ref",
        0x1D => "#Name",
        0x24 => "#Num",
        0x2A => "#NA",
        0x2B => "#GettingData",
        _ => return None,
    })
}

/// The cells of the record held in `recs`, onto `out`; `formula_at` is where the last
/// `Formula` was (its `String` lands there).
fn cells_of<R: Read>(
    recs: &Records<R>,
    book: &XlsBook,
    formula_at: &mut (u32, u32),
    out: &mut std::collections::VecDeque<(u32, u32, String)>,
) -> Result<(), XlsRowsError> {
    let d = &recs.data;
    let at = || Some((u32::from(u16_at(d, 0)?), u32::from(u16_at(d, 2)?)));
    let short = |n: usize| d.len() < n;
    match recs.typ {
        NUMBER => {
            let (Some((r, c)), Some(bits)) = (at(), d.get(6..14)) else {
                return Err(recs.malformed("shorter than its 14 bytes"));
            };
            let v = f64::from_le_bytes(bits.try_into().map_err(|_| recs.malformed("shorter than its 14 bytes"))?);
            out.push_back((r, c, number_text(v)));
        }
        RK => {
            let (Some((r, c)), Some(rk)) = (at(), u32_at(d, 6)) else {
                return Err(recs.malformed("shorter than its 10 bytes"));
            };
            out.push_back((r, c, rk_text(rk)));
        }
        MUL_RK => {
            let (Some((r, first)), Some(last)) = (at(), d.len().checked_sub(2).and_then(|e| u16_at(d, e))) else {
                return Err(recs.malformed("shorter than its 6 bytes"));
            };
            let n = u32::from(last).checked_sub(first).map(|n| n as usize + 1);
            if n.is_none_or(|n| d.len() != 6 + 6 * n) {
                return Err(recs.malformed("its length does not hold its columns"));
            }
            for (k, c) in (first..=u32::from(last)).enumerate() {
                let rk =
                    u32_at(d, 4 + 6 * k + 2).ok_or_else(|| recs.malformed("its length does not hold its columns"))?;
                out.push_back((r, c, rk_text(rk)));
            }
        }
        LABEL_SST => {
            let (Some((r, c)), Some(i)) = (at(), u32_at(d, 6)) else {
                return Err(recs.malformed("shorter than its 10 bytes"));
            };
            if let Some(s) = book.strings.get(i as usize).filter(|s| !s.is_empty()) {
                out.push_back((r, c, s.to_owned()));
            }
        }
        LABEL => {
            let (Some((r, c)), Some(s)) = (at(), d.get(6..).and_then(|s| book.string(s))) else {
                return Err(recs.malformed("its string is cut"));
            };
            out.push_back((r, c, s));
        }
        STRING => {
            let s = book.string(d).ok_or_else(|| recs.malformed("its string is cut"))?;
            out.push_back((formula_at.0, formula_at.1, s));
        }
        BOOL_ERR => {
            let (Some((r, c)), false) = (at(), short(8)) else {
                return Err(recs.malformed("shorter than its 8 bytes"));
            };
            let text = match d[7] {
                0 => {
                    if d[6] == 0 {
                        "false"
                    } else {
                        "true"
                    }
                }
                1 => error_text(d[6]).ok_or_else(|| recs.malformed("an error code no version of Excel writes"))?,
                _ => return Err(recs.malformed("neither a boolean nor an error")),
            };
            out.push_back((r, c, text.to_owned()));
        }
        FORMULA => {
            let (Some((r, c)), false) = (at(), short(20)) else {
                return Err(recs.malformed("shorter than its 20 bytes"));
            };
            *formula_at = (r, c);
            // `FormulaValue` [MS-XLS] 2.5.133: 0xFFFF in its last two bytes marks a string
            // (in the `String` record next), a boolean, an error or an empty string.
            let v = &d[6..14];
            let text = if v[6..] == [0xFF, 0xFF] {
                match v[0] {
                    0 => return Ok(()),
                    1 => (if v[2] == 0 { "false" } else { "true" }).to_owned(),
                    2 => error_text(v[2])
                        .ok_or_else(|| recs.malformed("an error code no version of Excel writes"))?
                        .to_owned(),
                    3 => String::new(),
                    _ => return Err(recs.malformed("a cached value of no known type")),
                }
            } else {
                let mut bits = [0u8; 8];
                bits.copy_from_slice(v);
                number_text(f64::from_le_bytes(bits))
            };
            out.push_back((r, c, text));
        }
        _ => {}
    }
    Ok(())
}

/// Hands sheet `sheet` (an index into [`XlsBook::sheets`]) of the workbook `stream` to `each`,
/// row by row (its number from 0, its cells), until it breaks or the sheet's `EOF`.
///
/// Contract: any bytes; one record held at a time and one row being built (cells out of row
/// order are ignored, as a hand-made file's); rows past [`MAX_ROWS`](super::grid::MAX_ROWS) refused; work linear in
/// the sheet's records.
///
/// # Errors
/// The stream cannot be read or ends inside a record, a cell record is malformed (which, and
/// its offset), or the sheet is past [`MAX_ROWS`](super::grid::MAX_ROWS); an unknown sheet index reads as empty.
pub fn parse_xls_rows<R: Read + Seek>(
    mut stream: R,
    book: &XlsBook,
    sheet: usize,
    each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>,
) -> Result<XlsRows, XlsRowsError> {
    let Some(s) = book.sheets.get(sheet) else { return Ok(XlsRows::default()) };
    stream.seek(SeekFrom::Start(s.offset))?;
    let mut recs = Records::new(stream);
    recs.at = s.offset;
    let mut queue = std::collections::VecDeque::new();
    let mut formula_at = (0, 0);
    let mut ended = false;
    let cut_cells = rows_from_cells(
        || loop {
            if let Some(cell) = queue.pop_front() {
                return Ok(Some(cell));
            }
            if ended || !recs.next()? || recs.typ == EOF {
                ended = true;
                return Ok(None);
            }
            cells_of(&recs, book, &mut formula_at, &mut queue)?;
        },
        each,
        XlsRowsError::TooManyRows,
    )?;
    Ok(XlsRows { cut_cells })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A record: type, size, data ([MS-XLS] 2.1.4).
    fn rec(typ: u16, data: &[u8]) -> Vec<u8> {
        [&typ.to_le_bytes()[..], &u16::try_from(data.len()).unwrap().to_le_bytes(), data].concat()
    }

    /// A workbook stream: `BOF` of `version`, `globals`, a `BoundSheet8` named by `name` (its
    /// bytes as the version writes them), `EOF`; then the sheet: `BOF`, `cells`, `EOF`.
    fn stream(version: u16, globals: &[Vec<u8>], name: &[u8], cells: &[Vec<u8>]) -> Vec<u8> {
        let bof = |dt: u16| rec(BOF, &[&version.to_le_bytes()[..], &dt.to_le_bytes(), &[0; 4]].concat());
        let mut head = bof(0x0005);
        head.extend(globals.concat());
        let bound_len = rec(BOUND_SHEET, &[&[0u8; 6][..], name].concat()).len();
        let sheet_at = u32::try_from(head.len() + bound_len + 4).unwrap();
        head.extend(rec(BOUND_SHEET, &[&sheet_at.to_le_bytes()[..], &[0, 0], name].concat()));
        head.extend(rec(EOF, &[]));
        head.extend(bof(0x0010));
        head.extend(cells.concat());
        head.extend(rec(EOF, &[]));
        head
    }

    /// Every row of sheet 0, as owned text.
    fn rows(s: &[u8]) -> (Vec<String>, Vec<Vec<String>>) {
        let book = parse_xls_book(s).unwrap();
        let mut out = Vec::new();
        parse_xls_rows(std::io::Cursor::new(s), &book, 0, &mut |_, cells| {
            out.push(cells.iter().map(|c| (*c).to_owned()).collect());
            ControlFlow::Continue(())
        })
        .unwrap();
        (book.sheets.into_iter().map(|s| s.name).collect(), out)
    }

    /// `Напряжение` in code page 1251 (Windows Cyrillic).
    const VOLTAGE_1251: [u8; 10] = [0xCD, 0xE0, 0xEF, 0xF0, 0xFF, 0xE6, 0xE5, 0xED, 0xE8, 0xE5];

    /// BIFF5 (Excel 5/95) text is bytes in the workbook's code page ([MS-XLS] 2.4.52): a
    /// Cyrillic `Label` and sheet name read as Cyrillic. (calamine widened the bytes to UTF-16
    /// first for a code page of more than one byte a character.)
    #[test]
    fn biff5_text_is_read_in_the_workbook_s_code_page() {
        let name = [&[4u8][..], b"regs"].concat();
        // Label: row 0, column 1, format 0, a u16 length, the bytes.
        let label = rec(LABEL, &[&[0, 0, 1, 0, 0, 0][..], &10u16.to_le_bytes(), &VOLTAGE_1251].concat());
        let s = stream(0x0500, &[rec(CODE_PAGE, &1251u16.to_le_bytes())], &name, std::slice::from_ref(&label));
        assert_eq!(rows(&s), (vec!["regs".to_owned()], vec![vec![String::new(), "Напряжение".to_owned()]]));
        // No code page named: each byte is its own character.
        let s = stream(0x0500, &[], &name, &[label]);
        assert_eq!(rows(&s).1[0][1], "Íàïðÿæåíèå");
        // A code page nobody knows: said, not guessed.
        let s = stream(0x0500, &[rec(CODE_PAGE, &9u16.to_le_bytes())], &name, &[]);
        assert_eq!(parse_xls_book(&s[..]).map(|_| ()), Err(XlsRowsError::CodePage(9)));
    }

    /// BIFF8 text is Unicode whatever the `CodePage` record says ([MS-XLS] 2.5.294): 8-bit
    /// strings are the low bytes of UTF-16 units, not bytes in the code page.
    #[test]
    fn biff8_text_is_unicode_whatever_the_code_page() {
        let name = [&[4u8, 0][..], b"regs"].concat();
        // Label: row 0, column 0, format 0, length 3, flags 0 (8-bit), `é` `°` `C`.
        let label = rec(LABEL, &[&[0u8, 0, 0, 0, 0, 0][..], &3u16.to_le_bytes(), &[0, 0xE9, 0xB0, b'C']].concat());
        let s = stream(0x0600, &[rec(CODE_PAGE, &1251u16.to_le_bytes())], &name, &[label]);
        assert_eq!(rows(&s).1, vec![vec!["é°C".to_owned()]]);
    }
}
