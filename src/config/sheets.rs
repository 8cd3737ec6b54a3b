//! Spreadsheets read into rows of text: CSV (the delimiter sniffed: `,`, `;` or tab; bytes that
//! are not UTF-8 kept as replacement characters) and XLSX/XLS/ODS through calamine — row and
//! column numbers as the spreadsheet shows them, so a problem's "row 7, column C" is where the
//! user looks.

use std::path::Path;

use anyhow::Context as _;
use calamine::{Data, Reader as _};

/// The rows of a CSV file.
///
/// # Errors
/// The file cannot be read, or a record cannot be parsed (with its line).
pub fn read_csv(path: &Path) -> anyhow::Result<Vec<Vec<String>>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    // The delimiter the first lines use most: European sheets use `;` (the comma is their
    // decimal point), exports from databases tabs.
    let head: Vec<&[u8]> = bytes.split(|&b| b == b'\n').take(20).collect();
    // A sniff over at most 20 lines: counting byte by byte is fine here.
    #[allow(clippy::naive_bytecount)]
    let count = |d: u8| head.iter().map(|l| l.iter().filter(|&&b| b == d).count()).sum::<usize>();
    let delimiter = [b',', b';', b'\t'].into_iter().max_by_key(|&d| count(d)).unwrap_or(b',');
    let mut reader =
        csv::ReaderBuilder::new().has_headers(false).flexible(true).delimiter(delimiter).from_reader(bytes);
    let mut rows = Vec::new();
    for (i, record) in reader.byte_records().enumerate() {
        let record = record.with_context(|| format!("{}: record {}", path.display(), i + 1))?;
        rows.push(record.iter().map(|c| String::from_utf8_lossy(c).into_owned()).collect());
    }
    Ok(rows)
}

/// A cell as text: whole numbers without `.0`, as the sheet shows them.
fn cell_text(d: &Data) -> String {
    match d {
        Data::Empty => String::new(),
        Data::String(s) | Data::DateTimeIso(s) | Data::DurationIso(s) => s.clone(),
        Data::Int(i) => i.to_string(),
        Data::Float(f) if f.fract() == 0.0 && f.abs() < 1e15 => format!("{f:.0}"),
        Data::Float(f) => f.to_string(),
        Data::Bool(b) => b.to_string(),
        Data::DateTime(t) => t.as_f64().to_string(),
        Data::Error(e) => format!("#{e:?}"),
    }
}

/// The rows of a workbook's sheet `sheet` (by name), or its first.
///
/// # Errors
/// The workbook cannot be opened, or has no such sheet (the ones it has are named).
pub fn read_workbook(path: &Path, sheet: Option<&str>) -> anyhow::Result<Vec<Vec<String>>> {
    let mut wb = calamine::open_workbook_auto(path).with_context(|| format!("opening {}", path.display()))?;
    let names = wb.sheet_names();
    let name = match sheet {
        Some(s) => names
            .iter()
            .find(|n| n.eq_ignore_ascii_case(s))
            .cloned()
            .with_context(|| format!("{}: no sheet {s:?} (it has: {})", path.display(), names.join(", ")))?,
        None => names.first().cloned().with_context(|| format!("{}: no sheets", path.display()))?,
    };
    let range = wb.worksheet_range(&name).with_context(|| format!("{}: reading sheet {name:?}", path.display()))?;
    // The range starts at its first used cell; pad so rows and columns are the sheet's own.
    let (row0, col0) = range.start().map_or((0, 0), |(r, c)| (r as usize, c as usize));
    let mut rows: Vec<Vec<String>> = vec![Vec::new(); row0];
    for r in range.rows() {
        let mut cells = vec![String::new(); col0];
        cells.extend(r.iter().map(cell_text));
        rows.push(cells);
    }
    Ok(rows)
}
