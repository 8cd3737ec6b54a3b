//! RTU ADU: address, PDU, CRC-16 low byte first (Modbus over Serial Line v1.02 §2.5.1.1).
//!
//! [`parse_rtu`] takes one delimited frame (the framer found its ends) and splits it; a bad CRC
//! is reported through [`RtuFrame::check_ok`], not as an error, so the user still sees the bytes.

use super::checksum::crc16;
use super::error::AduError;

/// Address + function + CRC (Modbus over Serial Line v1.02 §2.5.1.1).
pub const RTU_MIN_LEN: usize = 4;
/// "The maximum size of a MODBUS RTU frame is 256 bytes" (Modbus over Serial Line v1.02 §2.5.1.1).
pub const RTU_MAX_LEN: usize = 256;

/// One RTU frame split into its fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtuFrame<'a> {
    pub unit: u8,
    /// Function code and data.
    pub pdu: &'a [u8],
    /// The CRC as received (decoded from its low-byte-first order).
    pub crc_received: u16,
    /// The CRC of address + PDU.
    pub crc_computed: u16,
}

impl RtuFrame<'_> {
    /// True when the received CRC matches.
    #[must_use]
    pub const fn check_ok(&self) -> bool {
        self.crc_received == self.crc_computed
    }
}

/// Splits one whole RTU frame.
///
/// # Errors
/// [`AduError::TooShort`] below [`RTU_MIN_LEN`] bytes. Longer than [`RTU_MAX_LEN`] is not an
/// error here; callers flag it as a finding.
pub fn parse_rtu(frame: &[u8]) -> Result<RtuFrame<'_>, AduError> {
    let too_short = AduError::TooShort { mode: "RTU", len: frame.len(), min: RTU_MIN_LEN };
    let [body @ .., lo, hi] = frame else { return Err(too_short) };
    let [unit, pdu @ ..] = body else { return Err(too_short) };
    if pdu.is_empty() {
        return Err(too_short);
    }
    Ok(RtuFrame { unit: *unit, pdu, crc_received: u16::from_le_bytes([*lo, *hi]), crc_computed: crc16(body) })
}

/// Appends an RTU frame for `unit` and `pdu`, CRC included.
pub fn encode_rtu(unit: u8, pdu: &[u8], out: &mut Vec<u8>) {
    let start = out.len();
    out.push(unit);
    out.extend_from_slice(pdu);
    let crc = crc16(&out[start..]);
    out.extend_from_slice(&crc.to_le_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_short_frames_are_errors() {
        for n in 0..RTU_MIN_LEN {
            assert_eq!(
                parse_rtu(&[1, 3, 0][..n.min(3)]).unwrap_err(),
                AduError::TooShort { mode: "RTU", len: n.min(3), min: 4 }
            );
        }
    }

    #[test]
    fn encode_then_parse() {
        let mut out = Vec::new();
        encode_rtu(1, &[0x03, 0x00, 0x65, 0x00, 0x03], &mut out);
        assert_eq!(out, [0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4]);
        let f = parse_rtu(&out).unwrap();
        assert!(f.check_ok());
        assert_eq!(f.unit, 1);
    }
}
