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

/// Bytes of Windows-1252 as text (`encoding_rs`, the WHATWG mapping: the five bytes the code
/// page leaves undefined keep their C1 control).
#[must_use]
pub fn windows_1252(bytes: &[u8]) -> String {
    encoding_rs::WINDOWS_1252.decode_without_bom_handling(bytes).0.into_owned()
}

/// UTF-16 read as UTF-8, streamed through `encoding_rs`'s decoder: what a CSV reader expects. An
/// unpaired surrogate or an odd last byte becomes U+FFFD, counted in `damaged`.
pub struct Utf16ToUtf8<R> {
    inner: R,
    decoder: encoding_rs::Decoder,
    /// UTF-8 bytes decoded and not yet read, and how far they have been read.
    out: Vec<u8>,
    at: usize,
    done: bool,
    pub damaged: u64,
}

impl<R> std::fmt::Debug for Utf16ToUtf8<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Utf16ToUtf8").field("done", &self.done).field("damaged", &self.damaged).finish_non_exhaustive()
    }
}

impl<R: Read> Utf16ToUtf8<R> {
    pub fn new(inner: R, big_endian: bool) -> Self {
        let encoding = if big_endian { encoding_rs::UTF_16BE } else { encoding_rs::UTF_16LE };
        Self {
            inner,
            decoder: encoding.new_decoder_without_bom_handling(),
            out: Vec::new(),
            at: 0,
            done: false,
            damaged: 0,
        }
    }
}

impl<R: Read> Read for Utf16ToUtf8<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while self.at >= self.out.len() && !self.done {
            let mut raw = [0u8; 8192];
            let n = self.inner.read(&mut raw)?;
            let last = n == 0;
            let src = raw.get(..n).unwrap_or_default();
            // Room for every code unit as three UTF-8 bytes, and the replacements at the end.
            self.out.clear();
            self.out.resize(self.decoder.max_utf8_buffer_length(n).unwrap_or(n * 3 + 16), 0);
            let (_, _, written, replaced) = self.decoder.decode_to_utf8(src, &mut self.out, last);
            self.out.truncate(written);
            self.at = 0;
            if replaced {
                let fffd = "\u{FFFD}".as_bytes();
                self.damaged += self.out.windows(fffd.len()).filter(|w| *w == fffd).count() as u64;
            }
            self.done = last;
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
