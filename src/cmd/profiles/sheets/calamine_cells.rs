//! XLSX and XLSB sheets read through calamine's cell reader at each pass (a cell at
//! XFD1048576 costs one cell, not a dense range), and what calamine opens otherwise — an ODS
//! without its `mimetype` — laid out as a grid, bounded.

use std::ops::ControlFlow;
use std::path::Path;

use anyhow::Context as _;
use calamine::{Data, DataRef, Reader as _};
use mbtap_device::profile::import::grid::{Grid, MAX_COLUMNS, MAX_ROWS};

use super::{WorkbookRows, too_big};

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

/// Runs `read` with the workbook reader's panics turned into an error about `path`: the reader
/// indexes some records without checking its input everywhere. Its panic message is kept out of the output.
pub(super) fn guarded<T>(path: &Path, read: impl FnOnce() -> anyhow::Result<T>) -> anyhow::Result<T> {
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
pub(super) fn open_sheet(path: &Path, sheet: Option<&str>) -> anyhow::Result<WorkbookRows> {
    let (mut wb, name) = open_named(path, sheet)?;
    if matches!(wb, calamine::Sheets::Xlsx(_) | calamine::Sheets::Xlsb(_)) {
        return Ok(WorkbookRows::Cells { path: path.to_owned(), sheet: name, cut_cells: 0 });
    }
    // What else calamine opens (an ODS without its `mimetype`) has no cell-by-cell reader: its
    // range is read whole, bounded by what its repeats expand to (counted before opening).
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

/// One pass over the XLSX or XLSB sheet `sheet` at `path`, cell by cell: the cells past the
/// last column kept.
pub(super) fn each_row(
    path: &Path,
    sheet: &str,
    each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>,
) -> anyhow::Result<u64> {
    let reading = || format!("{}: reading sheet {sheet:?}", path.display());
    guarded(path, || {
        let (mut wb, name) = open_named(path, Some(sheet))?;
        // XLSX and XLSB cell by cell: a cell at XFD1048576 costs one cell, not the dense
        // range of 17 billion the range reader lays out (enough to abort the process from a
        // 1.6 kB XLSX). The two readers are different types with the same calls (calamine gives
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
    })
}
