//! Where each field of a frame lies in its bytes, for the detail view's hex with the selected
//! field highlighted. RTU frames are laid out as they are; ASCII frames by their decoded bytes
//! (address, PDU, LRC). Layouts follow MAP v1.1b3 §6 (request and response PDUs per function)
//! and Serial Line v1.02 §2.5 (address first, CRC low byte first / LRC last).

use std::ops::Range;

/// One field: a label, its bytes in the frame, and its value as text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    pub label: String,
    pub range: Range<usize>,
    pub value: String,
}

/// The frame's bytes as laid out (RTU as on the wire; ASCII decoded).
#[must_use]
pub fn binary(wire: &[u8]) -> Vec<u8> {
    if wire.first() == Some(&b':') {
        mbtap_proto::parse_ascii(wire).map_or_else(
            |_| wire.to_vec(),
            |f| {
                let mut b = vec![f.unit()];
                b.extend_from_slice(f.pdu());
                b.push(f.lrc_received());
                b
            },
        )
    } else {
        wire.to_vec()
    }
}

fn u16_at(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(i)?, *b.get(i.checked_add(1)?)?]))
}

/// The fields of a frame (`bytes` as from [`binary`]); `ascii` says the check is one LRC byte;
/// `first` is the first register address a response's values belong to (its request's), so
/// they are numbered as the device numbers them — as the decode beside them does (
/// they were numbered from 0).
#[must_use]
pub fn fields(bytes: &[u8], is_request: bool, ascii: bool, first: Option<u16>) -> Vec<Field> {
    let mut out = Vec::new();
    let check_len = if ascii { 1 } else { 2 };
    if bytes.len() < 2 + check_len {
        if !bytes.is_empty() {
            out.push(Field { label: "bytes".into(), range: 0..bytes.len(), value: format!("{} byte(s)", bytes.len()) });
        }
        return out;
    }
    let end = bytes.len() - check_len;
    let mut push = |label: &str, range: Range<usize>, value: String| {
        if range.end <= end && range.start < range.end {
            out.push(Field { label: label.to_owned(), range, value });
        }
    };
    push("unit", 0..1, bytes[0].to_string());
    let fc = bytes[1];
    push("function", 1..2, format!("0x{fc:02X}"));
    let word = |i: usize| u16_at(bytes, i).map_or_else(String::new, |v| v.to_string());
    let mut next = 2;
    if fc & 0x80 != 0 {
        push("exception code", 2..3, format!("0x{:02X}", bytes[2]));
        next = 3;
    } else if is_request {
        let names: &[&str] = match fc {
            0x01..=0x04 | 0x0F | 0x10 => &["address", "quantity"],
            0x05 | 0x06 => &["address", "value"],
            0x16 => &["address", "and mask", "or mask"],
            0x17 => &["read address", "read quantity", "write address", "write quantity"],
            _ => &[],
        };
        for name in names {
            push(name, next..next + 2, word(next));
            next += 2;
        }
        if matches!(fc, 0x0F | 0x10 | 0x17) {
            push("byte count", next..next + 1, bytes[next.min(end)].to_string());
            next += 1;
            if fc != 0x0F {
                // 10 writes from its address, 17 from its write address (MAP v1.1b3 §6.12, 6.17).
                let at = if fc == 0x10 { 2 } else { 6 };
                next = registers(&mut push, bytes, next, end, "value", u16_at(bytes, at));
            }
        }
    } else {
        match fc {
            0x03 | 0x04 | 0x17 => {
                push("byte count", 2..3, bytes[2].to_string());
                next = registers(&mut push, bytes, 3, end, "register", first);
            }
            0x01 | 0x02 => {
                push("byte count", 2..3, bytes[2].to_string());
                next = 3;
            }
            0x05 | 0x06 | 0x0F | 0x10 => {
                push("address", 2..4, word(2));
                push(if matches!(fc, 0x0F | 0x10) { "quantity" } else { "value" }, 4..6, word(4));
                next = 6;
            }
            _ => {}
        }
    }
    push("data", next..end, format!("{} byte(s)", end.saturating_sub(next)));
    let check = if ascii {
        format!("0x{:02X}", bytes[end])
    } else {
        format!("0x{:04X}", u16::from_le_bytes([bytes[end], bytes[end + 1]]))
    };
    out.push(Field { label: if ascii { "LRC" } else { "CRC" }.into(), range: end..bytes.len(), value: check });
    out
}

