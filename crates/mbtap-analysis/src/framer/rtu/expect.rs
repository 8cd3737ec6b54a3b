//! What the bus expects next, and how a frame was read: the expectation (after a request, that
//! unit's answer of a known length; after an answer, a request), the readings of a frame, and
//! the structural checks that rule readings out.

use super::RtuFramer;
use crate::framer::glitch::Sender;
use mbtap_proto::function::EXCEPTION_FLAG;
use mbtap_proto::length::{PduLength, request_len};
use mbtap_proto::{DirectionHint, PduDecode, decode_pdu};

/// How a valid frame was read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Reading {
    Request,
    Response,
    /// Both readings, at the same length (echo shapes: 05, 06, 08, 0F, 10 answers).
    Either,
    /// Neither reading fixes the length (vendor codes): the CRC and what follows ended it.
    Unknown,
}

impl Reading {
    /// The reading of one direction.
    pub(super) fn of(is_request: bool) -> Self {
        if is_request { Self::Request } else { Self::Response }
    }
}

/// Does `pdu`, read in this direction, decode as one PDU without findings (no absurd quantity,
/// no byte count its quantity contradicts)?
pub(super) fn decodes_clean(pdu: &[u8], is_request: bool) -> bool {
    let hint = if is_request { DirectionHint::Request } else { DirectionHint::Response };
    matches!(decode_pdu(pdu, hint), PduDecode::One(d) if d.findings.is_empty())
}

/// What the next frame on the bus should be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Expect {
    /// Nothing known yet (start of input, after damage nobody can place).
    Unknown,
    /// A request: the last transaction is complete.
    Request,
    /// The answer of `unit` to `fc`: `len` bytes (RTU ADU) when the request fixes it; an
    /// exception answer is 5 bytes whatever the request.
    Response { unit: u8, fc: u8, len: Option<usize> },
}

/// The highest unicast address (Modbus over Serial Line v1.02 §2.2: 1–247; 0 broadcast).
pub(super) const MAX_ADDRESS: u8 = 247;

/// Could the PDU, read in this direction, be well formed? Only the byte-count fields that a
/// quantity fixes are checked (MAP v1.1b3 §6): enough to rule out the wrong reading of most
/// frames without waiting for bytes that would only make a malformed frame.
pub(super) fn consistent(pdu: &[u8], is_request: bool) -> bool {
    let u16_at = |i: usize| pdu.get(i..i + 2).map(|b| usize::from(u16::from_be_bytes([b[0], b[1]])));
    let byte = |i: usize| pdu.get(i).map(|&b| usize::from(b));
    let Some(&fc) = pdu.first() else { return true };
    if is_request {
        match fc {
            0x0F => u16_at(3).zip(byte(5)).is_none_or(|(q, bc)| bc == q.div_ceil(8)),
            0x10 => u16_at(3).zip(byte(5)).is_none_or(|(q, bc)| bc == 2 * q),
            0x17 => u16_at(7).zip(byte(9)).is_none_or(|(q, bc)| bc == 2 * q),
            _ => true,
        }
    } else {
        match fc {
            0x01 | 0x02 => byte(1).is_none_or(|bc| bc >= 1),
            0x03 | 0x04 | 0x17 => byte(1).is_none_or(|bc| bc >= 2 && bc % 2 == 0),
            0x0C => byte(1).is_none_or(|bc| bc >= 6),
            _ => true,
        }
    }
}

/// For a Diagnostics frame `s` (function 08, not an exception) that checks both `l` and `l + 1`
/// bytes long: the length whose data after the sub-function is N × 2 bytes (MAP v1.1b3 §6.8).
pub(super) fn diagnostics_even_len(s: &[u8], l: usize) -> Option<usize> {
    // unit, function, sub-function (2), data, CRC (2)
    let data = l.checked_sub(6)?;
    (s.get(1) == Some(&0x08)).then_some(if data % 2 == 0 { l } else { l + 1 })
}

/// Who sent frame `f`, read as `reading` (valid) or failed (`None`), given what was expected.
pub(super) fn sender_of(expect: Expect, f: &[u8], reading: Option<Reading>) -> Sender {
    match (reading, expect, f) {
        (Some(Reading::Request), ..) | (Some(Reading::Either | Reading::Unknown) | None, Expect::Request, _) => {
            Sender::Master
        }
        (Some(Reading::Response), ..) => Sender::Slave,
        (_, Expect::Response { unit, fc, .. }, [u, f, ..]) if *u == unit && (*f == fc || *f == fc | EXCEPTION_FLAG) => {
            Sender::Slave
        }
        _ => Sender::Unknown,
    }
}

