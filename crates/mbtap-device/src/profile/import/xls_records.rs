//! An XLS workbook stream's records read one at a time, and its shared strings: the
//! pieces of `xls_rows.rs` that know how BIFF carries a record on in `Continue` records.
//!
//! Records as [MS-XLS] 2.1.4 lays them out: a type (u16), a size (u16), the data; a record too
//! long for one is carried on in `Continue` records (2.4.58). The `SST` (2.4.265) is the record
//! that does it most: a string may break anywhere, its characters going on after a flags byte
//! of their own.

use std::io::Read;

use super::grid::MAX_ROWS;

/// `Continue` [MS-XLS] 2.4.58: the record before goes on here.
pub(super) const CONTINUE: u16 = 0x003C;
/// `SST` [MS-XLS] 2.4.265: the shared strings (two counts, then the strings).
pub(super) const SST: u16 = 0x00FC;
/// The most shared-string text kept (the stream is at most 64 MiB, and 8-bit text at most
/// doubles as UTF-8).
pub(super) const MAX_STRING_TEXT: usize = 128 << 20;

/// Why the sheet could not be read: what, and where in the workbook stream.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum XlsRowsError {
    #[error("reading the workbook stream: {0}")]
    Io(String),
    #[error("the workbook stream ends inside a record at offset {0}")]
    Cut(u64),
    #[error("record {typ:#06x} at offset {offset} of the workbook stream: {why}")]
    Malformed { offset: u64, typ: u16, why: &'static str },
    #[error("the workbook is encrypted")]
    Password,
    #[error("the workbook's code page {0} is not one the reader knows")]
    CodePage(u16),
    #[error("more than {MAX_ROWS} rows (a cell at row {}): not a register sheet", .0 + 1)]
    TooManyRows(usize),
    #[error("more than {} MiB of shared strings", MAX_STRING_TEXT >> 20)]
    TooMuchText,
}

impl From<std::io::Error> for XlsRowsError {
    fn from(e: std::io::Error) -> Self {
        Self::Io(e.to_string())
    }
}

/// The shared strings, compact: all text in one string, each string an end offset.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct Strings {
    pub(super) text: String,
    ends: Vec<u32>,
}

impl Strings {
    pub(super) fn get(&self, i: usize) -> Option<&str> {
        let end = *self.ends.get(i)? as usize;
        let start = i.checked_sub(1).and_then(|p| self.ends.get(p)).map_or(0, |&e| e as usize);
        self.text.get(start..end)
    }

    /// Ends the string being written at the text's end.
    pub(super) fn end(&mut self) -> Result<(), XlsRowsError> {
        if self.text.len() > MAX_STRING_TEXT {
            return Err(XlsRowsError::TooMuchText);
        }
        self.ends.push(u32::try_from(self.text.len()).map_err(|_| XlsRowsError::TooMuchText)?);
        Ok(())
    }
}

/// The stream's records, one at a time, the current one's data held (at most 65 535 bytes).
pub(super) struct Records<R> {
    pub(super) inner: R,
    /// Offset in the stream of the next byte `inner` gives.
    pub(super) at: u64,
    /// A header read ahead while looking for a `Continue`: type, size, offset.
    pub(super) ahead: Option<(u16, u16, u64)>,
    pub(super) typ: u16,
    pub(super) offset: u64,
    pub(super) data: Vec<u8>,
}

/// Fills `buf` from `r` as far as it goes: the bytes read.
pub(super) fn read_full(r: &mut impl Read, buf: &mut [u8]) -> Result<usize, XlsRowsError> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e.into()),
        }
    }
    Ok(n)
}

pub(super) fn u16_at(d: &[u8], at: usize) -> Option<u16> {
    d.get(at..at.checked_add(2)?).map(|b| u16::from_le_bytes([b[0], b[1]]))
}

