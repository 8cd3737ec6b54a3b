//! How long a PDU is, from its first bytes: the structure the RTU framer uses to find where a
//! frame ends when timing cannot tell, and what a truncation error reports as "needed".
//!
//! Lengths are whole-PDU lengths (function code included) and come from the layouts of
//! MAP v1.1b3 §6. Every sum is checked; nothing here can panic on any input.

use super::function::{EXCEPTION_FLAG, FunctionCode as F};

/// What the first bytes of a PDU say about its total length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PduLength {
    /// The PDU is exactly this many bytes.
    Exact(usize),
    /// At least this many bytes are needed before the length can be known.
    AtLeast(usize),
    /// The structure does not determine the length (unknown or user-defined function,
    /// Diagnostics "Return Query Data", a MEI type without a fixed layout).
    Unknown,
}

impl PduLength {
    /// The number of bytes known to be required (for error messages), or `None`.
    #[must_use]
    pub const fn needed(self) -> Option<usize> {
        match self {
            Self::Exact(n) | Self::AtLeast(n) => Some(n),
            Self::Unknown => None,
        }
    }
}

/// `fixed + prefix[at]`, or "need `at + 1` bytes" while the count byte is missing.
fn counted_u8(prefix: &[u8], at: usize, fixed: usize) -> PduLength {
    match prefix.get(at) {
        Some(&n) => PduLength::Exact(fixed + usize::from(n)),
        None => PduLength::AtLeast(at + 1),
    }
}

/// Length of a request PDU that starts with `prefix`.
#[must_use]
pub fn request_len(prefix: &[u8]) -> PduLength {
    let Some(&fc) = prefix.first() else {
        return PduLength::AtLeast(1);
    };
    match F::from(fc) {
        F::ReadCoils
        | F::ReadDiscreteInputs
        | F::ReadHoldingRegisters
        | F::ReadInputRegisters
        | F::WriteSingleCoil
        | F::WriteSingleRegister => PduLength::Exact(5),
        F::ReadExceptionStatus | F::GetCommEventCounter | F::GetCommEventLog | F::ReportServerId => PduLength::Exact(1),
        F::Diagnostics => diagnostics_len(prefix),
        // fc, address, quantity, byte count, values.
        F::WriteMultipleCoils | F::WriteMultipleRegisters => counted_u8(prefix, 5, 6),
        // fc, byte count, sub-requests.
        F::ReadFileRecord | F::WriteFileRecord => counted_u8(prefix, 1, 2),
        F::MaskWriteRegister => PduLength::Exact(7),
        // fc, read addr, read qty, write addr, write qty, byte count, values.
        F::ReadWriteMultipleRegisters => counted_u8(prefix, 9, 10),
        F::ReadFifoQueue => PduLength::Exact(3),
        F::EncapsulatedInterface => match prefix.get(1) {
            // fc, MEI type, read device id code, object id.
            Some(0x0E) => PduLength::Exact(4),
            Some(_) => PduLength::Unknown,
            None => PduLength::AtLeast(2),
        },
        F::Other(_) => PduLength::Unknown,
    }
}

/// Sub-function 0x0000 echoes any number of bytes; the others carry one 16-bit data field
/// (MAP v1.1b3 §6.8.1).
fn diagnostics_len(prefix: &[u8]) -> PduLength {
    match (prefix.get(1), prefix.get(2)) {
        (Some(&hi), Some(&lo)) if u16::from_be_bytes([hi, lo]) == 0 => PduLength::Unknown,
        (Some(_), Some(_)) => PduLength::Exact(5),
        _ => PduLength::AtLeast(3),
    }
}

