//! Spreadsheets read into rows of text: CSV (the delimiter sniffed: `,`, `;` or tab; bytes that
//! are not UTF-8 kept as replacement characters) and XLSX/XLS/ODS through calamine — row and
//! column numbers as the spreadsheet shows them, so a problem's "row 7, column C" is where the
//! user looks.
//!
//! Bounded before anything is allocated (issue 39): a CSV over [`MAX_FILE_BYTES`] or a workbook
//! that unpacks to more than [`MAX_UNPACKED_BYTES`] is refused unread; cells go into a compact
//! [`Grid`] with its own row, column and text bounds; an XLSX sheet is read cell by cell, so a
//! cell placed at XFD1048576 costs one cell, not a dense range of 17 billion.

use std::io::{BufRead as _, Read as _};
use std::ops::ControlFlow;
use std::path::Path;

use anyhow::Context as _;
use calamine::{Data, DataRef, Reader as _};
use mbtap_device::profile::import::grid::{Grid, MAX_COLUMNS, MAX_ROWS};
use mbtap_device::profile::import::sheet::SheetRows;

/// The largest CSV read (64 MiB; the largest register sheet — every address of four tables at
/// 200 bytes a row — is ~52 MB).
pub const MAX_FILE_BYTES: u64 = 64 << 20;
/// The most a workbook may unpack to, all its parts together (a zip bomb is refused by its
/// directory before anything is unpacked).
pub const MAX_UNPACKED_BYTES: u64 = 128 << 20;

/// The largest Home Assistant YAML read (32 MiB: twice a file naming every address of two tables;
/// a real `modbus:` configuration is kilobytes). The import holds ~6 bytes per byte of YAML (the
/// reader streams; the entries read and their problems remain): 193 MB for a 32.9 MB file.
pub const MAX_YAML_BYTES: u64 = 32 << 20;

/// A Home Assistant YAML file read into `out`, streamed twice (its nesting, then its entries),
/// refused unread past [`MAX_YAML_BYTES`] (issue 39: a 200 MB file of nested mappings was read
/// whole before anything looked at it). Returns the device read.
///
/// # Errors
/// The file cannot be read, is too big, or is not a Home Assistant configuration.
pub fn read_yaml(
    path: &Path,
    unit: Option<u8>,
    out: &mut impl mbtap_device::profile::import::Sink,
) -> anyhow::Result<u8> {
    let open = || -> anyhow::Result<std::io::Take<std::fs::File>> {
        let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
        let len = file.metadata().with_context(|| format!("reading {}", path.display()))?.len();
        anyhow::ensure!(
            len <= MAX_YAML_BYTES,
            "{}: {len} bytes, over the {MAX_YAML_BYTES} a Home Assistant `modbus:` file may have; give only the `modbus:` part",
            path.display()
        );
        Ok(file.take(MAX_YAML_BYTES))
    };
    let depth = std::io::BufReader::new(open()?);
    let yaml = std::io::BufReader::new(open()?);
    mbtap_device::profile::import::home_assistant::read_home_assistant_from(depth, yaml, unit, out)
        .with_context(|| format!("reading {}", path.display()))
}

/// Said when a sheet is over a bound: which, and what to do.
fn too_big(path: &Path, what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{}: {what}; a register sheet is far smaller — export only the register table (or give --sheet), or split it",
        path.display()
    )
}

/// A CSV file's rows, streamed from the file at each pass (the delimiter sniffed: `,`, `;` or
/// tab; bytes that are not UTF-8 kept as replacement characters): nothing but the record being
/// read is held (issue 39: the file read whole and laid out in a grid took 3.5× the file).
#[derive(Debug)]
pub struct CsvRows {
    path: std::path::PathBuf,
    delimiter: u8,
    cut_cells: u64,
    /// The file's length, and whether its last byte ends a line (else its last record has no
    /// terminator of its own).
    len: u64,
    ends_with_newline: bool,
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
    let mut head = Vec::new();
    file.take(64 << 10).read_to_end(&mut head).with_context(|| format!("reading {}", path.display()))?;
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
    Ok(CsvRows { path: path.to_owned(), delimiter, cut_cells: 0, len, ends_with_newline })
}

impl SheetRows for CsvRows {
    type Error = anyhow::Error;

