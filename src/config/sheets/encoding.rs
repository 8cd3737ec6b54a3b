//! A text file's encoding as spreadsheets save it: UTF-8 (with or without a byte-order mark),
//! UTF-16 with its byte-order mark (Excel's "Unicode text"), or — when the bytes are not UTF-8 —
//! Windows-1252, the code page Excel uses for "CSV" on Western systems (a superset of Latin-1's
//! printable characters). Decided from the whole file, streamed; never replacement characters in
//! silence.

use std::io::Read;

/// How a file's bytes become text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    Utf8,
    /// Little-endian UTF-16 (byte-order mark FF FE).
    Utf16Le,
    /// Big-endian UTF-16 (byte-order mark FE FF).
    Utf16Be,
    Windows1252,
}

impl Encoding {
    /// What to tell the user about it; `None` for plain UTF-8.
    #[must_use]
    pub const fn note(self) -> Option<&'static str> {
        match self {
            Self::Utf8 => None,
            Self::Utf16Le | Self::Utf16Be => Some("UTF-16 (its byte-order mark says so): read as such"),
            Self::Windows1252 => {
                Some("not UTF-8: read as Windows-1252 (Latin-1), as Excel saves CSV on Western systems")
            }
        }
    }
}

/// The encoding of what `input` holds: a UTF-16 byte-order mark, else UTF-8 if every byte is
/// (checked in 64 KiB pieces, a character split between two carried over), else Windows-1252.
///
/// # Errors
/// The input could not be read.
pub fn detect(mut input: impl Read) -> std::io::Result<Encoding> {
    let mut buf = vec![0u8; 64 << 10];
    let mut carry = 0usize;
    let mut first = true;
    loop {
        let n = input.read(buf.get_mut(carry..).unwrap_or_default())?;
        let have = carry + n;
        let chunk = buf.get(..have).unwrap_or_default();
        if first {
            first = false;
            if chunk.starts_with(b"\xFF\xFE") {
                return Ok(Encoding::Utf16Le);
            }
            if chunk.starts_with(b"\xFE\xFF") {
                return Ok(Encoding::Utf16Be);
            }
        }
        match std::str::from_utf8(chunk) {
            Ok(_) => carry = 0,
            // A character cut at the end of this piece: carried into the next read.
            Err(e) if e.error_len().is_none() && n > 0 => {
                let valid = e.valid_up_to();
                buf.copy_within(valid..have, 0);
                carry = have - valid;
            }
            Err(_) => return Ok(Encoding::Windows1252),
        }
        if n == 0 {
            return Ok(Encoding::Utf8);
        }
    }
}

/// Windows-1252's characters for bytes 0x80–0x9F (the rest of the code page is Latin-1: the byte
/// is the character); the five bytes the code page leaves undefined keep their C1 control.
const CP1252_80_9F: [char; 32] = [
    '\u{20AC}', '\u{0081}', '\u{201A}', '\u{0192}', '\u{201E}', '\u{2026}', '\u{2020}', '\u{2021}', '\u{02C6}',
    '\u{2030}', '\u{0160}', '\u{2039}', '\u{0152}', '\u{008D}', '\u{017D}', '\u{008F}', '\u{0090}', '\u{2018}',
    '\u{2019}', '\u{201C}', '\u{201D}', '\u{2022}', '\u{2013}', '\u{2014}', '\u{02DC}', '\u{2122}', '\u{0161}',
    '\u{203A}', '\u{0153}', '\u{009D}', '\u{017E}', '\u{0178}',
];

/// Bytes of Windows-1252 as text.
#[must_use]
pub fn windows_1252(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|&b| match b {
            0x80..=0x9F => CP1252_80_9F.get(usize::from(b - 0x80)).copied().unwrap_or('\u{FFFD}'),
            _ => char::from(b),
        })
        .collect()
}

/// UTF-16 read as UTF-8, streamed: what a CSV reader expects. An unpaired surrogate becomes
/// U+FFFD (counted in `damaged`).
#[derive(Debug)]
pub struct Utf16ToUtf8<R> {
    inner: R,
    big_endian: bool,
    /// UTF-8 bytes decoded and not yet read, and how far they have been read.
    out: Vec<u8>,
    at: usize,
    /// A byte of a code unit cut between two reads.
    odd: Option<u8>,
    /// A high surrogate waiting for its low half.
    high: Option<u16>,
    pub damaged: u64,
}

impl<R: Read> Utf16ToUtf8<R> {
    pub const fn new(inner: R, big_endian: bool) -> Self {
        Self { inner, big_endian, out: Vec::new(), at: 0, odd: None, high: None, damaged: 0 }
    }

