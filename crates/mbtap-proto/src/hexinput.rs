//! Reading the frames users paste: hex with spaces, `0x` prefixes and separators, or an ASCII
//! frame given as its characters (`:...`, with or without CR LF, or with a literal `\r\n`) —
//! and the lines of the logs people paste them from ([`parse_log_line`]): a leading timestamp
//! and a direction tag (`Tx:`, `Rx:`, `send:`, `recv:`, `>`, `<`) are set aside, the tag kept as
//! the frame's direction; bytes written with dots (`F7.03.50.02`, as esphome logs them) read too.

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
    /// An ASCII frame shorter than address, function and LRC (Serial Line v1.02 §2.5.2.1).
    #[error(
        "an ASCII frame needs at least 6 characters after ':' (address, function and LRC as hex pairs); this one has {chars}"
    )]
    AsciiTooShort { chars: usize },
}

/// Characters accepted between hex bytes.
fn is_separator(c: char) -> bool {
    c.is_whitespace() || matches!(c, ',' | ';' | '-' | '_' | '|' | ':' | '.' | '[' | ']' | '{' | '}')
}

/// Which way a logged frame went, as the log's tag says (from the master's side).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tagged {
    /// `Tx`, `send`, `>`, `-->`: what the master sent.
    Request,
    /// `Rx`, `recv`, `<`, `<--`: what came back.
    Response,
}

/// One log line read: the frame's bytes, and what was set aside in front of them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogLine {
    pub bytes: Vec<u8>,
    /// The leading timestamp, as written.
    pub timestamp: Option<String>,
    /// The direction tag, as written, and what it says.
    pub tag: Option<(String, Tagged)>,
}

/// Reads one line of a log: an optional timestamp (`2024-05-01 12:00:01.123`, `12:00:01.123`,
/// `[12:00:01]`, `1715000000.123`), an optional direction tag, then a frame as
/// [`parse_frame_text`] reads it. A bare time without fractions or brackets (`01:03:00`) is
/// taken for bytes, not a time: colons separate bytes too.
///
/// # Errors
/// [`HexInputError`] for the frame part, its column counted in the whole line.
pub fn parse_log_line(line: &str) -> Result<LogLine, HexInputError> {
    let start = line.len() - line.trim_start().len();
    let mut rest = &line[start..];
    let mut timestamp = None;
    if let Some((ts, after)) = leading_timestamp(rest) {
        timestamp = Some(ts.trim().to_owned());
        rest = after;
    }
    let mut tag = None;
    if let Some((t, dir, after)) = leading_tag(rest.trim_start()) {
        tag = Some((t.to_owned(), dir));
        rest = after;
        // Modbus Poll's and Modbus Slave's logs number their lines after the tag:
        // `Tx:000001-01 03 00 00 00 0A C5 CD`. The counter is set aside, not read as bytes.
        if let Some((counter, frame)) = rest.split_once('-')
            && (1..=10).contains(&counter.len())
            && counter.bytes().all(|b| b.is_ascii_digit())
        {
            rest = frame;
        }
    }
    let rest = rest.trim_start();
    let offset = line.len() - rest.len();
    let shift = |e: HexInputError| match e {
        HexInputError::BadDigit { column, found } => {
            HexInputError::BadDigit { column: column + line[..offset].chars().count(), found }
        }
        HexInputError::OddDigits { column, token } => {
            HexInputError::OddDigits { column: column + line[..offset].chars().count(), token }
        }
        other => other,
    };
    let bytes = parse_frame_text(rest).map_err(shift)?;
    Ok(LogLine { bytes, timestamp, tag })
}

/// A timestamp at the start of `s`, and what follows it.
fn leading_timestamp(s: &str) -> Option<(&str, &str)> {
    // Bracketed: `[ … ]` holding digits and ':' or '-' (a time or a date).
    if let Some(inner) = s.strip_prefix('[') {
        let end = inner.find(']')?;
        let body = &inner[..end];
        let timeish = body.chars().any(|c| c.is_ascii_digit())
            && body.chars().any(|c| matches!(c, ':' | '-'))
            && body.chars().all(|c| c.is_ascii_digit() || " :.-T,+Z".contains(c));
        return timeish.then(|| (&s[..end + 2], &inner[end + 1..]));
    }
    let mut used = 0;
    let mut words = s.split_inclusive(char::is_whitespace);
    let mut found = false;
    for _ in 0..2 {
        let Some(word) = words.next() else { break };
        let w = word.trim();
        let date = w.len() >= 10
            && w.as_bytes()[4] == b'-'
            && w.as_bytes()[7] == b'-'
            && w[..4].bytes().all(|b| b.is_ascii_digit());
        // A time with fractions (12:00:01.123), or an epoch with fractions (1715000000.123).
        let time = w.contains(':')
            && w.contains(['.', ','])
            && w.split([':', '.', ',']).all(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()));
        let epoch = w.len() > 11
            && w.split_once('.')
                .is_some_and(|(a, b)| a.len() >= 9 && a.bytes().chain(b.bytes()).all(|c| c.is_ascii_digit()));
        if date || time || epoch {
            used += word.len();
            found = true;
            // A date may be followed by its time.
            if !date {
                break;
            }
        } else {
            break;
        }
    }
    found.then(|| (&s[..used], &s[used..]))
}

