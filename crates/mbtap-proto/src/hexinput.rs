//! Reading the frames users paste: hex with spaces, `0x` prefixes and separators, or an ASCII
//! frame given as its characters (`:...`, with or without CR LF, or with a literal `\r\n`).

use thiserror::Error;

/// Why a line of input is not a frame.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum HexInputError {
    #[error(
        "empty input: give a frame as hex bytes (e.g. \"01 03 00 65 00 03 15 D4\") or ASCII (\":010300650003 94\")"
    )]
    Empty,
    #[error("'{found}' at column {column} is not a hex digit")]
    BadDigit { column: usize, found: char },
    #[error("'{token}' at column {column} has an odd number of hex digits; write bytes as pairs (e.g. 0A, not A0A)")]
    OddDigits { column: usize, token: String },
}

/// Characters accepted between hex bytes.
fn is_separator(c: char) -> bool {
    c.is_whitespace() || matches!(c, ',' | ';' | '-' | '_' | '|' | ':' | '[' | ']' | '{' | '}')
}

/// Turns one line of user input into the bytes of a frame as on the wire.
///
/// # Errors
/// [`HexInputError`] naming the column (1-based) of the first character that is not hex.
pub fn parse_frame_text(line: &str) -> Result<Vec<u8>, HexInputError> {
    let line = line.trim();
    if line.is_empty() {
        return Err(HexInputError::Empty);
    }
    if line.starts_with(':') {
        return Ok(ascii_frame(line));
    }
    let mut out = Vec::with_capacity(line.len() / 2);
    let mut column = 1;
    for token in line.split(is_separator) {
        let token_column = column;
        column += token.chars().count() + 1;
        if token.is_empty() {
            continue;
        }
        let (digits, offset) = match token.strip_prefix("0x").or_else(|| token.strip_prefix("0X")) {
            Some(d) => (d, 2),
            None => (token, 0),
        };
        if let Some((i, c)) = digits.char_indices().find(|(_, c)| !c.is_ascii_hexdigit()) {
            return Err(HexInputError::BadDigit {
                column: token_column + offset + digits[..i].chars().count(),
                found: c,
            });
        }
        match digits.len() {
            0 => return Err(HexInputError::OddDigits { column: token_column, token: token.to_owned() }),
            // "0x1" or "1" alone is one byte; "A0A" is ambiguous and refused.
            1 => out.push(nibble(digits.as_bytes()[0])),
            n if n % 2 == 1 => return Err(HexInputError::OddDigits { column: token_column, token: token.to_owned() }),
            _ => out.extend(digits.as_bytes().chunks_exact(2).map(|p| (nibble(p[0]) << 4) | nibble(p[1]))),
        }
    }
    if out.is_empty() {
        return Err(HexInputError::Empty);
    }
    Ok(out)
}

fn nibble(c: u8) -> u8 {
    match c {
        b'0'..=b'9' => c - b'0',
        b'a'..=b'f' => c - b'a' + 10,
        b'A'..=b'F' => c - b'A' + 10,
        _ => 0,
    }
}

/// An ASCII frame as typed: spaces removed (manuals print the LRC apart), a literal `\r\n` or
/// a missing CR LF turned into the real terminator.
fn ascii_frame(line: &str) -> Vec<u8> {
    let body = line.strip_suffix("\\r\\n").unwrap_or(line);
    let mut out: Vec<u8> = body.bytes().filter(|c| !c.is_ascii_whitespace()).collect();
    out.extend_from_slice(b"\r\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_the_usual_spellings() {
        let want = vec![0x01, 0x83, 0x03, 0x01, 0x31];
        for s in [
            "0183030131",
            "01 83 03 01 31",
            "0x01 0x83 0x03 0x01 0x31",
            "01,83,03,01,31",
            "01-83-03-01-31",
            "[01 83 03 01 31]",
        ] {
            assert_eq!(parse_frame_text(s).unwrap(), want, "{s}");
        }
    }

    #[test]
    fn ascii_gets_its_terminator() {
        assert_eq!(parse_frame_text(":01030065000394").unwrap(), b":01030065000394\r\n");
        assert_eq!(parse_frame_text(":010300650003 94\\r\\n").unwrap(), b":01030065000394\r\n");
    }

    #[test]
    fn bad_digit_is_located() {
        assert_eq!(parse_frame_text("01 0G"), Err(HexInputError::BadDigit { column: 5, found: 'G' }));
        assert_eq!(parse_frame_text("0x1Z"), Err(HexInputError::BadDigit { column: 4, found: 'Z' }));
    }

    #[test]
    fn odd_digits_are_refused() {
        assert!(matches!(parse_frame_text("010"), Err(HexInputError::OddDigits { column: 1, .. })));
    }

    #[test]
    fn empty_is_refused() {
        assert_eq!(parse_frame_text("  "), Err(HexInputError::Empty));
        assert_eq!(parse_frame_text(" , "), Err(HexInputError::Empty));
    }
}
