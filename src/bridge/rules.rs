//! What the bridge lets through, as pure rules shared by every listener and by reverse mode:
//! the read-only allow-list and the exception codes the gateway answers with itself. A leaf
//! (issue 26: the TLS roles and the reverse side took these from the server, which imports the
//! TLS module: one import circle).

/// Exception 0x01: the function is not allowed here (MAP v1.1b3 §7).
pub const ILLEGAL_FUNCTION: u8 = 0x01;
/// Exception 0x03: the request's length or a value in it is wrong (MAP v1.1b3 §7).
pub const ILLEGAL_DATA_VALUE: u8 = 0x03;

/// Can this request not change a device? The read-only allow-list — everything not on it,
/// vendor and unknown codes included, is refused in read-only mode. From MAP v1.1b3 §6: reads
/// of bits and registers (01, 02, 03, 04, §6.1–6.4), Read Exception Status (07, §6.7), Get Comm
/// Event Counter / Log (0B, 0C, §6.9–6.10), Report Server ID (11, §6.13), Read File Record (14,
/// §6.14), Read FIFO Queue (18, §6.18), Read Device Identification (2B / MEI 0E, §6.21), and
/// Diagnostics only as sub-function 0000 Return Query Data (08, §6.8: an echo; every other
/// sub-function restarts, silences or clears something — 0001 restarts communications, 0004
/// forces listen-only mode, 000A clears counters) with one data word: its data field has no
/// length of its own, and a longer echo could carry a whole frame for a slave that frames by
/// structure. The caller also checks every length the function fixes (`mbtap_core::proto::request_len_problem`).
#[must_use]
pub fn read_only_safe(pdu: &[u8]) -> bool {
    matches!(
        *pdu,
        [0x01 | 0x02 | 0x03 | 0x04 | 0x07 | 0x0B | 0x0C | 0x11 | 0x14 | 0x18, ..]
            | [0x08, 0x00, 0x00, _, _]
            | [0x2B, 0x0E, ..]
    )
}