/// The expectation after a frame `f` read as `reading` (valid) or failed (`None`), given what
/// was expected before it.
pub(super) fn next_expect(expect: Expect, f: &[u8], reading: Option<Reading>) -> Expect {
    let as_request = |f: &[u8]| {
        let [unit, fc, ..] = *f else { return Expect::Unknown };
        if unit == 0 {
            // Broadcasts are not answered (Serial Line v1.02 §2.1).
            return Expect::Request;
        }
        let pdu = &f[1..f.len().saturating_sub(2).max(1)];
        let len = match mbtap_proto::answer_len(pdu) {
            PduLength::Exact(k) => k.checked_add(3),
            _ => None,
        };
        Expect::Response { unit, fc, len }
    };
    let answers_pending = |e: Expect| match (e, f) {
        (Expect::Response { unit, fc, .. }, [u, f, ..]) => *u == unit && (*f == fc || *f == fc | EXCEPTION_FLAG),
        _ => false,
    };
    match reading {
        // A failed frame ends the transaction it answered; otherwise nobody can say.
        None if matches!(expect, Expect::Response { .. }) => Expect::Request,
        Some(Reading::Request) => as_request(f),
        Some(Reading::Response) => Expect::Request,
        Some(Reading::Either | Reading::Unknown) if answers_pending(expect) => Expect::Request,
        Some(Reading::Either | Reading::Unknown) if expect == Expect::Request => as_request(f),
        None | Some(_) => Expect::Unknown,
    }
}

/// Could a frame start with these bytes at all? Function code 0 does not exist (MAP v1.1b3
/// §5: codes 1–127), nor its exception 0x80; a broadcast (address 0) carries a write only
/// (Serial Line v1.02 §2.1); an exception carries a code from 01 (MAP v1.1b3 §7). A CRC that
/// matches by chance over damage (1 in 65 536) is taken only where the header is possible.
pub(super) fn sane_header(f: &[u8], pasted: bool) -> bool {
    match *f {
        // Function 0 does not exist (MAP v1.1b3 §5.1); its exception `80` is kept only in pasted
        // text, where a slave answering for an absent one has been seen to send it.
        [_, 0x80, ..] if pasted => true,
        [_, fc, ..] if fc & !EXCEPTION_FLAG == 0 => false,
        // Exception codes start at 01 (MAP v1.1b3 §7): an "exception 00" is a chance match.
        [_, fc, 0, ..] if fc & EXCEPTION_FLAG != 0 => false,
        [0, fc, ..] => matches!(fc, 0x05 | 0x06 | 0x0F | 0x10 | 0x15 | 0x16),
        _ => true,
    }
}

impl RtuFramer {
    /// Is `n` bytes the length a damaged frame at absolute `a` (`== self.timed.head`) must have: the
    /// awaited answer's (an exception's 5), or — a request awaited — its own structure's?
    pub(super) fn expected_len_at(&self, a: usize, n: usize) -> bool {
        match self.expect {
            Expect::Response { unit, fc, len: Some(l) } if self.timed.buf[a] == unit => {
                n == if self.timed.buf.get(a + 1) == Some(&(fc | EXCEPTION_FLAG)) { 5 } else { l }
            }
            Expect::Request => {
                let f = &self.timed.buf[a..a + n];
                f.len() >= 2
                    && f[1] & EXCEPTION_FLAG == 0
                    && matches!(request_len(&f[1..]), PduLength::Exact(k) if k + 3 == n)
            }
            _ => false,
        }
    }

    /// What the bus expects of a frame at live index `g`: bytes before it that are not a lone
    /// glitch are damage nobody can read — one frame or several, requests or answers: after
    /// them nothing is expected.
    pub(super) fn expect_at(&self, g: usize) -> Expect {
        if g == 0 || (g == 1 && self.at_glitch(self.timed.head)) { self.expect } else { Expect::Unknown }
    }

    /// Does reading `l` bytes at live index `g` as `reading` give what the bus expects next?
    pub(super) fn expected(&self, g: usize, l: usize, reading: Reading) -> bool {
        let s = &self.timed.buf[self.timed.head + g..];
        match self.expect_at(g) {
            Expect::Unknown => false,
            Expect::Request => reading == Reading::Request,
            Expect::Response { unit, fc, len } => {
                reading == Reading::Response
                    && s.first() == Some(&unit)
                    && match s.get(1) {
                        Some(&f) if f == fc => len.is_none_or(|n| n == l),
                        // Exception: unit, function | 0x80, code, CRC (MAP v1.1b3 §7).
                        Some(&f) => f == fc | EXCEPTION_FLAG && l == 5,
                        None => false,
                    }
            }
        }
    }
}
