//! Decoding a PDU with a direction hint. Requests and responses often share a shape (0x05,
//! 0x06, 0x08, 0x16 echo; 0x0F/0x10 responses repeat the request header), so when the
//! direction is unknown the decoder says what the bytes can be instead of guessing silently.

use super::error::PduError;
use super::findings::{Finding, check_pair, check_request, check_response};
use super::request::{Request, parse_request};
use super::response::{Response, parse_response};

/// Which way a frame travels, when the caller knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DirectionHint {
    Request,
    Response,
    Unknown,
}

/// A parsed request or response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pdu<'a> {
    Request(Request<'a>),
    Response(Response<'a>),
}

impl Pdu<'_> {
    /// The function byte as on the wire.
    #[must_use]
    pub const fn function_byte(&self) -> u8 {
        match self {
            Self::Request(r) => r.function_byte(),
            Self::Response(r) => r.function_byte(),
        }
    }

    /// True for a response.
    #[must_use]
    pub const fn is_response(&self) -> bool {
        matches!(self, Self::Response(_))
    }
}

/// A PDU with what follows its last field and the findings on it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodedPdu<'a> {
    pub pdu: Pdu<'a>,
    pub trailing: &'a [u8],
    pub findings: Vec<Finding>,
}

impl DecodedPdu<'_> {
    /// Re-encodes the PDU and its trailing bytes: for anything the parser produced, exactly the
    /// bytes it was parsed from.
    ///
    /// # Errors
    /// Only for hand-built values whose slices overflow their byte counts.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<(), super::EncodeError> {
        match &self.pdu {
            Pdu::Request(r) => r.encode(out)?,
            Pdu::Response(r) => r.encode(out)?,
        }
        out.extend_from_slice(self.trailing);
        Ok(())
    }
}

/// What a PDU decodes to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PduDecode<'a> {
    /// One reading (the hint's, or the only one that fits).
    One(DecodedPdu<'a>),
    /// Direction unknown and the bytes read cleanly both ways (an echo-shaped frame).
    Either { request: DecodedPdu<'a>, response: DecodedPdu<'a> },
    /// The bytes do not fit the structure of their function code in the direction(s) tried.
    Malformed { function: Option<u8>, error: PduError },
}

fn as_request(pdu: &[u8]) -> Result<DecodedPdu<'_>, PduError> {
    let (trailing, req) = parse_request(pdu)?;
    let mut findings = Vec::new();
    check_request(&req, &mut findings);
    if !trailing.is_empty() {
        findings.push(Finding::TrailingBytes { count: trailing.len() });
    }
    Ok(DecodedPdu { pdu: Pdu::Request(req), trailing, findings })
}

fn as_response(pdu: &[u8]) -> Result<DecodedPdu<'_>, PduError> {
    let (trailing, resp) = parse_response(pdu)?;
    let mut findings = Vec::new();
    check_response(&resp, &mut findings);
    if !trailing.is_empty() {
        findings.push(Finding::TrailingBytes { count: trailing.len() });
    }
    Ok(DecodedPdu { pdu: Pdu::Response(resp), trailing, findings })
}

/// Decodes `pdu` (function code first) in the direction `hint` says, or both ways when unknown.
///
/// With [`DirectionHint::Unknown`]: a function byte with 0x80 set is an exception response; a
/// reading with no trailing bytes beats one with; two clean readings give [`PduDecode::Either`];
/// among two readings with trailing bytes the one with fewer wins (the request on a tie).
#[must_use]
pub fn decode_pdu<'a>(pdu: &'a [u8], hint: DirectionHint) -> PduDecode<'a> {
    let function = pdu.first().copied();
    let wrap = |r: Result<DecodedPdu<'a>, PduError>| -> PduDecode<'a> {
        match r {
            Ok(d) => PduDecode::One(d),
            Err(error) => PduDecode::Malformed { function, error },
        }
    };
    match hint {
        DirectionHint::Request => wrap(as_request(pdu)),
        DirectionHint::Response => wrap(as_response(pdu)),
        DirectionHint::Unknown if function.is_some_and(|f| f & 0x80 != 0) => wrap(as_response(pdu)),
        DirectionHint::Unknown => match (as_request(pdu), as_response(pdu)) {
            (Ok(request), Ok(response)) => match (request.trailing.is_empty(), response.trailing.is_empty()) {
                (true, true) => PduDecode::Either { request, response },
                (false, true) => PduDecode::One(response),
                (false, false) if response.trailing.len() < request.trailing.len() => PduDecode::One(response),
                (true | false, false) => PduDecode::One(request),
            },
            (Ok(d), Err(_)) | (Err(_), Ok(d)) => PduDecode::One(d),
            (Err(error), Err(_)) => PduDecode::Malformed { function, error },
        },
    }
}

/// Findings on a response against its request, for a transaction.
#[must_use]
pub fn pair_findings(request: &Request<'_>, response: &Response<'_>) -> Vec<Finding> {
    let mut out = Vec::new();
    check_pair(request, response, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_request_is_not_mistaken_for_a_response() {
        let d = decode_pdu(&[0x03, 0x00, 0x65, 0x00, 0x03], DirectionHint::Unknown);
        assert!(matches!(d, PduDecode::One(DecodedPdu { pdu: Pdu::Request(_), .. })), "{d:?}");
    }

    #[test]
    fn read_response_is_not_mistaken_for_a_request() {
        let d = decode_pdu(&[0x03, 0x02, 0x00, 0x07], DirectionHint::Unknown);
        assert!(matches!(d, PduDecode::One(DecodedPdu { pdu: Pdu::Response(_), .. })), "{d:?}");
    }

    #[test]
    fn echo_shapes_are_either() {
        let d = decode_pdu(&[0x06, 0x00, 0x6C, 0x00, 0x0A], DirectionHint::Unknown);
        assert!(matches!(d, PduDecode::Either { .. }), "{d:?}");
    }

    #[test]
    fn hint_is_obeyed() {
        let d = decode_pdu(&[0x06, 0x00, 0x6C, 0x00, 0x0A], DirectionHint::Response);
        assert!(matches!(d, PduDecode::One(DecodedPdu { pdu: Pdu::Response(_), .. })), "{d:?}");
    }

    #[test]
    fn trailing_bytes_are_a_finding() {
        let PduDecode::One(d) = decode_pdu(&[0x03, 0x00, 0x65, 0x00, 0x03, 0xEE], DirectionHint::Request) else {
            panic!()
        };
        assert_eq!(d.findings, vec![Finding::TrailingBytes { count: 1 }]);
    }

    #[test]
    fn empty_pdu_is_malformed() {
        assert_eq!(
            decode_pdu(&[], DirectionHint::Unknown),
            PduDecode::Malformed { function: None, error: PduError::Empty }
        );
    }
}
