//! OpenDocument and zip-based workbooks: the zip checked before anything is unpacked, an ODS
//! sheet's rows streamed from its `content.xml` by our own row reader at each pass.

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
/// [`MAX_ODS_CELLS`] or [`MAX_ODS_TEXT`], counted from its `content.xml` streamed (an
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
        // What the workbook reader lays out in memory for each element: sheets, shared strings.
        let (tag, max, what): (Option<&[u8]>, u64, &str) = match name.to_ascii_lowercase().as_str() {
            "xl/workbook.xml" => (Some(b"sheet"), MAX_SHEETS, "its workbook names {n} sheets, over the {max} read"),
            "xl/sharedstrings.xml" => {
                (Some(b"si"), MAX_SHARED_STRINGS, "it holds {n} shared strings, over the {max} read")
            }
            _ => (None, u64::MAX, ""),
        };
        // A part that cannot be inflated is the workbook reader's to report.
        let (got, n) = inflate_counting(part.take(left.saturating_add(1)), tag);
        total = total.saturating_add(got);
        if n > max {
            let said = what.replace("{n}", &n.to_string()).replace("{max}", &max.to_string());
            return Err(too_big(path, &format!("{said} (each is held in memory when the workbook opens)")));
        }
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

/// The most sheets an XLSX workbook may name: the workbook reader lays out every sheet it names
/// when it opens (measured: 2.5 million sheets named in 12.7 MB took 574 MB). A register map
/// has a handful.
pub const MAX_SHEETS: u64 = 4096;

/// The most shared strings an XLSX may hold: the workbook reader keeps every one in memory when
/// it opens (measured: 7.4 million one-letter strings from a 307 kB file took 413 MB, ~55 bytes
/// a string), so this keeps them under ~55 MB; a 200 000-row register sheet with three texts a
/// row has 600 000.
pub const MAX_SHARED_STRINGS: u64 = 1_000_000;

/// Inflates `part` to nothing, counting its bytes and the start tags named `tag` in it (any
/// namespace prefix: `<x:sheet `; `<sheets>` and `<sheetView` are not `sheet`s).
fn inflate_counting(mut part: impl std::io::Read, tag: Option<&[u8]>) -> (u64, u64) {
    let (mut bytes, mut found) = (0u64, 0u64);
    let mut buf = vec![0u8; 64 * 1024];
    // The tail of the previous chunk, so an element cut by the read is still seen.
    let mut carry: Vec<u8> = Vec::new();
    loop {
        let n = match part.read(&mut buf) {
            Ok(0) | Err(_) => return (bytes, found),
            Ok(n) => n,
        };
        bytes = bytes.saturating_add(n as u64);
        let Some(tag) = tag else { continue };
        carry.extend_from_slice(buf.get(..n).unwrap_or_default());
        let (count, rest) = count_elements(&carry, tag);
        found += count;
        carry.drain(..rest);
    }
}

/// The longest element name looked at (prefix included); longer ones are no `tag`.
const MAX_NAME: usize = 64;

/// Start tags named `tag` in `text` (any prefix: `<x:si>`; `<si/>` too; `</si>` is an end tag),
/// and where the unread rest begins: a `<` whose name the text cuts is kept for the next read.
fn count_elements(text: &[u8], tag: &[u8]) -> (u64, usize) {
    let mut found = 0;
    let mut at = 0;
    while let Some(lt) = text.get(at..).and_then(|t| t.iter().position(|&b| b == b'<')).map(|p| p + at) {
        let name_from = lt + 1;
        let rest = text.get(name_from..).unwrap_or_default();
        let Some(len) =
            rest.iter().take(MAX_NAME).position(|&b| matches!(b, b' ' | b'>' | b'/' | b'\t' | b'\r' | b'\n'))
        else {
            if rest.len() < MAX_NAME {
                // The name goes on in the next read.
                return (found, lt);
            }
            at = name_from;
            continue;
        };
        let name = rest.get(..len).unwrap_or_default();
        if name.rsplit(|&b| b == b':').next() == Some(tag) {
            found += 1;
        }
        at = name_from + len;
    }
    (found, text.len())
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

#[cfg(test)]
mod sheet_count_tests {
    use super::inflate_counting;

    /// Reads `text` in pieces of `step` bytes, as an inflater hands them on.
    struct Pieces<'a>(&'a [u8], usize);

    impl std::io::Read for Pieces<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.1.min(self.0.len()).min(buf.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    #[test]
    fn sheets_are_counted_however_the_part_is_cut() {
        let wb = br#"<workbook><sheets><sheet name="A"/><x:sheet name="B"/><sheetView/></sheets></workbook>"#;
        for step in 1..wb.len() {
            assert_eq!(inflate_counting(Pieces(wb, step), Some(b"sheet")), (wb.len() as u64, 2), "pieces of {step}");
        }
        assert_eq!(inflate_counting(Pieces(wb, 4), None).1, 0, "nothing counted without a tag");
        let sst = b"<sst><si><t>a</t></si><x:si><t>b</t></x:si><si/><sig/></sst>";
        for step in 1..sst.len() {
            assert_eq!(inflate_counting(Pieces(sst, step), Some(b"si")).1, 3, "pieces of {step}");
        }
    }
}
