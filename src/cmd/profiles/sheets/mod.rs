//! Spreadsheets read into rows of text, one file per format: CSV (`csv.rs`), XLSX and XLSB through
//! calamine cell by cell (`calamine_cells.rs`), XLS and ODS by our own readers (`xls.rs`,
//! `ods.rs`), and Home Assistant YAML (`yaml.rs`) — row and column numbers as the spreadsheet
//! shows them, so a problem's "row 7, column C" is where the user looks.
//!
//! Bounded before anything is allocated: a CSV over [`MAX_FILE_BYTES`] or a workbook
//! that unpacks to more than [`MAX_UNPACKED_BYTES`] is refused unread; every sheet is streamed
//! row by row at each of the sheet reader's passes, nothing laid out, so a cell placed at
//! XFD1048576 costs one cell, not a dense range of 17 billion.
//!
//! `encoding` tells a text file's encoding as spreadsheets save it.

mod calamine_cells;
mod csv;
pub mod encoding;
mod ods;
mod xls;
mod yaml;

use std::ops::ControlFlow;
use std::path::Path;

use mbtap_device::profile::import::grid::Grid;
use mbtap_device::profile::import::sheet::SheetRows;

pub use csv::csv_rows;
pub use yaml::read_yaml;

/// The largest CSV read (64 MiB; the largest register sheet — every address of four tables at
/// 200 bytes a row — is ~52 MB).
pub const MAX_FILE_BYTES: u64 = 64 << 20;
/// The most a workbook may unpack to, all its parts together (a zip bomb is refused by its
/// directory before anything is unpacked).
pub const MAX_UNPACKED_BYTES: u64 = 128 << 20;

/// Said when a sheet is over a bound: which, and what to do.
fn too_big(path: &Path, what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{}: {what}; a register sheet is far smaller — export only the register table (or give --sheet), or split it",
        path.display()
    )
}

/// A workbook's sheet as rows: XLSX and XLSB read from the file cell by cell at each pass, XLS
/// and ODS by our own readers at each pass (the rows are never held); only a workbook
/// calamine opens some other way (an ODS without its `mimetype`) is laid out as a grid, bounded
/// by the checks before.
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

/// The rows of a workbook's sheet `sheet` (by name), or its first.
///
/// # Errors
/// The workbook cannot be opened, unpacks to more than [`MAX_UNPACKED_BYTES`], is over the
/// grid's bounds, or has no such sheet (the ones it has are named).
pub fn read_workbook(path: &Path, sheet: Option<&str>) -> anyhow::Result<WorkbookRows> {
    if xls::is_compound(path) {
        return xls::open_xls(path, sheet);
    }
    if ods::check_zip(path)? {
        return Ok(WorkbookRows::Ods { path: path.to_owned(), sheet: sheet.map(str::to_owned), cut_cells: 0 });
    }
    calamine_cells::guarded(path, || calamine_cells::open_sheet(path, sheet))
}

impl SheetRows for WorkbookRows {
    type Error = anyhow::Error;

    fn each_row(&mut self, each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>) -> anyhow::Result<()> {
        match self {
            Self::Grid(g) => match g.each_row(each) {
                Ok(()) => Ok(()),
                Err(never) => match never {},
            },
            Self::Ods { path, sheet, cut_cells } => {
                *cut_cells = ods::each_row(path, sheet.as_deref(), each)?;
                Ok(())
            }
            Self::Xls { path, stream, book, sheet, cut_cells } => {
                *cut_cells = xls::each_row(path, stream, book, *sheet, each)?;
                Ok(())
            }
            Self::Cells { path, sheet, cut_cells } => {
                *cut_cells = calamine_cells::each_row(path, sheet, each)?;
                Ok(())
            }
        }
    }

    fn cut_cells(&self) -> u64 {
        match self {
            Self::Grid(g) => g.cut_cells,
            Self::Cells { cut_cells, .. } | Self::Ods { cut_cells, .. } | Self::Xls { cut_cells, .. } => *cut_cells,
        }
    }
}