    fn push(&mut self, c: char) {
        let mut b = [0u8; 4];
        self.out.extend_from_slice(c.encode_utf8(&mut b).as_bytes());
    }

    fn unit(&mut self, u: u16) {
        match (self.high.take(), u) {
            (Some(h), 0xDC00..=0xDFFF) => {
                let c = 0x10000 + ((u32::from(h) - 0xD800) << 10) + (u32::from(u) - 0xDC00);
                self.push(char::from_u32(c).unwrap_or('\u{FFFD}'));
            }
            (h, 0xD800..=0xDBFF) => {
                if h.is_some() {
                    self.damaged += 1;
                    self.push('\u{FFFD}');
                }
                self.high = Some(u);
            }
            (h, _) => {
                if h.is_some() {
                    self.damaged += 1;
                    self.push('\u{FFFD}');
                }
                let c = char::from_u32(u32::from(u)).unwrap_or_else(|| {
                    self.damaged += 1;
                    '\u{FFFD}'
                });
                self.push(c);
            }
        }
    }
}

impl<R: Read> Read for Utf16ToUtf8<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while self.at >= self.out.len() {
            self.out.clear();
            self.at = 0;
            let mut raw = [0u8; 8192];
            let n = self.inner.read(&mut raw)?;
            if n == 0 {
                if self.high.take().is_some() || self.odd.take().is_some() {
                    self.damaged += 1;
                    self.push('\u{FFFD}');
                    break;
                }
                return Ok(0);
            }
            let mut bytes = raw.get(..n).unwrap_or_default().iter().copied();
            while let Some(a) = self.odd.take().or_else(|| bytes.next()) {
                let Some(b) = bytes.next() else {
                    self.odd = Some(a);
                    break;
                };
                let u = if self.big_endian { u16::from_be_bytes([a, b]) } else { u16::from_le_bytes([a, b]) };
                self.unit(u);
            }
        }
        let rest = self.out.get(self.at..).unwrap_or_default();
        let n = rest.len().min(buf.len());
        buf.get_mut(..n).unwrap_or_default().copy_from_slice(rest.get(..n).unwrap_or_default());
        self.at += n;
        Ok(n)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// `Température;°C` as Excel's "CSV" saves it on a Western system: é = E9, ° = B0.
    const CP1252_HEADER: &[u8] = b"Temp\xE9rature;\xB0C;\x80";

    #[test]
    fn a_windows_1252_file_is_told_apart_from_utf8_and_read_right() {
        assert_eq!(detect(CP1252_HEADER).unwrap(), Encoding::Windows1252);
        assert_eq!(windows_1252(CP1252_HEADER), "Température;°C;€");
        assert_eq!(detect("Température;°C".as_bytes()).unwrap(), Encoding::Utf8);
    }

    #[test]
    fn a_utf8_character_cut_between_two_reads_is_still_utf8() {
        // 65 535 ASCII bytes, then é (C3 A9) across the 64 KiB boundary.
        let mut text = vec![b'a'; (64 << 10) - 1];
        text.extend_from_slice("é;x".as_bytes());
        assert_eq!(detect(text.as_slice()).unwrap(), Encoding::Utf8);
    }

    #[test]
    fn utf16_with_its_mark_is_read_as_text_in_either_byte_order() {
        let text = "Name;Unit\nTempérature;°C\n😀\n";
        let le: Vec<u8> = [0xFF, 0xFE].into_iter().chain(text.encode_utf16().flat_map(u16::to_le_bytes)).collect();
        let be: Vec<u8> = [0xFE, 0xFF].into_iter().chain(text.encode_utf16().flat_map(u16::to_be_bytes)).collect();
        assert_eq!(detect(le.as_slice()).unwrap(), Encoding::Utf16Le);
        assert_eq!(detect(be.as_slice()).unwrap(), Encoding::Utf16Be);
        for (bytes, big) in [(&le, false), (&be, true)] {
            let mut s = String::new();
            Utf16ToUtf8::new(&bytes[2..], big).read_to_string(&mut s).unwrap();
            assert_eq!(s, text);
        }
    }

    #[test]
    fn a_lone_surrogate_or_an_odd_byte_is_counted_not_lost_silently() {
        let bytes = [0x00, 0xD8, 0x41, 0x00, 0x42];
        let mut r = Utf16ToUtf8::new(&bytes[..], false);
        let mut s = String::new();
        r.read_to_string(&mut s).unwrap();
        assert_eq!(s, "\u{FFFD}A\u{FFFD}");
        assert_eq!(r.damaged, 2);
    }
}