/// Length of a response PDU that starts with `prefix`.
#[must_use]
pub fn response_len(prefix: &[u8]) -> PduLength {
    let Some(&fc) = prefix.first() else {
        return PduLength::AtLeast(1);
    };
    if fc & EXCEPTION_FLAG != 0 {
        // Function | 0x80, exception code (MAP v1.1b3 §7).
        return PduLength::Exact(2);
    }
    match F::from(fc) {
        F::ReadCoils
        | F::ReadDiscreteInputs
        | F::ReadHoldingRegisters
        | F::ReadInputRegisters
        | F::GetCommEventLog
        | F::ReportServerId
        | F::ReadFileRecord
        | F::WriteFileRecord
        | F::ReadWriteMultipleRegisters => counted_u8(prefix, 1, 2),
        F::WriteSingleCoil | F::WriteSingleRegister | F::WriteMultipleCoils | F::WriteMultipleRegisters => {
            PduLength::Exact(5)
        }
        F::ReadExceptionStatus => PduLength::Exact(2),
        F::Diagnostics => diagnostics_len(prefix),
        F::GetCommEventCounter => PduLength::Exact(5),
        F::MaskWriteRegister => PduLength::Exact(7),
        // fc, byte count (u16), then byte count bytes (FIFO count + values).
        F::ReadFifoQueue => match (prefix.get(1), prefix.get(2)) {
            (Some(&hi), Some(&lo)) => PduLength::Exact(3 + usize::from(u16::from_be_bytes([hi, lo]))),
            _ => PduLength::AtLeast(3),
        },
        F::EncapsulatedInterface => match prefix.get(1) {
            Some(0x0E) => device_id_response_len(prefix),
            Some(_) => PduLength::Unknown,
            None => PduLength::AtLeast(2),
        },
        F::Other(_) => PduLength::Unknown,
    }
}

/// Length of the normal (non-exception) answer PDU to the whole request PDU `request`: what a
/// half-duplex bus's next frame must be when it answers. Exceptions are always 2 bytes
/// (MAP v1.1b3 §7).
///
/// Layouts from MAP v1.1b3 §6: reads answer `fc, byte count, data` (01/02: one bit each,
/// §6.1–6.2; 03/04: two bytes a register, §6.3–6.4; 17: the read quantity, §6.17); single
/// and multiple writes answer `fc, address, value|quantity` (§6.5, 6.6, 6.11, 6.12); 07 answers
/// one status byte (§6.7); 08 echoes its request for the sub-functions a bus carries (§6.8);
/// 0B a status and a count (§6.9); 16 echoes its request (§6.16).
#[must_use]
pub fn answer_len(request: &[u8]) -> PduLength {
    let Some(&fc) = request.first() else {
        return PduLength::AtLeast(1);
    };
    let quantity = |at: usize| request.get(at..at + 2).map(|q| usize::from(u16::from_be_bytes([q[0], q[1]])));
    match F::from(fc) {
        F::ReadCoils | F::ReadDiscreteInputs => match quantity(3) {
            Some(q) => PduLength::Exact(2 + q.div_ceil(8)),
            None => PduLength::AtLeast(5),
        },
        // 17 answers its read quantity, which stands where 03/04 keep theirs.
        F::ReadHoldingRegisters | F::ReadInputRegisters | F::ReadWriteMultipleRegisters => match quantity(3) {
            Some(q) => PduLength::Exact(2 + 2 * q),
            None => PduLength::AtLeast(5),
        },
        F::WriteSingleCoil | F::WriteSingleRegister | F::WriteMultipleCoils | F::WriteMultipleRegisters => {
            PduLength::Exact(5)
        }
        F::ReadExceptionStatus => PduLength::Exact(2),
        F::GetCommEventCounter => PduLength::Exact(5),
        F::MaskWriteRegister => PduLength::Exact(7),
        F::Diagnostics => PduLength::Exact(request.len()),
        _ => PduLength::Unknown,
    }
}

/// What is wrong with the length of a whole request PDU, or `None` when its function's
/// structure agrees with it (or fixes no length: vendor codes, Diagnostics 0000).
///
/// A gateway that forwards a PDU longer than its function allows puts the extra bytes on the
/// serial line right behind the request, where a slave that frames by structure reads them as
/// a second frame (a CRC-valid write smuggled behind a read). Layouts: MAP v1.1b3 §6 (01–06
/// five bytes; 0F/10/17 by their byte counts; 2B/0E four bytes).
#[must_use]
pub fn request_len_problem(pdu: &[u8]) -> Option<String> {
    match request_len(pdu) {
        PduLength::Exact(n) if n == pdu.len() => None,
        PduLength::Exact(n) => Some(format!(
            "function 0x{:02X} takes a {n}-byte PDU (its structure{}), this one has {}",
            pdu.first().copied().unwrap_or(0),
            if matches!(pdu.first(), Some(0x0F | 0x10 | 0x17 | 0x14 | 0x15)) { " and byte count" } else { "" },
            pdu.len()
        )),
        PduLength::AtLeast(n) => Some(format!("a {}-byte PDU is cut short: at least {n} bytes needed", pdu.len())),
        PduLength::Unknown => None,
    }
}

