//! A sheet read cell by cell, handed on row by row: the XLSX/XLSB and XLS readers give
//! cells one at a time in the order their files hold them; the sheet reader wants rows. Nothing
//! is allocated for the empty space between cells and no row is kept once handed on, so a cell
//! at XFD1048576 costs one cell, not the dense range between it and A1.

use std::ops::ControlFlow;

use super::grid::{MAX_COLUMNS, MAX_ROWS};

/// Hands on the cells `next` gives — each its row, column (both from 0) and text — as rows to
/// `each`, every row up to the last cell's included (the empty ones between too), trailing empty
/// cells left off. Cells past [`MAX_COLUMNS`] are counted (returned), not handed on; a cell in
/// a row before the one being built (a hand-made file) is ignored: what was handed on stays.
///
/// # Errors
/// What `next` returns, or `too_many_rows(row)` for a cell past [`MAX_ROWS`].
pub fn rows_from_cells<E>(
    mut next: impl FnMut() -> Result<Option<(u32, u32, String)>, E>,
    each: &mut dyn FnMut(usize, &[&str]) -> ControlFlow<()>,
    too_many_rows: impl Fn(usize) -> E,
) -> Result<u64, E> {
    let mut row: Vec<String> = Vec::new();
    let mut at_row = 0usize;
    let mut cut = 0u64;
    let mut hand_on = |i: usize, row: &mut Vec<String>| {
        // Trailing empty cells are not part of the row (a workbook pads rows to its widest).
        let kept = row.iter().rposition(|c| !c.trim().is_empty()).map_or(0, |k| k + 1);
        let cells: Vec<&str> = row.iter().take(kept).map(String::as_str).collect();
        let flow = each(i, &cells);
        row.clear();
        flow
    };
    while let Some((r, c, text)) = next()? {
        let (r, c) = (r as usize, c as usize);
        if r >= MAX_ROWS {
            return Err(too_many_rows(r));
        }
        if r < at_row {
            continue;
        }
        while at_row < r {
            if hand_on(at_row, &mut row).is_break() {
                return Ok(cut);
            }
            at_row += 1;
        }
        if c >= MAX_COLUMNS {
            cut += 1;
            continue;
        }
        if row.len() <= c {
            row.resize(c + 1, String::new());
        }
        row[c] = text;
    }
    let _ = hand_on(at_row, &mut row);
    Ok(cut)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Every row handed on, as owned cells.
    fn rows(cells: &[(u32, u32, &str)]) -> (Vec<(usize, Vec<String>)>, u64) {
        let mut cells = cells.iter().map(|&(r, c, t)| (r, c, t.to_owned()));
        let mut out = Vec::new();
        let cut = rows_from_cells(
            || Ok::<_, usize>(cells.next()),
            &mut |i, r| {
                out.push((i, r.iter().map(|c| (*c).to_owned()).collect()));
                ControlFlow::Continue(())
            },
            |r| r,
        )
        .unwrap();
        (out, cut)
    }

    #[test]
    fn cells_become_rows_with_the_empty_ones_between_and_far_columns_counted() {
        let (out, cut) = rows(&[(0, 1, "b"), (0, 0, "a"), (2, 0, "x"), (2, 3, " "), (1, 999, "far"), (3, 0, "late")]);
        let want: Vec<(usize, Vec<String>)> =
            vec![(0, vec!["a".into(), "b".into()]), (1, vec![]), (2, vec!["x".into()]), (3, vec!["late".into()])];
        // The cell at row 1 comes after row 2 began: ignored, not counted.
        assert_eq!((out, cut), (want, 0));
        let (_, cut) = rows(&[(0, 300, "a"), (0, 256, "b"), (0, 255, "c")]);
        assert_eq!(cut, 2);
    }

    #[test]
    fn a_cell_past_the_last_row_is_refused() {
        let mut one = std::iter::once((u32::try_from(MAX_ROWS).unwrap(), 0, String::new()));
        let got = rows_from_cells(|| Ok(one.next()), &mut |_, _| ControlFlow::Continue(()), |r| r);
        assert_eq!(got, Err(MAX_ROWS));
    }
}