pub(super) fn u32_at(d: &[u8], at: usize) -> Option<u32> {
    d.get(at..at.checked_add(4)?).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

impl<R: Read> Records<R> {
    pub(super) fn new(inner: R) -> Self {
        Self { inner, at: 0, ahead: None, typ: 0, offset: 0, data: Vec::new() }
    }

    pub(super) fn header(&mut self) -> Result<Option<(u16, u16, u64)>, XlsRowsError> {
        if let Some(h) = self.ahead.take() {
            return Ok(Some(h));
        }
        let mut h = [0u8; 4];
        let offset = self.at;
        let n = read_full(&mut self.inner, &mut h)?;
        self.at += n as u64;
        match n {
            0 => Ok(None),
            4 => Ok(Some((u16::from_le_bytes([h[0], h[1]]), u16::from_le_bytes([h[2], h[3]]), offset))),
            _ => Err(XlsRowsError::Cut(offset)),
        }
    }

    pub(super) fn load(&mut self, (typ, len, offset): (u16, u16, u64)) -> Result<(), XlsRowsError> {
        self.data.resize(usize::from(len), 0);
        let n = read_full(&mut self.inner, &mut self.data)?;
        self.at += n as u64;
        if n < usize::from(len) {
            return Err(XlsRowsError::Cut(offset));
        }
        (self.typ, self.offset) = (typ, offset);
        Ok(())
    }

    /// The next record, held: false at the stream's end.
    pub(super) fn next(&mut self) -> Result<bool, XlsRowsError> {
        match self.header()? {
            Some(h) => self.load(h).map(|()| true),
            None => Ok(false),
        }
    }

    /// The next record when it is a `Continue`, held; any other is left for [`Self::next`].
    pub(super) fn next_continue(&mut self) -> Result<bool, XlsRowsError> {
        match self.header()? {
            Some(h) if h.0 == CONTINUE => self.load(h).map(|()| true),
            other => {
                self.ahead = other;
                Ok(false)
            }
        }
    }

    pub(super) fn malformed(&self, why: &'static str) -> XlsRowsError {
        XlsRowsError::Malformed { offset: self.offset, typ: self.typ, why }
    }
}

/// Up to `left` characters of BIFF8 text from `d` onto `out` — 8-bit (the low byte of each
/// UTF-16 unit, [MS-XLS] 2.5.293 `fHighByte` clear) or UTF-16: the characters and bytes taken.
pub(super) fn biff8_text(d: &[u8], left: usize, wide: bool, out: &mut String) -> (usize, usize) {
    if wide {
        let n = left.min(d.len() / 2);
        let units = d[..2 * n].chunks_exact(2).map(|u| u16::from_le_bytes([u[0], u[1]]));
        out.extend(char::decode_utf16(units).map(|c| c.unwrap_or(char::REPLACEMENT_CHARACTER)));
        (n, 2 * n)
    } else {
        let n = left.min(d.len());
        out.extend(d[..n].iter().map(|&b| char::from(b)));
        (n, n)
    }
}

/// One string of the `SST` from `recs.data[*pos..]`, carried on into `Continue` records as the
/// string says ([MS-XLS] 2.5.293: length, flags, rich-text runs and phonetic data after the
/// characters; a `Continue` inside the characters starts with a flags byte of its own).
pub(super) fn shared_string<R: Read>(
    recs: &mut Records<R>,
    pos: &mut usize,
    out: &mut Strings,
) -> Result<(), XlsRowsError> {
    let d = recs.data.get(*pos..).unwrap_or_default();
    if d.is_empty() {
        return out.end();
    }
    let (Some(cch), Some(&flags)) = (u16_at(d, 0), d.get(2)) else {
        return Err(recs.malformed("a shared string's length and flags run past the record"));
    };
    *pos += 3;
    let mut after = 0usize;
    if flags & 0x8 != 0 {
        let runs = u16_at(&recs.data, *pos).ok_or_else(|| recs.malformed("a shared string's run count is cut"))?;
        after += 4 * usize::from(runs);
        *pos += 2;
    }
    if flags & 0x4 != 0 {
        let ext = u32_at(&recs.data, *pos).ok_or_else(|| recs.malformed("a shared string's phonetic size is cut"))?;
        let ext = usize::try_from(i32::from_le_bytes(ext.to_le_bytes()))
            .map_err(|_| recs.malformed("a shared string's phonetic size is negative"))?;
        after = after.saturating_add(ext);
        *pos += 4;
    }
    let (mut left, mut wide) = (usize::from(cch), flags & 1 != 0);
    loop {
        let (n, took) = biff8_text(recs.data.get(*pos..).unwrap_or_default(), left, wide, &mut out.text);
        *pos += took;
        left -= n;
        if left == 0 {
            break;
        }
        if out.text.len() > MAX_STRING_TEXT {
            return Err(XlsRowsError::TooMuchText);
        }
        if !recs.next_continue()? {
            return Err(recs.malformed("a shared string runs past the last Continue record"));
        }
        let Some(&f) = recs.data.first() else {
            return Err(recs.malformed("a Continue record inside a shared string has no flags byte"));
        };
        (wide, *pos) = (f & 1 != 0, 1);
    }
    out.end()?;
    // The rich-text runs and phonetic data: skipped, into `Continue` records if they go on.
    while after > 0 {
        if *pos >= recs.data.len() {
            if !recs.next_continue()? {
                return Err(recs.malformed("a shared string's formatting runs past the last Continue record"));
            }
            *pos = 0;
            continue;
        }
        let n = after.min(recs.data.len() - *pos);
        (*pos, after) = (*pos + n, after - n);
    }
    Ok(())
}

/// The `SST` record held in `recs` and the `Continue` records after it.
pub(super) fn shared_strings<R: Read>(recs: &mut Records<R>, out: &mut Strings) -> Result<(), XlsRowsError> {
    if recs.data.len() < 8 {
        return Err(recs.malformed("shorter than its two 4-byte counts"));
    }
    let mut pos = 8;
    loop {
        if pos >= recs.data.len() {
            if !recs.next_continue()? {
                return Ok(());
            }
            // A `Continue` record of no bytes is an empty string, as the workbook reader has it.
            pos = 0;
        }
        shared_string(recs, &mut pos, out)?;
    }
}
