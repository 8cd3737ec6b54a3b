//! The lines `mbtap decode` reads from a stream, one at a time in constant memory: bytes, not
//! text (a Latin-1 comment must not stop the input), each line at most [`MAX_LINE`] bytes
//! (a longer one is cut, the rest skipped without being held, and the cut reported).

use std::borrow::Cow;
use std::io::{self, BufRead, Read};

/// A line longer than this is no frame (the longest, an ASCII frame, is 513 characters; hex
/// of 256 bytes with separators and a log's timestamp stays well under it): it is cut, and said.
pub const MAX_LINE: usize = 4096;

/// One line of input.
#[derive(Debug, PartialEq, Eq)]
pub struct Line<'a> {
    /// 1-based line number, counting every line (blank and comment lines too).
    pub number: usize,
    /// The line without its line end; bytes that are not UTF-8 become U+FFFD.
    pub text: Cow<'a, str>,
    /// The line was longer than [`MAX_LINE`] and `text` is its start.
    pub cut: bool,
}

/// Reads lines from a buffered stream.
#[derive(Debug)]
pub struct Lines<R> {
    reader: R,
    buf: Vec<u8>,
    number: usize,
}

impl<R: BufRead> Lines<R> {
    pub fn new(reader: R) -> Self {
        Self { reader, buf: Vec::with_capacity(256), number: 0 }
    }

    /// The stream (to see whether its buffer is drained, a good moment to flush output).
    pub fn get_ref(&self) -> &R {
        &self.reader
    }

    /// The next line, `None` at the end of the stream.
    ///
    /// # Errors
    /// I/O errors of the stream.
    pub fn next_line(&mut self) -> io::Result<Option<Line<'_>>> {
        self.buf.clear();
        let n = (&mut self.reader).take(MAX_LINE as u64 + 1).read_until(b'\n', &mut self.buf)?;
        if n == 0 {
            return Ok(None);
        }
        self.number += 1;
        let cut = self.buf.last() != Some(&b'\n') && n > MAX_LINE;
        if cut {
            // Skip the rest of the line in bounded pieces, never holding it.
            let mut rest = Vec::new();
            loop {
                rest.clear();
                let m = (&mut self.reader).take(64 * 1024).read_until(b'\n', &mut rest)?;
                if m == 0 || rest.last() == Some(&b'\n') {
                    break;
                }
            }
            self.buf.truncate(MAX_LINE);
        }
        while matches!(self.buf.last(), Some(b'\n' | b'\r')) {
            self.buf.pop();
        }
        Ok(Some(Line { number: self.number, text: String::from_utf8_lossy(&self.buf), cut }))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn all(input: &[u8]) -> Vec<(usize, String, bool)> {
        let mut l = Lines::new(input);
        let mut out = Vec::new();
        while let Some(line) = l.next_line().unwrap() {
            out.push((line.number, line.text.into_owned(), line.cut));
        }
        out
    }

    #[test]
    fn lines_are_numbered_ends_stripped_and_latin1_survives() {
        // "# caf\xE9" is a Latin-1 comment: read, not an error.
        let got = all(b"01 03\r\n# caf\xE9\n\n0103");
        assert_eq!(
            got,
            vec![
                (1, "01 03".into(), false),
                (2, "# caf\u{FFFD}".into(), false),
                (3, String::new(), false),
                (4, "0103".into(), false)
            ]
        );
    }

    #[test]
    fn a_long_line_is_cut_and_the_next_one_read() {
        let mut input = vec![b'A'; 100_000];
        input.extend_from_slice(b"\n0103\n");
        let got = all(&input);
        assert_eq!(got.len(), 2);
        assert_eq!((got[0].0, got[0].1.len(), got[0].2), (1, MAX_LINE, true));
        assert_eq!(got[1], (2, "0103".into(), false));
    }
}
