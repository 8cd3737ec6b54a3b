//! ASCII ADU: ':' + hex pairs (address, PDU, LRC) + CR LF (Modbus over Serial Line v1.02
//! §2.5.2.1). Upper-case hex is the spec's; lower case is accepted and flagged.

use super::checksum::lrc;
use super::error::AduError;

/// Start of frame (Modbus over Serial Line v1.02 §2.5.2.1).
pub const ASCII_START: u8 = b':';
/// End of frame: CR LF (Modbus over Serial Line v1.02 §2.5.2.1; the LF is changeable by
/// Diagnostics sub-function 03, which we do not track).
pub const ASCII_END: &[u8; 2] = b"\r\n";
/// ':' + address + function + LRC, two characters each.
pub const ASCII_MIN_LEN: usize = 7;
/// "The maximum size of a MODBUS ASCII frame is 513 characters" (§2.5.2.1).
pub const ASCII_MAX_LEN: usize = 513;

/// One ASCII frame decoded from its characters. Owned: hex has to be decoded somewhere.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AsciiFrame {
    /// Address, PDU and LRC as binary bytes.
    binary: Vec<u8>,
    pub lrc_computed: u8,
    /// Some hex digits were lower case.
    pub lowercase: bool,
    /// The frame ended with CR LF.
    pub terminated: bool,
}

impl AsciiFrame {
    #[must_use]
    pub fn unit(&self) -> u8 {
        self.binary.first().copied().unwrap_or(0)
    }
    /// Function code and data.
    #[must_use]
    pub fn pdu(&self) -> &[u8] {
        self.binary.get(1..self.binary.len().saturating_sub(1)).unwrap_or(&[])
    }
    #[must_use]
    pub fn lrc_received(&self) -> u8 {
        self.binary.last().copied().unwrap_or(0)
    }
    #[must_use]
    pub fn check_ok(&self) -> bool {
        self.lrc_received() == self.lrc_computed
    }
}

const fn hex_value(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'A'..=b'F' => Some(c - b'A' + 10),
        b'a'..=b'f' => Some(c - b'a' + 10),
        _ => None,
    }
}

/// Decodes one ASCII frame: ':' then hex pairs, then optionally CR LF.
///
/// # Errors
/// [`AduError::MissingStart`], [`AduError::BadCharacter`] (position counted from the ':'),
/// [`AduError::OddDigits`], [`AduError::TooShort`].
pub fn parse_ascii(chars: &[u8]) -> Result<AsciiFrame, AduError> {
    let Some((&first, rest)) = chars.split_first() else {
        return Err(AduError::TooShort { mode: "ASCII", len: 0, min: ASCII_MIN_LEN });
    };
    if first != ASCII_START {
        return Err(AduError::MissingStart { found: first });
    }
    let (digits, terminated) = match rest.strip_suffix(ASCII_END) {
        Some(d) => (d, true),
        None => (rest, false),
    };
    if let Some(i) = digits.iter().position(|&c| hex_value(c).is_none()) {
        return Err(AduError::BadCharacter { position: i + 1, byte: digits[i] });
    }
    if digits.len() % 2 == 1 {
        return Err(AduError::OddDigits { digits: digits.len() });
    }
    if chars.len() < ASCII_MIN_LEN {
        return Err(AduError::TooShort { mode: "ASCII", len: chars.len(), min: ASCII_MIN_LEN });
    }
    let binary: Vec<u8> =
        digits.chunks_exact(2).map(|p| (hex_value(p[0]).unwrap_or(0) << 4) | hex_value(p[1]).unwrap_or(0)).collect();
    let lrc_computed = lrc(&binary[..binary.len() - 1]);
    Ok(AsciiFrame { binary, lrc_computed, lowercase: digits.iter().any(u8::is_ascii_lowercase), terminated })
}

/// Appends an ASCII frame for `unit` and `pdu`: ':', upper-case hex, LRC, CR LF.
pub fn encode_ascii(unit: u8, pdu: &[u8], out: &mut Vec<u8>) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let push_hex = |out: &mut Vec<u8>, b: u8| {
        out.push(HEX[usize::from(b >> 4)]);
        out.push(HEX[usize::from(b & 0x0F)]);
    };
    out.push(ASCII_START);
    push_hex(out, unit);
    for &b in pdu {
        push_hex(out, b);
    }
    let check = pdu.iter().fold(unit, |acc, &b| acc.wrapping_add(b)).wrapping_neg();
    push_hex(out, check);
    out.extend_from_slice(ASCII_END);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_character_is_located() {
        assert_eq!(parse_ascii(b":01G3006500039\r\n"), Err(AduError::BadCharacter { position: 3, byte: b'G' }));
    }

    #[test]
    fn lower_case_is_accepted_and_flagged() {
        let f = parse_ascii(b":0106006c000a83\r\n").unwrap();
        assert!(f.check_ok());
        assert!(f.lowercase);
    }

    #[test]
    fn encode_matches_mk4_example() {
        let mut out = Vec::new();
        encode_ascii(1, &[0x03, 0x00, 0x65, 0x00, 0x03], &mut out);
        assert_eq!(out, b":010300650003 94\r\n".iter().copied().filter(|&c| c != b' ').collect::<Vec<_>>());
    }
}