    fn each_row(&mut self, each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>) -> anyhow::Result<()> {
        let path = &self.path;
        let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
        let mut input = std::io::BufReader::new(file.take(MAX_FILE_BYTES + 1));
        // A byte-order mark is not part of the first cell.
        let mut data_len = self.len;
        if input.fill_buf().with_context(|| format!("reading {}", path.display()))?.starts_with(b"\xEF\xBB\xBF") {
            input.consume(3);
            data_len -= 3;
        }
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
                record.iter().take(MAX_COLUMNS).map(String::from_utf8_lossy).collect();
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

/// The most cells an OpenDocument workbook may expand to when opened, the cells read and the
/// used areas laid out together (all its tables: the reader expands every one at opening).
/// Measured: ~66 bytes of memory per cell (a 1 048 003-row area of 3 columns, 207 MB), so this
/// keeps an opening under ~210 MB; a register sheet of 263 168 rows × 5 columns is ~2.6 M.
pub const MAX_ODS_CELLS: u64 = 3 << 20;
/// The most cell text an OpenDocument workbook may expand to (repeated cells copy their text).
pub const MAX_ODS_TEXT: u64 = 64 << 20;

/// Refuses an OpenDocument workbook whose repeated rows and cells expand past
/// [`MAX_ODS_CELLS`] or [`MAX_ODS_TEXT`], counted from its `content.xml` streamed (issue 39: an
/// 873-byte workbook expanded past 17 GB while being opened).
fn check_ods<R: std::io::Read + std::io::Seek>(path: &Path, zip: &mut zip::ZipArchive<R>) -> anyhow::Result<()> {
    use mbtap_device::profile::import::ods_size::parse_ods_size;
    // Not an OpenDocument file: nothing to count here.
    let Ok(content) = zip.by_name("content.xml") else { return Ok(()) };
    let size = parse_ods_size(std::io::BufReader::new(content.take(MAX_UNPACKED_BYTES)))
        .with_context(|| format!("{}: reading the sheet", path.display()))?;
    let cells = size.cells_read.saturating_add(size.area_cells);
    if cells > MAX_ODS_CELLS || size.text_bytes > MAX_ODS_TEXT {
        let largest = size
            .largest
            .map(|(name, rows, cols)| format!(" (the largest, {name:?}: {rows} rows × {cols} columns)"))
            .unwrap_or_default();
        return Err(too_big(
            path,
            &format!(
                "its repeated rows and cells expand to {cells} cells and {} bytes of text{largest}, over the {MAX_ODS_CELLS} cells and {MAX_ODS_TEXT} bytes read from an OpenDocument sheet",
                size.text_bytes
            ),
        ));
    }
    Ok(())
}

/// The compound-file signature an XLS starts with ([MS-CFB] 2.2, the header's `Signature`).
const CFB_MAGIC: [u8; 8] = [0xD0, 0xCF, 0x11, 0xE0, 0xA1, 0xB1, 0x1A, 0xE1];

/// Whether `path` starts as a compound file does (an XLS workbook).
fn is_compound(path: &Path) -> bool {
    let mut magic = [0u8; 8];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut magic)).is_ok() && magic == CFB_MAGIC
}

/// An XLS workbook's sheet `sheet` (by name), or its first, read by our own reader
/// (`xls_rows.rs`): the container is read whole once to find where the workbook stream lies
/// (then let go), the globals once — sheet names and offsets, the shared strings, kept — and
/// the sheet's records from the file at each pass (issue 39: calamine laid every sheet out
/// densely when it opened the file, 8.7× a 4.4 MB sheet; cells at A1 and IV65536 took 1 GB).
fn open_xls(path: &Path, sheet: Option<&str>) -> anyhow::Result<WorkbookRows> {
    use mbtap_device::profile::import::xls_container::parse_xls_stream;
    use mbtap_device::profile::import::xls_rows::parse_xls_book;
    let len = std::fs::metadata(path).with_context(|| format!("reading {}", path.display()))?.len();
    if len > MAX_FILE_BYTES {
        return Err(too_big(path, &format!("{len} bytes, over the {MAX_FILE_BYTES} a sheet may have")));
    }
    let stream = {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        parse_xls_stream(&bytes)
            .with_context(|| format!("{}: not a compound file a workbook can be read from", path.display()))?
    };
    let book = with_xls_stream(path, &stream, |r| parse_xls_book(std::io::BufReader::new(r)))
        .and_then(|read| read.map_err(|e| xls_error(path, &e)))?;
    let names = || book.sheets.iter().map(|s| s.name.as_str()).collect::<Vec<_>>().join(", ");
    let index = match sheet {
        Some(s) => book
            .sheets
            .iter()
            .position(|n| n.name.eq_ignore_ascii_case(s))
            .with_context(|| format!("{}: no sheet {s:?} (it has: {})", path.display(), names()))?,
        None if book.sheets.is_empty() => anyhow::bail!("{}: no sheets", path.display()),
        None => 0,
    };
    Ok(WorkbookRows::Xls { path: path.to_owned(), stream, book, sheet: index, cut_cells: 0 })
}

