//! XLS workbooks, read by our own record reader (`xls_rows.rs`) from the workbook stream's
//! pieces of the file.

use std::io::Read as _;
use std::ops::ControlFlow;
use std::path::Path;

use anyhow::Context as _;
use mbtap_device::profile::import::xls_container::WorkbookStream;
use mbtap_device::profile::import::xls_rows::XlsBook;

use super::{MAX_FILE_BYTES, WorkbookRows, too_big};

/// The compound-file signature an XLS starts with ([MS-CFB] 2.2, the header's `Signature`).
const CFB_MAGIC: [u8; 8] = [0xD0, 0xCF, 0x11, 0xE0, 0xA1, 0xB1, 0x1A, 0xE1];

/// Whether `path` starts as a compound file does (an XLS workbook).
pub(super) fn is_compound(path: &Path) -> bool {
    let mut magic = [0u8; 8];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut magic)).is_ok() && magic == CFB_MAGIC
}

/// An XLS workbook's sheet `sheet` (by name), or its first, read by our own reader
/// (`xls_rows.rs`): the container is read whole once to find where the workbook stream lies
/// (then let go), the globals once — sheet names and offsets, the shared strings, kept — and
/// the sheet's records from the file at each pass (calamine laid every sheet out
/// densely when it opened the file, 8.7× a 4.4 MB sheet; cells at A1 and IV65536 took 1 GB).
pub(super) fn open_xls(path: &Path, sheet: Option<&str>) -> anyhow::Result<WorkbookRows> {
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

/// One pass over sheet `sheet` of the XLS at `path`: the cells past the last column kept.
pub(super) fn each_row(
    path: &Path,
    stream: &WorkbookStream,
    book: &XlsBook,
    sheet: usize,
    each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>,
) -> anyhow::Result<u64> {
    let read = with_xls_stream(path, stream, |r| {
        mbtap_device::profile::import::xls_rows::parse_xls_rows(r, book, sheet, each)
    })?
    .map_err(|e| xls_error(path, &e))?;
    Ok(read.cut_cells)
}
