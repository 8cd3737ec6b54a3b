//! A CSV sheet's rows, streamed from its file at each of the sheet reader's passes.

use std::io::{BufRead as _, Read as _};
use std::ops::ControlFlow;
use std::path::Path;

use anyhow::Context as _;
use mbtap_device::profile::import::grid::{MAX_COLUMNS, MAX_ROWS};
use mbtap_device::profile::import::sheet::SheetRows;

use super::encoding::{Encoding, Utf16ToUtf8, detect, windows_1252};
use super::{MAX_FILE_BYTES, too_big};

/// A CSV file's rows, streamed from the file at each pass (the delimiter sniffed: `,`, `;` or
/// tab; the encoding found from the whole file: UTF-8, UTF-16 by its mark, else Windows-1252 —
/// [`super::encoding`]): nothing but the record being read is held (the file read whole and laid
/// out in a grid took 3.5× the file).
#[derive(Debug)]
pub struct CsvRows {
    path: std::path::PathBuf,
    delimiter: u8,
    cut_cells: u64,
    /// The file's length, and whether its last byte ends a line (else its last record has no
    /// terminator of its own).
    len: u64,
    ends_with_newline: bool,
    encoding: Encoding,
}

impl CsvRows {
    /// What to tell the user of the file's encoding (`None`: UTF-8).
    #[must_use]
    pub const fn encoding_note(&self) -> Option<&'static str> {
        self.encoding.note()
    }
}

/// The rows of the CSV file at `path`, checked for size and its delimiter sniffed.
///
/// # Errors
/// The file cannot be read, or is over [`MAX_FILE_BYTES`].
pub fn csv_rows(path: &Path) -> anyhow::Result<CsvRows> {
    let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
    let len = file.metadata().with_context(|| format!("reading {}", path.display()))?.len();
    if len > MAX_FILE_BYTES {
        return Err(too_big(path, &format!("{len} bytes, over the {MAX_FILE_BYTES} a sheet may have")));
    }
    // The delimiter the first lines use most: European sheets use `;` (the comma is their
    // decimal point), exports from databases tabs.
    let encoding = detect(std::io::BufReader::new(&file).take(MAX_FILE_BYTES))
        .with_context(|| format!("reading {}", path.display()))?;
    let mut head = Vec::new();
    let opened = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
    match encoding {
        Encoding::Utf16Le | Encoding::Utf16Be => {
            // Past the mark, as text: the delimiters are sniffed in characters, not bytes.
            let mut raw = opened.take(128 << 10);
            let mut mark = [0u8; 2];
            raw.read_exact(&mut mark).with_context(|| format!("reading {}", path.display()))?;
            Utf16ToUtf8::new(raw, encoding == Encoding::Utf16Be)
                .read_to_end(&mut head)
                .with_context(|| format!("reading {}", path.display()))?;
        }
        Encoding::Utf8 | Encoding::Windows1252 => {
            opened.take(64 << 10).read_to_end(&mut head).with_context(|| format!("reading {}", path.display()))?;
        }
    }
    let lines: Vec<&[u8]> = head.split(|&b| b == b'\n').take(20).collect();
    // A sniff over at most 20 lines: counting byte by byte is fine here.
    #[allow(clippy::naive_bytecount)]
    let count = |d: u8| lines.iter().map(|l| l.iter().filter(|&&b| b == d).count()).sum::<usize>();
    let delimiter = [b',', b';', b'\t'].into_iter().max_by_key(|&d| count(d)).unwrap_or(b',');
    let mut last = [0u8];
    let ends_with_newline = len > 0 && {
        use std::os::unix::fs::FileExt as _;
        let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
        file.read_exact_at(&mut last, len - 1).is_ok() && last[0] == b'\n'
    };
    Ok(CsvRows { path: path.to_owned(), delimiter, cut_cells: 0, len, ends_with_newline, encoding })
}

impl SheetRows for CsvRows {
    type Error = anyhow::Error;

    fn each_row(&mut self, each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>) -> anyhow::Result<()> {
        let path = &self.path;
        let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
        let mut raw = std::io::BufReader::new(file.take(MAX_FILE_BYTES + 1));
        let mut data_len = self.len;
        let input: Box<dyn std::io::Read> = match self.encoding {
            Encoding::Utf16Le | Encoding::Utf16Be => {
                // The mark is not text. The decoded length is not the file's: where the last
                // record ends is told by the file's own last byte (a newline either way).
                raw.consume(2);
                data_len = u64::MAX;
                Box::new(Utf16ToUtf8::new(raw, self.encoding == Encoding::Utf16Be))
            }
            Encoding::Utf8 | Encoding::Windows1252 => {
                // A byte-order mark is not part of the first cell.
                if raw.fill_buf().with_context(|| format!("reading {}", path.display()))?.starts_with(b"\xEF\xBB\xBF") {
                    raw.consume(3);
                    data_len -= 3;
                }
                Box::new(raw)
            }
        };
        let latin = self.encoding == Encoding::Windows1252;
        let mut reader =
            csv::ReaderBuilder::new().has_headers(false).flexible(true).delimiter(self.delimiter).from_reader(input);
        let mut record = csv::ByteRecord::new();
        let (mut next, mut cut) = (0usize, 0u64);
        loop {
            if !reader.read_byte_record(&mut record).with_context(|| format!("{}: row {}", path.display(), next + 1))? {
                break;
            }
            // The reader skips blank lines, and a spreadsheet shows each as a row: problems name
            // rows as it shows them. The record's first line is found from where the reader now
            // is, less the lines the record itself spans (its terminator, and line breaks inside
            // quoted cells).
            let after = usize::try_from(reader.position().line()).unwrap_or(usize::MAX);
            // A record is one row of a sheet: counting its bytes one by one is fine here.
            #[allow(clippy::naive_bytecount)]
            let inner = record.as_slice().iter().filter(|&&b| b == b'\n').count();
            let ended = reader.position().byte() < data_len || self.ends_with_newline;
            let first_line = after.saturating_sub(inner + usize::from(ended));
            let i = first_line.saturating_sub(1).max(next);
            next = i.saturating_add(1);
            if i >= MAX_ROWS {
                return Err(too_big(path, &format!("at record {}: more than {MAX_ROWS} rows", i + 1)));
            }
            cut += u64::try_from(record.len().saturating_sub(MAX_COLUMNS)).unwrap_or(u64::MAX);
            let text: Vec<std::borrow::Cow<'_, str>> =
                record
                    .iter()
                    .take(MAX_COLUMNS)
                    .map(|cell| {
                        if latin { std::borrow::Cow::Owned(windows_1252(cell)) } else { String::from_utf8_lossy(cell) }
                    })
                    .collect();
            // Trailing empty cells are not part of the row (as a workbook's padding is not).
            let kept = text.iter().rposition(|c| !c.trim().is_empty()).map_or(0, |k| k + 1);
            let cells: Vec<&str> = text.iter().take(kept).map(AsRef::as_ref).collect();
            if each(i, &cells).is_break() {
                return Ok(());
            }
        }
        self.cut_cells = cut;
        Ok(())
    }

    fn cut_cells(&self) -> u64 {
        self.cut_cells
    }
}
