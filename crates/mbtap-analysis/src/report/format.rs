//! Small formatters every output shares: times of day and hex dumps, so the text transcript,
//! JSON lines, the terminal UI and the health report print them the same way.

use std::fmt::Write as _;

/// The civil date (year, month, day) of a day counted from 1970-01-01: the proleptic Gregorian
/// calendar, H. Hinnant's days-to-civil algorithm (exact for any day an `i64` holds here).
#[must_use]
pub fn civil_date(days_since_epoch: i64) -> (i64, i64, i64) {
    let z = days_since_epoch + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(month <= 2), month, day)
}

/// `HH:MM:SS.mmm` (UTC) of a time in ns since the epoch: the UI's and the reports' clock.
#[must_use]
pub fn clock_ms(t_ns: u64) -> String {
    let secs = t_ns / 1_000_000_000;
    let (h, m, s) = ((secs / 3600) % 24, (secs / 60) % 60, secs % 60);
    format!("{h:02}:{m:02}:{s:02}.{:03}", (t_ns % 1_000_000_000) / 1_000_000)
}

/// `HH:MM:SS.uuuuuu` (UTC): the transcript's clock, fine enough for character timing.
#[must_use]
pub fn clock_us(t_ns: u64) -> String {
    let secs = t_ns / 1_000_000_000;
    let (h, m, s) = ((secs / 3600) % 24, (secs / 60) % 60, secs % 60);
    format!("{h:02}:{m:02}:{s:02}.{:06}", (t_ns % 1_000_000_000) / 1000)
}

/// `01 03 A0` — for people.
#[must_use]
pub fn hex_spaced(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() * 3);
    for (i, b) in bytes.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{b:02X}");
    }
    s
}

/// `0103a0` — for programs (JSON values).
#[must_use]
pub fn hex_compact(bytes: &[u8]) -> String {
    bytes.iter().fold(String::with_capacity(bytes.len() * 2), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// `text` safe for a terminal: every control character but the line break — an escape
/// sequence in a profile's name, a device's identification string or an ASCII frame from the
/// bus would otherwise retitle, clear or reprogram the user's terminal — is written as `\u{1b}`.
#[must_use]
pub fn printable(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.chars().any(|c| c.is_control() && c != '\n') {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        if c.is_control() && c != '\n' {
            let _ = write!(out, "\\u{{{:x}}}", u32::from(c));
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    /// `^[]0;pwned^G^[[2J` in a profile name retitled and cleared the terminal.
    #[test]
    fn control_characters_never_reach_the_terminal() {
        let hostile = "pump \u{1b}]0;pwned\u{7}\u{1b}[2J\u{9b}31m\r";
        let shown = super::printable(hostile);
        assert!(!shown.chars().any(char::is_control), "{shown}");
        assert_eq!(shown, "pump \\u{1b}]0;pwned\\u{7}\\u{1b}[2J\\u{9b}31m\\u{d}");
        assert_eq!(super::printable("line one\nline two"), "line one\nline two");
    }

    use super::*;

    #[test]
    fn clocks_and_hex() {
        let t = 3_723_004_005_006;
        assert_eq!((clock_ms(t), clock_us(t)), ("01:02:03.004".into(), "01:02:03.004005".into()));
        assert_eq!((hex_spaced(&[1, 0xA0]), hex_compact(&[1, 0xA0])), ("01 A0".into(), "01a0".into()));
        assert_eq!((hex_spaced(&[]), hex_compact(&[])), (String::new(), String::new()));
    }
}
