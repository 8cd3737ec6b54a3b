//! Where an XLS file's workbook stream lies, and a reader of it: the stream is read
//! from its pieces of the file as one stream — never gathered beside the file — for
//! `xls_rows.rs` to read the sheet from, each pass.

use std::ops::Range;

/// Where an XLS file's workbook stream is: pieces of the file, in order (a stream of 4 096
/// bytes or more lives in regular sectors), or — a small one, from the mini stream — its bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WorkbookStream {
    InFile(Vec<Range<u64>>),
    Held(Vec<u8>),
}

impl WorkbookStream {
    /// The stream's length in bytes.
    #[must_use]
    pub fn len(&self) -> u64 {
        match self {
            Self::InFile(p) => p.iter().map(|r| r.end - r.start).sum(),
            Self::Held(b) => b.len() as u64,
        }
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A workbook stream lying in pieces of a file, read as one stream: reading and seeking it
/// reads and seeks the file, and pieces one after another are read without a seek (a
/// `BufReader` keeps its buffer).
#[derive(Debug)]
pub struct StreamReader<R> {
    inner: R,
    /// Each piece: where it starts in the stream, and its bytes in the file.
    pieces: Vec<(u64, Range<u64>)>,
    len: u64,
    pos: u64,
    /// Where `inner` is, when known.
    inner_pos: Option<u64>,
}

impl<R: std::io::Read + std::io::Seek> StreamReader<R> {
    /// The stream lying in `pieces` of `inner` (see [`WorkbookStream::InFile`]).
    #[must_use]
    pub fn new(inner: R, pieces: &[Range<u64>]) -> Self {
        let mut at = 0u64;
        let pieces = pieces
            .iter()
            .map(|r| {
                let start = at;
                at = at.saturating_add(r.end.saturating_sub(r.start));
                (start, r.clone())
            })
            .collect();
        Self { inner, pieces, len: at, pos: 0, inner_pos: None }
    }
}

impl<R: std::io::Read + std::io::Seek> std::io::Read for StreamReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        // The piece holding `pos`: the last one starting at or before it.
        let k = self.pieces.partition_point(|(start, _)| *start <= self.pos);
        let Some((start, range)) = k.checked_sub(1).and_then(|k| self.pieces.get(k)) else { return Ok(0) };
        let into = self.pos - start;
        let left = (range.end - range.start).saturating_sub(into);
        if left == 0 {
            return Ok(0);
        }
        let at = range.start + into;
        if self.inner_pos != Some(at) {
            self.inner.seek(std::io::SeekFrom::Start(at))?;
        }
        let want = buf.len().min(usize::try_from(left).unwrap_or(usize::MAX));
        let n = match self.inner.read(&mut buf[..want]) {
            Ok(n) => n,
            Err(e) => {
                self.inner_pos = None;
                return Err(e);
            }
        };
        self.pos += n as u64;
        self.inner_pos = Some(at + n as u64);
        Ok(n)
    }
}

impl<R: std::io::Read + std::io::Seek> std::io::Seek for StreamReader<R> {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        let pos = match to {
            std::io::SeekFrom::Start(p) => Some(p),
            std::io::SeekFrom::End(d) => self.len.checked_add_signed(d),
            std::io::SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = pos.ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "a seek before the workbook stream's start")
        })?;
        Ok(self.pos)
    }
}
