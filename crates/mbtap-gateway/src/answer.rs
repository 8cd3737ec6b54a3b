//! The one answer check: may this answer go back to the client that asked? Every back — a
//! serial line (RTU or ASCII), a serial server (`rtu-over-tcp://`, `rfc2217://`), a Modbus
//! TCP device (`tcp://`) and reverse mode's TCP server — puts each answer it hears through
//! [`check`] before a client sees it. An answer that does not fit its request is another
//! request's (a late answer after a timeout, a device that confused two clients, a unit that
//! answered for another): dropped, counted under [`Misfit::reason`], and the request waits on for
//! its own answer, is retried, or is answered 0x0B.

use mbtap_proto::{EXCEPTION_FLAG, PduLength, answer_fits, answer_len};

/// Why an answer is not the answer to the request awaited.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Misfit {
    /// It names another unit than the one asked (Serial Line v1.02 §2.2: the slave puts its
    /// own address in its answer; Messaging on TCP/IP v1.0b §3.1.3: the unit identifier is
    /// copied back).
    Unit,
    /// Another function than the one asked, nor its exception (MAP v1.1b3 §7).
    Function,
    /// Longer or shorter than the quantity asked makes it (MAP v1.1b3 §6: byte counts), or an
    /// exception that is not two bytes.
    Length,
    /// A write's answer that does not echo the address, value or quantity written (MAP v1.1b3
    /// §6.5, 6.6, 6.11, 6.12, 6.16), or a diagnostics / device identification answer for
    /// another sub-function (§6.8, §6.21).
    Echo,
}

impl Misfit {
    /// The label it is counted under (`mbtap_bridge_misfit_answers_total{reason}`).
    #[must_use]
    pub fn reason(self) -> &'static str {
        match self {
            Self::Unit => "unit",
            Self::Function => "function",
            Self::Length => "length",
            Self::Echo => "echo",
        }
    }
}

/// Checks the answer `answer` (a response PDU) from `answer_unit` against the request `request`
/// (its PDU) sent to `unit`.
///
/// # Errors
/// The first [`Misfit`] found, in the order unit, function, length, echoed fields.
pub fn check(unit: u8, request: &[u8], answer_unit: u8, answer: &[u8]) -> Result<(), Misfit> {
    if answer_unit != unit {
        return Err(Misfit::Unit);
    }
    let (Some(&fc), Some(&afc)) = (request.first(), answer.first()) else {
        return Err(Misfit::Length);
    };
    if afc != fc && afc != fc | EXCEPTION_FLAG {
        return Err(Misfit::Function);
    }
    if afc & EXCEPTION_FLAG != 0 && fc & EXCEPTION_FLAG == 0 {
        return if answer.len() == 2 { Ok(()) } else { Err(Misfit::Length) };
    }
    if let PduLength::Exact(n) = answer_len(request)
        && n != answer.len()
    {
        return Err(Misfit::Length);
    }
    // A counted answer's byte count must agree with its own length too (a device that says
    // 4 bytes and sends 6 is not to be believed for any of them).
    if matches!(fc, 0x01..=0x04 | 0x17) && answer.get(1).map(|&n| usize::from(n) + 2) != Some(answer.len()) {
        return Err(Misfit::Length);
    }
    if answer_fits(request, answer) { Ok(()) } else { Err(Misfit::Echo) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Read holding registers 100–101 (MAP v1.1b3 §6.3): function 03, address 0064, quantity 0002.
    const READ_TWO: [u8; 5] = [0x03, 0x00, 0x64, 0x00, 0x02];
    /// Its answer: function 03, byte count 04, values 044C 044D.
    const ANSWER_TWO: [u8; 6] = [0x03, 0x04, 0x04, 0x4C, 0x04, 0x4D];
    /// The same values as input registers (function 04): another function's answer.
    const ANSWER_TWO_FC04: [u8; 6] = [0x04, 0x04, 0x04, 0x4C, 0x04, 0x4D];
    /// One register more than asked: byte count 06.
    const ANSWER_THREE: [u8; 8] = [0x03, 0x06, 0x04, 0x4C, 0x04, 0x4D, 0x04, 0x4E];
    /// A byte count that says 4 while 6 data bytes follow.
    const ANSWER_COUNT_LIE: [u8; 8] = [0x03, 0x04, 0x04, 0x4C, 0x04, 0x4D, 0x04, 0x4E];
    /// Exception 02 to function 03 (MAP v1.1b3 §7).
    const EXCEPTION_02: [u8; 2] = [0x83, 0x02];
    /// Write single register 10 = 25 (§6.6) and an answer echoing another value.
    const WRITE_10: [u8; 5] = [0x06, 0x00, 0x0A, 0x00, 0x19];
    const WRITE_10_OTHER: [u8; 5] = [0x06, 0x00, 0x0A, 0x00, 0x1A];

    #[test]
    fn the_answer_to_the_request_fits() {
        assert_eq!(check(1, &READ_TWO, 1, &ANSWER_TWO), Ok(()));
        assert_eq!(check(1, &READ_TWO, 1, &EXCEPTION_02), Ok(()));
        assert_eq!(check(1, &WRITE_10, 1, &WRITE_10), Ok(()));
    }

    /// Each misfit of a `tcp://` device's answer is named and dropped, as on the serial path: none
    /// reaches the client.
    #[test]
    fn tcp_device_misfits_are_named() {
        assert_eq!(check(1, &READ_TWO, 2, &ANSWER_TWO), Err(Misfit::Unit), "another unit's answer");
        assert_eq!(check(1, &READ_TWO, 1, &ANSWER_TWO_FC04), Err(Misfit::Function), "an FC04 answer to FC03");
        assert_eq!(check(1, &READ_TWO, 1, &ANSWER_THREE), Err(Misfit::Length), "one register more");
        assert_eq!(check(1, &READ_TWO, 1, &ANSWER_COUNT_LIE), Err(Misfit::Length));
        assert_eq!(check(1, &WRITE_10, 1, &WRITE_10_OTHER), Err(Misfit::Echo));
        assert_eq!(check(1, &READ_TWO, 1, &[0x83, 0x02, 0x00]), Err(Misfit::Length));
        assert_eq!(check(1, &READ_TWO, 1, &[]), Err(Misfit::Length));
    }
}