/// Runs `read` on the workbook stream of the XLS at `path`, lying where `stream` says.
fn with_xls_stream<T>(
    path: &Path,
    stream: &mbtap_device::profile::import::xls_container::WorkbookStream,
    read: impl FnOnce(&mut dyn ReadSeek) -> T,
) -> anyhow::Result<T> {
    use mbtap_device::profile::import::xls_container::{StreamReader, WorkbookStream};
    Ok(match stream {
        WorkbookStream::Held(bytes) => read(&mut std::io::Cursor::new(bytes.as_slice())),
        WorkbookStream::InFile(pieces) => {
            let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
            read(&mut StreamReader::new(std::io::BufReader::new(file), pieces))
        }
    })
}

/// What the XLS reader reads from.
trait ReadSeek: std::io::Read + std::io::Seek {}
impl<T: std::io::Read + std::io::Seek> ReadSeek for T {}

/// An XLS sheet could not be read: over a bound (what to do said), or why not and what to do.
fn xls_error(path: &Path, e: &mbtap_device::profile::import::xls_rows::XlsRowsError) -> anyhow::Error {
    use mbtap_device::profile::import::xls_rows::XlsRowsError;
    match e {
        XlsRowsError::TooManyRows(_) | XlsRowsError::TooMuchText => too_big(path, &e.to_string()),
        XlsRowsError::Password => {
            anyhow::anyhow!("{}: {e}; save it without a password, or export the register table as CSV", path.display())
        }
        _ => anyhow::anyhow!(
            "{}: {e}: a malformed record; open the file in a spreadsheet and save it again, or export the register table as CSV",
            path.display()
        ),
    }
}

/// Refuses a zip-based workbook before the reader opens it: one that unpacks past
/// [`MAX_UNPACKED_BYTES`], or an OpenDocument one whose repeats expand past its bounds
/// ([`check_ods`]).
fn check_zip(path: &Path) -> anyhow::Result<()> {
    let Ok(file) = std::fs::File::open(path) else { return Ok(()) };
    // Not a zip (XLS is not): nothing to check here.
    let Ok(mut zip) = zip::ZipArchive::new(std::io::BufReader::new(file)) else { return Ok(()) };
    check_unpacked(path, &mut zip)?;
    check_ods(path, &mut zip)
}

/// Refuses a zip-based workbook whose parts unpack to more than [`MAX_UNPACKED_BYTES`], by its
/// central directory (the sizes it declares; the reader stops at them).
fn check_unpacked<R: std::io::Read + std::io::Seek>(path: &Path, zip: &mut zip::ZipArchive<R>) -> anyhow::Result<()> {
    let mut total = 0u64;
    for i in 0..zip.len() {
        let size = zip.by_index_raw(i).map_or(0, |f| f.size());
        total = total.saturating_add(size);
    }
    if total > MAX_UNPACKED_BYTES {
        return Err(too_big(path, &format!("unpacks to {total} bytes, over the {MAX_UNPACKED_BYTES} read")));
    }
    Ok(())
}

/// A cell as text: whole numbers without `.0`, as the sheet shows them.
fn cell_text(d: &Data) -> String {
    match d {
        Data::Empty => String::new(),
        Data::String(s) | Data::DateTimeIso(s) | Data::DurationIso(s) => s.clone(),
        Data::Int(i) => i.to_string(),
        Data::Float(f) => mbtap_device::profile::import::grid::number_text(*f),
        Data::Bool(b) => b.to_string(),
        Data::DateTime(t) => t.as_f64().to_string(),
        Data::Error(e) => format!("#{e:?}"),
    }
}

/// A cell read by the streaming XLSX reader as text, like [`cell_text`].
fn cell_ref_text(d: &DataRef<'_>) -> String {
    match d {
        DataRef::SharedString(s) => (*s).to_owned(),
        DataRef::String(s) | DataRef::DateTimeIso(s) | DataRef::DurationIso(s) => s.clone(),
        DataRef::Int(i) => cell_text(&Data::Int(*i)),
        DataRef::Float(f) => cell_text(&Data::Float(*f)),
        DataRef::Bool(b) => b.to_string(),
        DataRef::DateTime(t) => t.as_f64().to_string(),
        DataRef::Error(e) => format!("#{e:?}"),
        DataRef::Empty => String::new(),
    }
}