/// Whether `answer` (a response PDU) can be the answer to `request` (its request PDU): the
/// same function (or its exception, MAP v1.1b3 §7), as long as the request fixes, and for the
/// functions that echo (05, 06, 0F, 10, 16, 08) the same address, sub-function or echo. An
/// answer that fails this is another request's (a late answer after a timeout), never this
/// one's.
#[must_use]
pub fn answer_fits(request: &[u8], answer: &[u8]) -> bool {
    let (Some(&fc), Some(&afc)) = (request.first(), answer.first()) else {
        return false;
    };
    if afc == fc | EXCEPTION_FLAG {
        return answer.len() == 2;
    }
    if afc != fc {
        return false;
    }
    if let PduLength::Exact(n) = answer_len(request)
        && n != answer.len()
    {
        return false;
    }
    match fc {
        // Single writes and Mask Write echo their request (§6.5, 6.6, 6.16).
        0x05 | 0x06 | 0x16 => answer == request,
        // Diagnostics answers its sub-function (§6.8; sub-functions other than 0000 answer
        // their own data field), device identification its MEI type and read code (§6.21).
        0x08 | 0x2B => answer.get(..3) == request.get(..3),
        // Multiple writes answer address and quantity (§6.11, 6.12).
        0x0F | 0x10 => answer.get(..5) == request.get(..5),
        _ => true,
    }
}

