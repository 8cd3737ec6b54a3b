//! An imported profile loaded back as the loader loads any profile, a part at a time and read
//! line by line: the TOML reader's document takes ~25 bytes per byte of text, so a
//! profile of 200 000 points read whole took 300 MB, and the profile itself is ~3× the sheet.

use std::io::BufRead;

use crate::profile::Table;

/// Entries loaded back at a time: a part of 1 024 entries is ~70 kB of text, ~2 MB in the reader.
pub const LOAD_BACK_PART: usize = 1024;

/// Why a written profile does not load back.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LoadBackError {
    #[error(transparent)]
    Part(#[from] crate::profile::ProfileError),
    #[error("{file}: {table} address {address} is defined twice")]
    Twice { file: String, table: &'static str, address: u16 },
    #[error("{file}: reading it back, line {line}: {why}")]
    Read { file: String, line: usize, why: String },
}

/// Loads the profile read from `reader` — [`super::header`] and [`super::entry`]'s output, named
/// `file` — [`LOAD_BACK_PART`] entries at a time: each part is the file's header and a run of
/// its `[[table]]` entries (the writer emits nothing else, and no string spans lines), checked
/// whole by the loader; an address defined in two parts is found by a bit per address. Errors
/// name the line of the whole file.
///
/// # Errors
/// The first part that does not load, an address defined twice, or the text cannot be read.
pub fn load_back<R: BufRead>(file: &str, mut reader: R) -> Result<(), LoadBackError> {
    let mut part = Part { file, header: String::new(), header_lines: 0, seen: vec![0u64; 4 * 65_536 / 64] };
    let mut text = String::new();
    let mut line = String::new();
    let (mut in_header, mut entries, mut first_line, mut lineno) = (true, 0usize, 0usize, 0usize);
    loop {
        line.clear();
        let n = reader.read_line(&mut line).map_err(|e| LoadBackError::Read {
            file: file.to_owned(),
            line: lineno + 1,
            why: e.to_string(),
        })?;
        if n == 0 {
            break;
        }
        if line.starts_with("[[") {
            if in_header {
                in_header = false;
                first_line = lineno;
            } else if entries == LOAD_BACK_PART {
                part.load(&text, first_line)?;
                text.clear();
                entries = 0;
                first_line = lineno;
            }
            entries += 1;
        }
        if in_header {
            part.header.push_str(&line);
            part.header_lines += 1;
        } else {
            text.push_str(&line);
        }
        lineno += 1;
    }
    if in_header {
        crate::profile::load(file, &part.header)?;
        return Ok(());
    }
    part.load(&text, first_line)
}

/// What every part shares: the header, and the addresses defined so far.
struct Part<'a> {
    file: &'a str,
    header: String,
    header_lines: usize,
    seen: Vec<u64>,
}

impl Part<'_> {
    /// Loads the header and `entries` (whose first line is the file's line `first_line`, from 0).
    fn load(&mut self, entries: &str, first_line: usize) -> Result<(), LoadBackError> {
        let text = format!("{}{entries}", self.header);
        let loaded = crate::profile::load(self.file, &text).map_err(|mut e| {
            if e.line > self.header_lines {
                e.line = e.line - self.header_lines + first_line;
            }
            e
        })?;
        for (&table, slots) in &loaded.tables {
            let t = match table {
                Table::Coils => 0,
                Table::DiscreteInputs => 1,
                Table::InputRegisters => 2,
                Table::HoldingRegisters => 3,
            };
            for &address in slots.keys() {
                let bit = t * 65_536 + usize::from(address);
                // Four tables of 65 536 addresses: every bit is within `seen`.
                let Some(word) = self.seen.get_mut(bit / 64) else { continue };
                if *word & (1 << (bit % 64)) != 0 {
                    return Err(LoadBackError::Twice { file: self.file.to_owned(), table: table.name(), address });
                }
                *word |= 1 << (bit % 64);
            }
        }
        Ok(())
    }
}
