//! What the bridge lets through, as pure rules shared by every listener and by reverse mode:
//! the read-only allow-list, the broadcast rule and the exception codes the gateway answers
//! with itself. A leaf: the admission policy, the TLS roles and the reverse side take them
//! from here.

use mbtap_proto::ExceptionCode;

/// Exception 0x01: the function is not allowed here (MAP v1.1b3 §7).
pub const ILLEGAL_FUNCTION: ExceptionCode = ExceptionCode::IllegalFunction;
/// Exception 0x03: the request's length or a value in it is wrong (MAP v1.1b3 §7).
pub const ILLEGAL_DATA_VALUE: ExceptionCode = ExceptionCode::IllegalDataValue;
/// Exception 0x06: busy — the client's queue is full or its rate is exceeded (MAP v1.1b3 §7).
pub const SERVER_DEVICE_BUSY: ExceptionCode = ExceptionCode::ServerDeviceBusy;
/// Exception 0x0A: the gateway has no path to the target (MAP v1.1b3 §7).
pub const GATEWAY_PATH_UNAVAILABLE: ExceptionCode = ExceptionCode::GatewayPathUnavailable;
/// Exception 0x0B: the target did not answer (MAP v1.1b3 §7).
pub const GATEWAY_TARGET_FAILED: ExceptionCode = ExceptionCode::GatewayTargetFailedToRespond;

/// Can this request not change a device? The read-only allow-list — everything not on it,
/// vendor and unknown codes included, is refused in read-only mode. From MAP v1.1b3 §6: reads
/// of bits and registers (01, 02, 03, 04, §6.1–6.4), Read Exception Status (07, §6.7), Get Comm
/// Event Counter / Log (0B, 0C, §6.9–6.10), Report Server ID (11, §6.13), Read File Record (14,
/// §6.14), Read FIFO Queue (18, §6.18), Read Device Identification (2B / MEI 0E, §6.21), and
/// Diagnostics only as sub-function 0000 Return Query Data (08, §6.8: an echo; every other
/// sub-function restarts, silences or clears something — 0001 restarts communications, 0004
/// forces listen-only mode, 000A clears counters) with one data word: its data field has no
/// length of its own, and a longer echo could carry a whole frame for a slave that frames by
/// structure. The caller also checks every length the function fixes (`mbtap_proto::request_len_problem`).
#[must_use]
pub fn read_only_safe(pdu: &[u8]) -> bool {
    matches!(
        *pdu,
        [0x01 | 0x02 | 0x03 | 0x04 | 0x07 | 0x0B | 0x0C | 0x11 | 0x14 | 0x18, ..]
            | [0x08, 0x00, 0x00, _, _]
            | [0x2B, 0x0E, ..]
    )
}

/// Function codes a broadcast may carry (Serial Line v1.02 §2.1: broadcasts are writes only,
/// MAP v1.1b3 §6.5, 6.6, 6.11, 6.12, 6.15, 6.16).
#[must_use]
pub fn broadcastable(fc: u8) -> bool {
    matches!(fc, 0x05 | 0x06 | 0x0F | 0x10 | 0x15 | 0x16)
}

/// Whether a request PDU is exactly as long as a slave that frames by structure reads it.
/// Diagnostics (08) is framed by such slaves as sub-function and one data word for every
/// sub-function — 0000 Return Query Data included (MAP v1.1b3 §6.8 lets its data run on; the
/// slave does not know where it ends): a longer one would put its tail on the line as a frame
/// of its own (a write smuggled in an FC08/0000 under `--allow-function 8`).
#[must_use]
pub fn forwardable_length(pdu: &[u8]) -> bool {
    !matches!(pdu.first(), Some(0x08)) || pdu.len() == 5
}

/// The exception PDU the gateway answers `function` with (MAP v1.1b3 §7: the function code
/// with its high bit set, then the code).
#[must_use]
pub fn exception_pdu(function: u8, code: ExceptionCode) -> Vec<u8> {
    vec![function | mbtap_proto::EXCEPTION_FLAG, code.value()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_only_is_an_allow_list_of_what_cannot_change_a_device() {
        // Reads and reports pass.
        for pdu in [
            &[0x01, 0, 0, 0, 8][..],
            &[0x03, 0, 0, 0, 1],
            &[0x04, 0, 0, 0, 1],
            &[0x07],
            &[0x0B],
            &[0x0C],
            &[0x11],
            &[0x14, 7, 6, 0, 4, 0, 1, 0, 2],
            &[0x18, 0, 4],
            &[0x2B, 0x0E, 1, 0],
            &[0x08, 0x00, 0x00, 0xA5, 0x37], // Return Query Data: an echo
        ] {
            assert!(read_only_safe(pdu), "{pdu:02X?} should pass");
        }
        // Everything else is refused: writes, the diagnostics that restart or silence a device,
        // CANopen (2B/0D), vendor and unknown codes, 0x00, 0x7F and exception-shaped codes.
        for pdu in [
            &[0x05, 0, 1, 0xFF, 0][..],
            &[0x06, 0, 1, 0, 3],
            &[0x0F, 0, 1, 0, 1, 1, 1],
            &[0x10, 0, 1, 0, 1, 2, 0, 1],
            &[0x15, 6, 6, 0, 4, 0, 1, 0, 1, 0, 0],
            &[0x16, 0, 4, 0, 0xF2, 0, 0x25],
            &[0x17, 0, 0, 0, 1, 0, 0, 0, 1, 2, 0, 1],
            &[0x08, 0x00, 0x01, 0x00, 0x00], // restart communications
            &[0x08, 0x00, 0x04, 0x00, 0x00], // force listen-only mode
            &[0x08, 0x00, 0x0A, 0x00, 0x00], // clear counters
            &[0x2B, 0x0D, 0, 0],
            &[0x41, 1, 2],
            &[0x46, 0, 0],
            &[0x64],
            &[0x00],
            &[0x7F],
            &[0x80],
            &[0x83, 0x02],
            &[],
        ] {
            assert!(!read_only_safe(pdu), "{pdu:02X?} should be refused");
        }
    }

    #[test]
    fn gateway_exceptions_are_the_function_with_its_high_bit_and_the_code() {
        assert_eq!(exception_pdu(0x03, GATEWAY_TARGET_FAILED), [0x83, 0x0B]);
        assert_eq!(exception_pdu(0x10, GATEWAY_PATH_UNAVAILABLE), [0x90, 0x0A]);
    }
}
