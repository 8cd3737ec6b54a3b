//! What the audit of writes (`--audit FILE`) records of a request, and how its ending reads:
//! every request that may change a device — a write (MAP v1.1b3 §6.5 05, §6.6 06, §6.11 0F,
//! §6.12 10, §6.16 16, §6.17 17), a diagnostic that restarts or silences it (§6.8 08 sub-functions
//! 0001 "restart communications option" and 0004 "force listen only mode"), and anything not
//! known to leave it as it was (a vendor's function: the same line [`crate::rules::read_only_safe`]
//! draws) — and never a read. Pure: the PDU in, the fields out; the shell writes the lines.

use crate::rules::{GATEWAY_PATH_UNAVAILABLE, GATEWAY_TARGET_FAILED, read_only_safe};
use crate::transaction::Reply;

/// At most this many values are recorded of one request (a write carries at most 123
/// registers or 1968 coils, MAP v1.1b3 §6.11–§6.12); the count says if more were cut.
pub const MAX_VALUES: usize = 2000;

/// What a request changes, as the audit records it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Change {
    pub function: u8,
    /// The first address written (the write part of 17), or a diagnostic's sub-function.
    pub address: Option<u16>,
    pub quantity: Option<u16>,
    /// Registers as numbers, coils as 0 or 1; a mask write's AND and OR masks.
    pub values: Vec<u16>,
    /// What it is, in words (`write single register`, `restart communications`).
    pub what: &'static str,
}

fn u16_at(pdu: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*pdu.get(at)?, *pdu.get(at + 1)?]))
}

fn registers(bytes: &[u8]) -> Vec<u16> {
    bytes.chunks_exact(2).take(MAX_VALUES).map(|w| u16::from_be_bytes([w[0], w[1]])).collect()
}

fn bits(bytes: &[u8], quantity: u16) -> Vec<u16> {
    (0..usize::from(quantity).min(MAX_VALUES))
        .map_while(|i| bytes.get(i / 8).map(|b| u16::from((b >> (i % 8)) & 1)))
        .collect()
}

/// What `pdu` changes, `None` for a request that changes nothing (a read, a harmless
/// diagnostic). A request too short to parse is still recorded, with what it holds.
#[must_use]
pub fn change(pdu: &[u8]) -> Option<Change> {
    let &function = pdu.first()?;
    if read_only_safe(pdu) {
        return None;
    }
    let address = u16_at(pdu, 1);
    let c = |what, quantity, values| Some(Change { function, address, quantity, values, what });
    match function {
        0x05 => {
            c("write single coil", Some(1), u16_at(pdu, 3).map(|v| vec![u16::from(v == 0xFF00)]).unwrap_or_default())
        }
        0x06 => c("write single register", Some(1), u16_at(pdu, 3).into_iter().collect()),
        0x0F => {
            let q = u16_at(pdu, 3);
            c("write multiple coils", q, bits(pdu.get(6..).unwrap_or_default(), q.unwrap_or(0)))
        }
        0x10 => c("write multiple registers", u16_at(pdu, 3), registers(pdu.get(6..).unwrap_or_default())),
        0x16 => c("mask write register", Some(1), [u16_at(pdu, 3), u16_at(pdu, 5)].into_iter().flatten().collect()),
        0x17 => Some(Change {
            function,
            address: u16_at(pdu, 5),
            quantity: u16_at(pdu, 7),
            values: registers(pdu.get(10..).unwrap_or_default()),
            what: "read/write multiple registers",
        }),
        0x08 => {
            let what = match address {
                Some(0x0001) => "restart communications",
                Some(0x0004) => "force listen only mode",
                _ => "diagnostics",
            };
            Some(Change {
                function,
                address,
                quantity: None,
                values: registers(pdu.get(3..).unwrap_or_default()),
                what,
            })
        }
        _ => Some(Change {
            function,
            address: None,
            quantity: None,
            values: Vec::new(),
            what: "a function not known to be harmless",
        }),
    }
}

/// How a recorded request ended, in words: `done`, `exception 02`, `timeout`, `no path`,
/// `broadcast` (nobody answers one).
#[must_use]
pub fn outcome(reply: &Reply) -> String {
    match reply {
        Reply::Pdu(pdu) if pdu.first().is_some_and(|f| f & mbtap_proto::EXCEPTION_FLAG != 0) => {
            format!("exception {:02X}", pdu.get(1).copied().unwrap_or(0))
        }
        Reply::Pdu(_) => "done".into(),
        Reply::Gateway(GATEWAY_TARGET_FAILED) => "timeout".into(),
        Reply::Gateway(GATEWAY_PATH_UNAVAILABLE) => "no path to the device (exception 0A)".into(),
        Reply::Gateway(code) => format!("gateway exception {:02X}", code.value()),
        Reply::Silence => "broadcast (no answer)".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Named constants (MAP v1.1b3): write single register 101 = 42 (§6.6); write multiple
    /// coils 20–29, ten bits 0b10_1100_1101 (§6.11); read holding 0, 1 (§6.3); restart
    /// communications (§6.8.1, sub-function 0001, data 0000).
    const WRITE_REGISTER: [u8; 5] = [0x06, 0x00, 0x65, 0x00, 0x2A];
    const WRITE_COILS: [u8; 8] = [0x0F, 0x00, 0x14, 0x00, 0x0A, 0x02, 0xCD, 0x02];
    const READ: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x01];
    const RESTART: [u8; 5] = [0x08, 0x00, 0x01, 0x00, 0x00];

    #[test]
    fn writes_and_restarts_are_recorded_and_reads_are_not() {
        let w = change(&WRITE_REGISTER).unwrap();
        assert_eq!((w.function, w.address, w.quantity, w.values.as_slice()), (0x06, Some(101), Some(1), &[42][..]));
        let c = change(&WRITE_COILS).unwrap();
        assert_eq!(c.values, [1, 0, 1, 1, 0, 0, 1, 1, 0, 1]);
        assert_eq!(change(&READ), None);
        assert_eq!(change(&RESTART).unwrap().what, "restart communications");
        assert_eq!(change(&[0x08, 0x00, 0x00, 0x12, 0x34]), None, "return query data changes nothing");
        assert_eq!(change(&[0x41, 0x01]).unwrap().what, "a function not known to be harmless");
        assert_eq!(change(&[0x10]).unwrap().address, None, "a request too short still recorded");
    }

    #[test]
    fn outcomes_read_as_words() {
        assert_eq!(outcome(&Reply::Pdu(WRITE_REGISTER.to_vec())), "done");
        assert_eq!(outcome(&Reply::Pdu(vec![0x86, 0x02])), "exception 02");
        assert_eq!(outcome(&Reply::Gateway(GATEWAY_TARGET_FAILED)), "timeout");
    }
}
