//! Modbus TCP ADU: the MBAP header (transaction id, protocol id, length, unit id) and the PDU
//! (Modbus Messaging on TCP/IP v1.0b §3.1.3).
//!
//! Contract of [`parse_tcp_frame`] on a byte stream: `Ok(Streaming::Incomplete(n))` — at least
//! `n` bytes in total are needed; `Ok(Streaming::Complete(frame, consumed))` — one frame from the
//! front; `Err(_)` — the header is invalid and the stream cannot be resynchronised.

use nom::Parser;
use nom::number::complete::{be_u16, u8 as byte};

use super::error::AduError;

/// MBAP header length (Modbus Messaging on TCP/IP v1.0b §3.1.3: 7 bytes).
pub const MBAP_LEN: usize = 7;
/// Modbus protocol identifier (§3.1.3: "0 = MODBUS protocol").
pub const MODBUS_PROTOCOL_ID: u16 = 0;
/// The length field counts the unit id and the PDU: at least unit + function code.
pub const MBAP_MIN_LENGTH: u16 = 2;
/// A PDU is at most 253 bytes (MAP v1.1b3 §4.1), so unit + PDU is at most 254.
pub const MBAP_MAX_LENGTH: u16 = 254;

/// The MBAP header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MbapHeader {
    pub transaction_id: u16,
    pub protocol_id: u16,
    /// Bytes that follow the length field: unit id + PDU.
    pub length: u16,
    pub unit: u8,
}

/// A TCP frame split into header and PDU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TcpFrame<'a> {
    pub header: MbapHeader,
    pub pdu: &'a [u8],
}

/// Result of parsing from the front of a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Streaming<T> {
    /// At least this many bytes in total are needed.
    Incomplete(usize),
    /// A frame, and how many bytes it took.
    Complete(T, usize),
}

/// Parses the 7-byte MBAP header from the front of `input` (nom style).
///
/// # Errors
/// A nom error when fewer than 7 bytes are given.
pub fn parse_mbap(input: &[u8]) -> nom::IResult<&[u8], MbapHeader> {
    (be_u16, be_u16, be_u16, byte).parse(input).map(|(rest, (transaction_id, protocol_id, length, unit))| {
        (rest, MbapHeader { transaction_id, protocol_id, length, unit })
    })
}

/// Parses one frame from the front of a stream. See the module documentation for the contract.
///
/// # Errors
/// [`AduError::ProtocolId`] or [`AduError::Length`] for a header no Modbus peer may send.
pub fn parse_tcp_frame(input: &[u8]) -> Result<Streaming<TcpFrame<'_>>, AduError> {
    let Ok((rest, header)) = parse_mbap(input) else {
        return Ok(Streaming::Incomplete(MBAP_LEN));
    };
    if header.protocol_id != MODBUS_PROTOCOL_ID {
        return Err(AduError::ProtocolId(header.protocol_id));
    }
    if !(MBAP_MIN_LENGTH..=MBAP_MAX_LENGTH).contains(&header.length) {
        return Err(AduError::Length(header.length));
    }
    // `length` counts the unit id, which parse_mbap already consumed.
    let pdu_len = usize::from(header.length) - 1;
    match rest.get(..pdu_len) {
        Some(pdu) => Ok(Streaming::Complete(TcpFrame { header, pdu }, MBAP_LEN + pdu_len)),
        None => Ok(Streaming::Incomplete(MBAP_LEN + pdu_len)),
    }
}

/// Parses exactly one whole frame (no bytes before or after).
///
/// # Errors
/// Header errors as [`parse_tcp_frame`], [`AduError::TooShort`], or
/// [`AduError::LengthMismatch`] when the length field disagrees with the bytes given.
pub fn parse_tcp(frame: &[u8]) -> Result<TcpFrame<'_>, AduError> {
    match parse_tcp_frame(frame)? {
        Streaming::Complete(f, used) if used == frame.len() => Ok(f),
        Streaming::Complete(f, _) => Err(AduError::LengthMismatch {
            declared: usize::from(f.header.length),
            actual: frame.len().saturating_sub(MBAP_LEN - 1),
        }),
        Streaming::Incomplete(_) if frame.len() < MBAP_LEN + 1 => {
            Err(AduError::TooShort { mode: "TCP", len: frame.len(), min: MBAP_LEN + 1 })
        }
        Streaming::Incomplete(n) => Err(AduError::LengthMismatch {
            declared: n - (MBAP_LEN - 1),
            actual: frame.len().saturating_sub(MBAP_LEN - 1),
        }),
    }
}

/// Appends a TCP frame. A PDU longer than 253 bytes gets a length field that says so honestly
/// (saturated at 65535) and peers will reject it.
pub fn encode_tcp(transaction_id: u16, unit: u8, pdu: &[u8], out: &mut Vec<u8>) {
    let length = u16::try_from(pdu.len() + 1).unwrap_or(u16::MAX);
    out.extend_from_slice(&transaction_id.to_be_bytes());
    out.extend_from_slice(&MODBUS_PROTOCOL_ID.to_be_bytes());
    out.extend_from_slice(&length.to_be_bytes());
    out.push(unit);
    out.extend_from_slice(pdu);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Transaction 0x0001, protocol 0, length 6, unit 0x11, PDU `03 00 6B 00 03`.
    const READ_REQUEST: &[u8] = &[0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x11, 0x03, 0x00, 0x6B, 0x00, 0x03];

    #[test]
    fn streams_need_more_then_frame() {
        assert_eq!(parse_tcp_frame(&READ_REQUEST[..3]), Ok(Streaming::Incomplete(7)));
        assert_eq!(parse_tcp_frame(&READ_REQUEST[..9]), Ok(Streaming::Incomplete(12)));
        let Ok(Streaming::Complete(f, 12)) = parse_tcp_frame(READ_REQUEST) else { panic!() };
        assert_eq!(f.header.unit, 0x11);
        assert_eq!(f.pdu, &READ_REQUEST[7..]);
    }

    #[test]
    fn bad_headers_are_invalid() {
        let mut bad = READ_REQUEST.to_vec();
        bad[3] = 1;
        assert_eq!(parse_tcp_frame(&bad), Err(AduError::ProtocolId(1)));
        for len in [0u16, 1, 255, 0xFFFF] {
            let mut bad = READ_REQUEST.to_vec();
            bad[4..6].copy_from_slice(&len.to_be_bytes());
            assert_eq!(parse_tcp_frame(&bad), Err(AduError::Length(len)));
        }
    }

    #[test]
    fn whole_frame_length_must_agree() {
        let mut long = READ_REQUEST.to_vec();
        long.push(0);
        assert!(matches!(parse_tcp(&long), Err(AduError::LengthMismatch { .. })));
    }
}
