//! A sheet's cells held compactly: all cell text in one string, each cell an end
//! offset (4 bytes), each row an end index (4 bytes) — a sheet of one-character cells takes
//! about 2.5 bytes per byte of CSV, where a `String` per cell took ~49.
//!
//! Bounded: at most [`MAX_ROWS`] rows, [`MAX_COLUMNS`] columns (cells beyond are counted, not
//! kept) and [`MAX_TEXT`] bytes of text; past a bound [`Grid::push_row`] refuses and says which.

/// Rows a register sheet can need: every address of the four tables, and titles and notes.
pub const MAX_ROWS: usize = 4 * 65_536 + 1_024;
/// Columns kept per row; a register sheet has a dozen. Cells beyond are counted in
/// [`Grid::cut_cells`].
pub const MAX_COLUMNS: usize = 256;
/// Bytes of cell text kept in all (64 MiB: 262 144 rows of 256 bytes).
pub const MAX_TEXT: usize = 64 << 20;

/// A number as a sheet shows it in a cell: whole numbers without `.0`, as every workbook reader
/// of the import gives them.
#[must_use]
pub fn number_text(f: f64) -> String {
    if f.fract() == 0.0 && f.abs() < 1e15 { format!("{f:.0}") } else { f.to_string() }
}

/// Why a row was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum GridFull {
    #[error("more than {MAX_ROWS} rows (every address of the four tables and then some): not a register sheet")]
    Rows,
    #[error("more than {} MiB of cell text: not a register sheet", MAX_TEXT >> 20)]
    Text,
}

/// Rows of cells, compact.
#[derive(Debug, Clone, Default)]
pub struct Grid {
    text: String,
    /// End offset in `text` of each cell.
    cell_ends: Vec<u32>,
    /// End index in `cell_ends` of each row.
    row_ends: Vec<u32>,
    /// Cells past [`MAX_COLUMNS`] that were not kept.
    pub cut_cells: u64,
}

/// One row of a [`Grid`].
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    grid: &'a Grid,
    first: usize,
    end: usize,
}

impl Grid {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// A grid of `rows` (tests and fuzzing), cut at the bounds.
    #[must_use]
    pub fn from_rows<R: IntoIterator<Item = C>, C: IntoIterator<Item = S>, S: AsRef<str>>(rows: R) -> Self {
        let mut g = Self::new();
        for r in rows {
            if g.push_row(r).is_err() {
                break;
            }
        }
        g
    }

    /// Appends a row; trailing empty cells are not kept (a workbook pads rows to its widest).
    ///
    /// # Errors
    /// The grid is full: [`MAX_ROWS`] rows or [`MAX_TEXT`] bytes.
    pub fn push_row<C: IntoIterator<Item = S>, S: AsRef<str>>(&mut self, cells: C) -> Result<(), GridFull> {
        if self.row_ends.len() >= MAX_ROWS {
            return Err(GridFull::Rows);
        }
        let (start, text_start) = (self.cell_ends.len(), self.text.len());
        let mut kept_to = start;
        for (i, c) in cells.into_iter().enumerate() {
            if i >= MAX_COLUMNS {
                self.cut_cells += 1;
                continue;
            }
            let c = c.as_ref();
            if self.text.len() + c.len() > MAX_TEXT {
                self.cell_ends.truncate(start);
                self.text.truncate(text_start);
                return Err(GridFull::Text);
            }
            self.text.push_str(c);
            self.cell_ends.push(u32::try_from(self.text.len()).map_err(|_| GridFull::Text)?);
            if !c.trim().is_empty() {
                kept_to = self.cell_ends.len();
            }
        }
        self.cell_ends.truncate(kept_to);
        self.text.truncate(self.cell_ends.last().map_or(0, |&e| e as usize));
        self.row_ends.push(u32::try_from(self.cell_ends.len()).map_err(|_| GridFull::Rows)?);
        Ok(())
    }

    /// Rows held.
    #[must_use]
    pub fn len(&self) -> usize {
        self.row_ends.len()
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.row_ends.is_empty()
    }

    /// Row `i` (an empty row past the end).
    #[must_use]
    pub fn row(&self, i: usize) -> Row<'_> {
        let first = i.checked_sub(1).and_then(|p| self.row_ends.get(p)).map_or(0, |&e| e as usize);
        let end = self.row_ends.get(i).map_or(first, |&e| e as usize);
        Row { grid: self, first, end }
    }

    /// Every row, in order.
    pub fn rows(&self) -> impl Iterator<Item = Row<'_>> {
        (0..self.len()).map(|i| self.row(i))
    }

    fn cell(&self, k: usize) -> &str {
        let start = k.checked_sub(1).and_then(|p| self.cell_ends.get(p)).map_or(0, |&e| e as usize);
        let end = self.cell_ends.get(k).map_or(start, |&e| e as usize);
        self.text.get(start..end).unwrap_or("")
    }
}

impl<'a> Row<'a> {
    /// Cell `i`, if the row has it.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<&'a str> {
        let k = self.first.checked_add(i)?;
        (k < self.end).then(|| self.grid.cell(k))
    }

    /// The row's cells.
    pub fn iter(&self) -> impl Iterator<Item = &'a str> + use<'a> {
        let grid = self.grid;
        (self.first..self.end).map(move |k| grid.cell(k))
    }

    /// Cells in the row (trailing empty ones not kept).
    #[must_use]
    pub fn len(&self) -> usize {
        self.end - self.first
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_read_back_as_pushed_without_trailing_empty_cells() {
        let g = Grid::from_rows([vec!["a", "", "bc", "", ""], vec![], vec!["", "x"]]);
        assert_eq!(g.len(), 3);
        assert_eq!(g.row(0).iter().collect::<Vec<_>>(), ["a", "", "bc"]);
        assert!(g.row(1).is_empty());
        assert_eq!(g.row(2).get(1), Some("x"));
        assert_eq!(g.row(2).get(2), None);
        assert!(g.row(9).is_empty());
    }

    #[test]
    fn columns_past_the_bound_are_counted_not_kept() {
        let wide: Vec<String> = (0..MAX_COLUMNS + 10).map(|i| i.to_string()).collect();
        let g = Grid::from_rows([wide]);
        assert_eq!((g.row(0).len(), g.cut_cells), (MAX_COLUMNS, 10));
    }
}