/// Register-sized fields from `start` up to `end`, labelled with their register address from
/// `first` (or their offset `+n` when no request says it); returns where they stopped.
fn registers(
    push: &mut impl FnMut(&str, Range<usize>, String),
    bytes: &[u8],
    start: usize,
    end: usize,
    label: &str,
    first: Option<u16>,
) -> usize {
    let mut i = start;
    let mut n: u16 = 0;
    while i + 2 <= end {
        let name = match first.and_then(|f| f.checked_add(n)) {
            Some(a) => format!("{label} {a}"),
            None => format!("{label} +{n}"),
        };
        push(&name, i..i + 2, u16_at(bytes, i).map_or_else(String::new, |v| v.to_string()));
        i += 2;
        n = n.saturating_add(1);
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MK4 document §3.1: read 3 holding registers from 101 (0x0065) at unit 1.
    const READ_REQUEST: [u8; 8] = [
        0x01, // unit
        0x03, // function: Read Holding Registers
        0x00, 0x65, // address 101
        0x00, 0x03, // quantity 3
        0x15, 0xD4, // CRC, low byte first
    ];

    #[test]
    fn a_read_request_is_unit_function_address_quantity_crc() {
        let f = fields(&READ_REQUEST, true, false, None);
        let labels: Vec<(&str, Range<usize>, &str)> =
            f.iter().map(|f| (f.label.as_str(), f.range.clone(), f.value.as_str())).collect();
        assert_eq!(
            labels,
            [
                ("unit", 0..1, "1"),
                ("function", 1..2, "0x03"),
                ("address", 2..4, "101"),
                ("quantity", 4..6, "3"),
                ("CRC", 6..8, "0xD415"),
            ]
        );
    }

    #[test]
    fn a_register_response_has_one_field_per_register() {
        let resp = [0x01, 0x03, 0x04, 0x00, 0x0A, 0x01, 0x02, 0xAA, 0xBB];
        let f = fields(&resp, false, false, Some(128));
        let labels: Vec<&str> = f.iter().map(|f| f.label.as_str()).collect();
        // Numbered as the device numbers them (from the request's 128), not from 0.
        assert_eq!(labels, ["unit", "function", "byte count", "register 128", "register 129", "CRC"]);
        let unknown: Vec<String> = fields(&resp, false, false, None).into_iter().map(|f| f.label).collect();
        assert_eq!(unknown[3..5], ["register +0", "register +1"]);
        assert_eq!(f[4].value, "258");
        assert_eq!(f[4].range, 5..7);
    }

    #[test]
    fn exceptions_ascii_and_short_or_lying_frames() {
        let exc = fields(&[0x01, 0x83, 0x02, 0xC0, 0xF1], false, false, None);
        assert_eq!(exc[2].label, "exception code");
        let ascii = binary(b":010300650003 94\r\n");
        assert_eq!(ascii.first(), Some(&b':'), "an unparseable ASCII frame stays as it is");
        let ascii = binary(b":010300650003 \r\n");
        assert!(!ascii.is_empty());
        // A byte count that lies, and frames too short for their function: never out of range.
        for bytes in [&[0x01, 0x03, 0xFF, 0x00, 0x00][..], &[0x01, 0x10, 0x00][..], &[0x01][..], &[][..]] {
            for request in [true, false] {
                for f in fields(bytes, request, false, Some(65_535)) {
                    assert!(f.range.end <= bytes.len(), "{f:?} in {bytes:02X?}");
                }
            }
        }
    }
}