/// A direction tag at the start of `s` (case-insensitive words ending in ':' or space, or an
/// arrow), what it says, and what follows it.
fn leading_tag(s: &str) -> Option<(&str, Tagged, &str)> {
    for (arrow, dir) in
        [("-->", Tagged::Request), ("<--", Tagged::Response), (">", Tagged::Request), ("<", Tagged::Response)]
    {
        if let Some(after) = s.strip_prefix(arrow) {
            return Some((&s[..arrow.len()], dir, after));
        }
    }
    let end = s.find([':', ' ', '\t'])?;
    let word = &s[..end];
    let dir = match word.to_ascii_lowercase().as_str() {
        "tx" | "send" | "sent" | "write" | "request" | "req" => Tagged::Request,
        "rx" | "recv" | "received" | "read" | "response" | "resp" => Tagged::Response,
        _ => return None,
    };
    let after = s[end..].strip_prefix(':').unwrap_or(&s[end..]);
    Some((word, dir, after))
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
        let frame = ascii_frame(line);
        // ':' and CR LF around the characters the user typed.
        let chars = frame.len().saturating_sub(3);
        if chars < 6 {
            return Err(HexInputError::AsciiTooShort { chars });
        }
        return Ok(frame);
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

    /// Real log formats are read: the bytes kept, the timestamp and tag set aside (never "'.' is
    /// not a hex digit").
    #[test]
    fn log_lines_keep_their_bytes_and_set_aside_timestamp_and_tag() {
        let want = vec![0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4];
        for (line, ts, tag) in [
            ("01.03.00.65.00.03.15.D4", None, None),
            ("2024-05-01 12:00:01.123 Tx: 01 03 00 65 00 03 15 D4", Some("2024-05-01 12:00:01.123"), Some("Tx")),
            ("12:00:01.123 send: 01 03 00 65 00 03 15 D4", Some("12:00:01.123"), Some("send")),
            ("[12:00:01] TX 01 03 00 65 00 03 15 D4", Some("[12:00:01]"), Some("TX")),
            ("1715000000.123 > 01 03 00 65 00 03 15 D4", Some("1715000000.123"), Some(">")),
            ("0x1 0x3 0x0 0x65 0x0 0x3 0x15 0xd4", None, None),
            ("01:03:00:65:00:03:15:D4", None, None),
        ] {
            let l = parse_log_line(line).unwrap_or_else(|e| panic!("{line}: {e}"));
            assert_eq!(l.bytes, want, "{line}");
            assert_eq!(l.timestamp.as_deref(), ts, "{line}");
            assert_eq!(l.tag.as_ref().map(|(t, _)| t.as_str()), tag, "{line}");
        }
        assert_eq!(parse_log_line("Rx: 01 83 02 C0 F1").unwrap().tag.unwrap().1, Tagged::Response);
        // Columns count in the whole line.
        assert_eq!(parse_log_line("Tx: 01 0G"), Err(HexInputError::BadDigit { column: 9, found: 'G' }));
    }

    /// `decode ":"` said "ASCII frame of 3 bytes" (its added CR LF counted).
    /// Modbus Poll's log lines decoded their line counter as noise.
    #[test]
    fn modbus_polls_line_counter_is_set_aside() {
        // Modbus Poll log: Tx:COUNTER-request, Rx:COUNTER-response (MK4 §3.3 read of 101..103).
        let tx = parse_log_line("Tx:000001-01 03 00 65 00 03 15 D4").unwrap();
        assert_eq!(tx.bytes, [0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4]);
        assert_eq!(tx.tag.unwrap().1, Tagged::Request);
        let rx = parse_log_line("Rx:000002-01 03 06 00 00 00 00 01 90 20 89").unwrap();
        assert_eq!(rx.bytes.len(), 11);
        assert_eq!(rx.tag.unwrap().1, Tagged::Response);
        // Without a tag, digits and a dash are bytes.
        assert_eq!(parse_log_line("01-03-00-65-00-03-15-D4").unwrap().bytes.len(), 8);
    }

    #[test]
    fn a_short_ascii_frame_counts_what_was_typed() {
        assert_eq!(parse_frame_text(":"), Err(HexInputError::AsciiTooShort { chars: 0 }));
        assert_eq!(parse_frame_text(":01"), Err(HexInputError::AsciiTooShort { chars: 2 }));
        assert!(parse_frame_text(":0103FC").is_ok());
    }

    #[test]
    fn empty_is_refused() {
        assert_eq!(parse_frame_text("  "), Err(HexInputError::Empty));
        assert_eq!(parse_frame_text(" , "), Err(HexInputError::Empty));
    }
}