/// [`rows_from_cells`] with a row past [`MAX_ROWS`] said about `path`.
fn rows_from_cells(
    path: &Path,
    next: impl FnMut() -> anyhow::Result<Option<(u32, u32, String)>>,
    each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>,
) -> anyhow::Result<u64> {
    mbtap_device::profile::import::cell_rows::rows_from_cells(next, each, |r| {
        too_big(path, &format!("a cell at row {} (over {MAX_ROWS} rows)", r + 1))
    })
}

/// A workbook's sheet as rows: XLSX and XLSB read from the file cell by cell at each pass (the
/// rows are never held: issue 39), XLS and ODS — which the reader lays out whole when it opens
/// them, bounded by the checks before — as a grid.
#[derive(Debug)]
pub enum WorkbookRows {
    Cells {
        path: std::path::PathBuf,
        sheet: String,
        cut_cells: u64,
    },
    /// An XLS workbook: where its workbook stream lies, its globals, and the sheet read
    /// from the stream at each pass.
    Xls {
        path: std::path::PathBuf,
        stream: mbtap_device::profile::import::xls_container::WorkbookStream,
        book: mbtap_device::profile::import::xls_rows::XlsBook,
        sheet: usize,
        cut_cells: u64,
    },
    /// An OpenDocument spreadsheet's `content.xml`, streamed at each pass.
    Ods {
        path: std::path::PathBuf,
        sheet: Option<String>,
        cut_cells: u64,
    },
    Grid(Grid),
}

/// Runs `read` with the workbook reader's panics turned into an error about `path`: the reader
/// indexes some records without checking their length (an XLS `BOF` or `CodePage` of fewer than
/// 2 bytes panics it). Its panic message is kept out of the output.
fn guarded<T>(path: &Path, read: impl FnOnce() -> anyhow::Result<T>) -> anyhow::Result<T> {
    let quiet = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(read));
    std::panic::set_hook(quiet);
    result.unwrap_or_else(|_| {
        Err(anyhow::anyhow!(
            "{}: the workbook reader failed on a malformed record; open the file in a spreadsheet and save it again, or export the register table as CSV",
            path.display()
        ))
    })
}

/// The rows of a workbook's sheet `sheet` (by name), or its first.
///
/// # Errors
/// The workbook cannot be opened, unpacks to more than [`MAX_UNPACKED_BYTES`], is over the
/// grid's bounds, or has no such sheet (the ones it has are named).
pub fn read_workbook(path: &Path, sheet: Option<&str>) -> anyhow::Result<WorkbookRows> {
    if is_compound(path) {
        return open_xls(path, sheet);
    }
    check_zip(path)?;
    if is_ods(path) {
        return Ok(WorkbookRows::Ods { path: path.to_owned(), sheet: sheet.map(str::to_owned), cut_cells: 0 });
    }
    guarded(path, || open_sheet(path, sheet))
}

/// Whether `path` is an OpenDocument spreadsheet (its `mimetype` part says so, ODF v1.2 part 3
/// §3.3): read by our own row reader, never opened by calamine, which expands every table of
/// the file into memory (~66 bytes a cell).
fn is_ods(path: &Path) -> bool {
    let Ok(file) = std::fs::File::open(path) else { return false };
    let Ok(mut zip) = zip::ZipArchive::new(std::io::BufReader::new(file)) else { return false };
    let Ok(part) = zip.by_name("mimetype") else { return false };
    let mut kind = String::new();
    part.take(256).read_to_string(&mut kind).is_ok() && kind.trim() == "application/vnd.oasis.opendocument.spreadsheet"
}

/// The workbook at `path` and the name of its sheet `sheet` (by name), or of its first.
fn open_named(
    path: &Path,
    sheet: Option<&str>,
) -> anyhow::Result<(calamine::Sheets<std::io::BufReader<std::fs::File>>, String)> {
    let wb = calamine::open_workbook_auto(path).with_context(|| format!("opening {}", path.display()))?;
    let names = wb.sheet_names();
    let name = match sheet {
        Some(s) => names
            .iter()
            .find(|n| n.eq_ignore_ascii_case(s))
            .cloned()
            .with_context(|| format!("{}: no sheet {s:?} (it has: {})", path.display(), names.join(", ")))?,
        None => names.first().cloned().with_context(|| format!("{}: no sheets", path.display()))?,
    };
    Ok((wb, name))
}