/// fc, MEI, read code, conformity, more follows, next object id, object count, then per object:
/// id, length, value (MAP v1.1b3 §6.21).
fn device_id_response_len(prefix: &[u8]) -> PduLength {
    const HEADER: usize = 7;
    let Some(&count) = prefix.get(HEADER - 1) else {
        return PduLength::AtLeast(HEADER);
    };
    let mut at = HEADER;
    for _ in 0..count {
        match prefix.get(at + 1) {
            Some(&len) => at += 2 + usize::from(len),
            None => return PduLength::AtLeast(at + 2),
        }
    }
    PduLength::Exact(at)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_requests() {
        assert_eq!(request_len(&[0x03]), PduLength::Exact(5));
        assert_eq!(request_len(&[0x11]), PduLength::Exact(1));
        assert_eq!(request_len(&[0x2B, 0x0E]), PduLength::Exact(4));
        assert_eq!(request_len(&[0x2B]), PduLength::AtLeast(2));
        assert_eq!(request_len(&[0x41]), PduLength::Unknown);
        assert_eq!(request_len(&[]), PduLength::AtLeast(1));
    }

    #[test]
    fn counted_requests_need_their_count_byte() {
        assert_eq!(request_len(&[0x10, 0, 0x65, 0, 5]), PduLength::AtLeast(6));
        assert_eq!(request_len(&[0x10, 0, 0x65, 0, 5, 10]), PduLength::Exact(16));
        assert_eq!(request_len(&[0x17, 0, 0, 0, 1, 0, 0, 0, 1, 2]), PduLength::Exact(12));
    }

    #[test]
    fn responses() {
        assert_eq!(response_len(&[0x83]), PduLength::Exact(2));
        assert_eq!(response_len(&[0x03, 6]), PduLength::Exact(8));
        assert_eq!(response_len(&[0x18, 0, 6]), PduLength::Exact(9));
        assert_eq!(response_len(&[0x08, 0, 0]), PduLength::Unknown);
        assert_eq!(response_len(&[0x08, 0, 0x0B]), PduLength::Exact(5));
    }

    #[test]
    fn answers_are_sized_by_their_requests() {
        // Read 3 holding registers from 0x006B: fc, byte count 6, six data bytes.
        assert_eq!(answer_len(&[0x03, 0x00, 0x6B, 0x00, 0x03]), PduLength::Exact(8));
        // Read 19 coils: fc, byte count 3, three data bytes.
        assert_eq!(answer_len(&[0x01, 0x00, 0x13, 0x00, 0x13]), PduLength::Exact(5));
        assert_eq!(answer_len(&[0x06, 0x00, 0x01, 0x00, 0x03]), PduLength::Exact(5));
        assert_eq!(answer_len(&[0x08, 0x00, 0x00, 0xA5, 0x37]), PduLength::Exact(5));
        assert_eq!(answer_len(&[0x03, 0x00]), PduLength::AtLeast(5));
        assert_eq!(answer_len(&[0x41, 1, 2]), PduLength::Unknown);
        assert_eq!(answer_len(&[0x03, 0x00, 0x00, 0xFF, 0xFF]), PduLength::Exact(2 + 2 * 65_535), "no overflow");
    }

    #[test]
    fn device_id_response_walks_objects() {
        // fc, MEI, code, conformity, more, next, count=2, (0, len 1, 'A'), (1, len 2, 'B','C')
        let pdu = [0x2B, 0x0E, 1, 1, 0, 0, 2, 0, 1, b'A', 1, 2, b'B', b'C'];
        assert_eq!(response_len(&pdu), PduLength::Exact(pdu.len()));
        assert_eq!(response_len(&pdu[..8]), PduLength::AtLeast(9));
    }
    /// A read with a whole write frame behind it is named too long for its function, never sent on
    /// as two frames.
    #[test]
    fn a_request_longer_than_its_function_allows_is_named() {
        // FC 03, address 0x0064, quantity 1 — then `01 06 00 65 00 2A` + CRC smuggled behind.
        let smuggled = [0x03, 0x00, 0x64, 0x00, 0x01, 0x01, 0x06, 0x00, 0x65, 0x00, 0x2A, 0x18, 0x0B];
        let why = request_len_problem(&smuggled).unwrap();
        assert!(why.contains("5-byte") && why.contains("13"), "{why}");
        assert_eq!(request_len_problem(&smuggled[..5]), None);
        // 0x10 by its byte count: 2 registers, byte count 4, 4 data bytes (10 bytes), then one more.
        let long = [0x10, 0x00, 0x01, 0x00, 0x02, 0x04, 0, 1, 0, 2, 0xFF];
        assert!(request_len_problem(&long).is_some());
        assert_eq!(request_len_problem(&long[..10]), None);
        assert!(request_len_problem(&[0x03, 0x00]).is_some(), "short");
        assert!(request_len_problem(&[0x2B, 0x0E, 1, 0, 9]).is_some());
        assert_eq!(request_len_problem(&[0x41, 1, 2, 3]), None, "a vendor code fixes no length");
    }

    /// An answer must fit its request: a late answer to another request is never handed to the next
    /// client.
    #[test]
    fn an_answer_must_fit_its_request() {
        let read2 = [0x03, 0x00, 0xA0, 0x00, 0x02];
        assert!(answer_fits(&read2, &[0x03, 0x04, 0, 1, 0, 2]));
        assert!(!answer_fits(&read2, &[0x03, 0x08, 0, 1, 0, 2, 0, 3, 0, 4]), "four registers to a request for two");
        assert!(!answer_fits(&read2, &[0x03, 0x04, 0, 1, 0]), "short");
        assert!(!answer_fits(&read2, &[0x04, 0x04, 0, 1, 0, 2]), "another function");
        assert!(answer_fits(&read2, &[0x83, 0x02]));
        let write = [0x06, 0x00, 0x65, 0x00, 0x2A];
        assert!(answer_fits(&write, &write));
        assert!(!answer_fits(&write, &[0x06, 0x00, 0x66, 0x00, 0x2A]), "another register's echo");
        let multi = [0x10, 0x00, 0x01, 0x00, 0x01, 0x02, 0x00, 0x07];
        assert!(answer_fits(&multi, &[0x10, 0x00, 0x01, 0x00, 0x01]));
        assert!(!answer_fits(&multi, &[0x10, 0x00, 0x02, 0x00, 0x01]));
        assert!(answer_fits(&[0x41, 1], &[0x41, 9, 9, 9]), "vendor codes: the function only");
        assert!(!answer_fits(&[], &[0x03]));
    }
}
