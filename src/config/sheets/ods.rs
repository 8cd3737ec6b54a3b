//! OpenDocument and zip-based workbooks: the zip checked before anything is unpacked, an ODS
//! sheet's rows streamed from its `content.xml` by our own row reader at each pass (issue 39).

use std::io::Read as _;
use std::ops::ControlFlow;
use std::path::Path;

use anyhow::Context as _;

use super::{MAX_UNPACKED_BYTES, too_big};

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

/// Refuses a zip-based workbook before anything reads it: one that unpacks past
/// [`MAX_UNPACKED_BYTES`], or whose OpenDocument repeats expand past their bounds
/// ([`check_ods`]: our row reader hands on every repeat, calamine lays them out); then says
/// whether it is an OpenDocument spreadsheet, for our row reader. The zip's directory is read
/// once for all three.
pub(super) fn check_zip(path: &Path) -> anyhow::Result<bool> {
    let Ok(file) = std::fs::File::open(path) else { return Ok(false) };
    // Not a zip (XLS is not): nothing to check here.
    let Ok(mut zip) = zip::ZipArchive::new(std::io::BufReader::new(file)) else { return Ok(false) };
    check_unpacked(path, &mut zip)?;
    check_ods(path, &mut zip)?;
    Ok(is_ods(&mut zip))
}

/// Refuses a zip-based workbook whose parts unpack to more than [`MAX_UNPACKED_BYTES`]: first by
/// the sizes its central directory declares, then by inflating every part and counting what
/// comes out — the headers are claims, and a part that says 1 000 bytes may inflate to 512 MiB
/// (the workbook reader would hold all of it). Inflating stops at the budget: memory stays flat.
fn check_unpacked<R: std::io::Read + std::io::Seek>(path: &Path, zip: &mut zip::ZipArchive<R>) -> anyhow::Result<()> {
    let mut declared = 0u64;
    for i in 0..zip.len() {
        let size = zip.by_index_raw(i).map_or(0, |f| f.size());
        declared = declared.saturating_add(size);
    }
    if declared > MAX_UNPACKED_BYTES {
        return Err(too_big(path, &format!("unpacks to {declared} bytes, over the {MAX_UNPACKED_BYTES} read")));
    }
    let mut total = 0u64;
    for i in 0..zip.len() {
        let Ok(part) = zip.by_index(i) else { continue };
        let (name, says) = (part.name().to_owned(), part.size());
        let left = MAX_UNPACKED_BYTES.saturating_sub(total);
        // A part that cannot be inflated is the workbook reader's to report.
        let got = std::io::copy(&mut part.take(left.saturating_add(1)), &mut std::io::sink()).unwrap_or(0);
        total = total.saturating_add(got);
        if total > MAX_UNPACKED_BYTES {
            return Err(too_big(
                path,
                &format!(
                    "its part {name:?} says {says} bytes but inflates past the {MAX_UNPACKED_BYTES} bytes read (the zip's sizes are not what it holds)"
                ),
            ));
        }
    }
    Ok(())
}

/// Whether the zip is an OpenDocument spreadsheet (its `mimetype` part says so, ODF v1.2 part 3
/// §3.3): read by our own row reader, never opened by calamine, which expands every table of
/// the file into memory (~66 bytes a cell).
fn is_ods<R: std::io::Read + std::io::Seek>(zip: &mut zip::ZipArchive<R>) -> bool {
    let Ok(part) = zip.by_name("mimetype") else { return false };
    let mut kind = String::new();
    part.take(256).read_to_string(&mut kind).is_ok() && kind.trim() == "application/vnd.oasis.opendocument.spreadsheet"
}

/// One pass over the ODS at `path`'s sheet `sheet` (or its first): the cells past the last
/// column kept.
pub(super) fn each_row(
    path: &Path,
    sheet: Option<&str>,
    each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>,
) -> anyhow::Result<u64> {
    let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
    let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file))
        .with_context(|| format!("{}: reading the OpenDocument file", path.display()))?;
    let content = zip.by_name("content.xml").with_context(|| format!("{}: no content.xml", path.display()))?;
    let read = mbtap_device::profile::import::ods_rows::parse_ods_rows(
        std::io::BufReader::new(content.take(MAX_UNPACKED_BYTES)),
        sheet,
        each,
    )
    .map_err(|e| too_big_or(path, &e))?;
    Ok(read.cut_cells)
}

/// An OpenDocument sheet's rows could not be read: over a bound (what to do said), or why not.
fn too_big_or(path: &Path, e: &mbtap_device::profile::import::ods_rows::OdsRowsError) -> anyhow::Error {
    use mbtap_device::profile::import::ods_rows::OdsRowsError;
    match e {
        OdsRowsError::TooManyRows(_) => too_big(path, &e.to_string()),
        _ => anyhow::anyhow!("{}: {e}", path.display()),
    }
}