/// [`read_workbook`] past its checks.
fn open_sheet(path: &Path, sheet: Option<&str>) -> anyhow::Result<WorkbookRows> {
    let (mut wb, name) = open_named(path, sheet)?;
    if matches!(wb, calamine::Sheets::Xlsx(_) | calamine::Sheets::Xlsb(_)) {
        return Ok(WorkbookRows::Cells { path: path.to_owned(), sheet: name, cut_cells: 0 });
    }
    // XLS and ODS have no cell-by-cell reader: their range is read whole, bounded by what
    // their records lay out (counted before opening).
    let range = wb.worksheet_range(&name).with_context(|| format!("{}: reading sheet {name:?}", path.display()))?;
    // The range starts at its first used cell; pad so rows and columns are the sheet's own.
    let (row0, col0) = range.start().map_or((0, 0), |(r, c)| (r as usize, c as usize));
    if row0.saturating_add(range.height()) > MAX_ROWS {
        return Err(too_big(path, &format!("{} rows, over {MAX_ROWS}", row0.saturating_add(range.height()))));
    }
    let mut grid = Grid::new();
    for _ in 0..row0 {
        grid.push_row(std::iter::empty::<&str>()).map_err(|e| too_big(path, &e.to_string()))?;
    }
    for r in range.rows() {
        let cells = std::iter::repeat_n(String::new(), col0.min(MAX_COLUMNS)).chain(r.iter().map(cell_text));
        grid.push_row(cells).map_err(|e| too_big(path, &e.to_string()))?;
    }
    Ok(WorkbookRows::Grid(grid))
}

impl SheetRows for WorkbookRows {
    type Error = anyhow::Error;

    fn each_row(&mut self, each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>) -> anyhow::Result<()> {
        let (path, sheet, cut_cells) = match self {
            Self::Grid(g) => {
                return match g.each_row(each) {
                    Ok(()) => Ok(()),
                    Err(never) => match never {},
                };
            }
            Self::Ods { path, sheet, cut_cells } => {
                let file = std::fs::File::open(&*path).with_context(|| format!("reading {}", path.display()))?;
                let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file))
                    .with_context(|| format!("{}: reading the OpenDocument file", path.display()))?;
                let content =
                    zip.by_name("content.xml").with_context(|| format!("{}: no content.xml", path.display()))?;
                let read = mbtap_device::profile::import::ods_rows::parse_ods_rows(
                    std::io::BufReader::new(content.take(MAX_UNPACKED_BYTES)),
                    sheet.as_deref(),
                    each,
                )
                .map_err(|e| too_big_or(path, &e))?;
                *cut_cells = read.cut_cells;
                return Ok(());
            }
            Self::Xls { path, stream, book, sheet, cut_cells } => {
                let read = with_xls_stream(path, stream, |r| {
                    mbtap_device::profile::import::xls_rows::parse_xls_rows(r, book, *sheet, each)
                })?
                .map_err(|e| xls_error(path, &e))?;
                *cut_cells = read.cut_cells;
                return Ok(());
            }
            Self::Cells { path, sheet, cut_cells } => (path, sheet, cut_cells),
        };
        let reading = || format!("{}: reading sheet {sheet:?}", path.display());
        let cut = guarded(path, || {
            let (mut wb, name) = open_named(path, Some(sheet))?;
            // XLSX and XLSB cell by cell: a cell at XFD1048576 costs one cell, not the dense
            // range of 17 billion the range reader lays out (a 1.6 kB XLSX aborted the process
            // on it). The two readers are different types with the same calls (calamine gives
            // them no trait).
            macro_rules! cell_by_cell {
                ($book:expr) => {{
                    let mut cells = $book.worksheet_cells_reader(&name).with_context(reading)?;
                    rows_from_cells(
                        path,
                        || {
                            let cell = cells.next_cell().with_context(reading)?;
                            Ok(cell.map(|c| (c.get_position().0, c.get_position().1, cell_ref_text(c.get_value()))))
                        },
                        each,
                    )
                }};
            }
            match &mut wb {
                calamine::Sheets::Xlsx(x) => cell_by_cell!(x),
                calamine::Sheets::Xlsb(x) => cell_by_cell!(x),
                _ => Err(anyhow::anyhow!("{}: not an XLSX or XLSB workbook any more", path.display())),
            }
        })?;
        *cut_cells = cut;
        Ok(())
    }

    fn cut_cells(&self) -> u64 {
        match self {
            Self::Grid(g) => g.cut_cells,
            Self::Cells { cut_cells, .. } | Self::Ods { cut_cells, .. } | Self::Xls { cut_cells, .. } => *cut_cells,
        }
    }
}

/// An OpenDocument sheet's rows could not be read: over a bound (what to do said), or why not.
fn too_big_or(path: &Path, e: &mbtap_device::profile::import::ods_rows::OdsRowsError) -> anyhow::Error {
    use mbtap_device::profile::import::ods_rows::OdsRowsError;
    match e {
        OdsRowsError::TooManyRows(_) => too_big(path, &e.to_string()),
        _ => anyhow::anyhow!("{}: {e}", path.display()),
    }
}
