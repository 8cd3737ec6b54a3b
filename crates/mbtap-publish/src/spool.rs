//! The record format of mbtap's on-disk message buffer (store-and-forward while the MQTT broker
//! or the Sparkplug host is away): append-only files of records, each
//!
//! ```text
//! B5 | kind (1) | length (u32 LE) | header check (u16 LE) | CRC-32 of the body (u32 LE) | body
//! ```
//!
//! The header check (the low half of the CRC-32 of kind and length) lets a reader that lost its
//! place find the next record without checking a body at every byte: random bytes pass it once
//! in 65 536, so the search stays linear.
//!
//! A record is trusted only whole and with its CRC: a power cut mid-append leaves a torn last
//! record, which [`parse_records`] reports and skips without losing the records before it; a
//! damaged record in the middle is skipped by searching for the next marker.

/// Marks the start of a record.
pub const MAGIC: u8 = 0xB5;
/// Bytes before the body: marker, kind, length, header check, body CRC.
pub const HEADER: usize = 12;
/// The longest body accepted (an MQTT payload is at most 256 MiB, MQTT v3.1.1 §2.2.3; mbtap's
/// are a few hundred bytes): a length above it is damage, not a record.
pub const MAX_BODY: usize = 1 << 20;

/// What a record holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A plain MQTT message: topic length (u16 LE), topic, QoS, retain, payload.
    Mqtt,
    /// Held Sparkplug updates (`sparkplug::Held`, JSON).
    Sparkplug,
    /// A kind this version does not know (a newer mbtap wrote it): kept, skipped on replay.
    Other(u8),
}

impl Kind {
    const fn code(self) -> u8 {
        match self {
            Self::Mqtt => 1,
            Self::Sparkplug => 2,
            Self::Other(k) => k,
        }
    }

    const fn from_code(k: u8) -> Self {
        match k {
            1 => Self::Mqtt,
            2 => Self::Sparkplug,
            k => Self::Other(k),
        }
    }
}

/// CRC-32 (IEEE 802.3, reflected, polynomial 0xEDB88320), bitwise: records are short.
#[must_use]
pub fn crc32(parts: &[&[u8]]) -> u32 {
    let mut crc = u32::MAX;
    for part in parts {
        for &b in *part {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
            }
        }
    }
    !crc
}

/// Appends one record to `out`. A body longer than [`MAX_BODY`] is not written (false).
pub fn encode_record(kind: Kind, body: &[u8], out: &mut Vec<u8>) -> bool {
    let Ok(len) = u32::try_from(body.len()) else { return false };
    if body.len() > MAX_BODY {
        return false;
    }
    let k = kind.code();
    out.push(MAGIC);
    out.push(k);
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(&header_check(k, len).to_le_bytes());
    out.extend_from_slice(&crc32(&[body]).to_le_bytes());
    out.extend_from_slice(body);
    true
}

fn header_check(kind: u8, len: u32) -> u16 {
    let l = len.to_le_bytes();
    (crc32(&[&[kind], &l]) & 0xFFFF) as u16
}

/// What a file of records holds.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Records<'a> {
    /// Whole, checked records in order: (kind, body).
    pub records: Vec<(Kind, &'a [u8])>,
    /// Bytes skipped as damage (a bad CRC, a length beyond [`MAX_BODY`], bytes between records),
    /// with the offset where each run began.
    pub damaged: Vec<(usize, usize)>,
    /// A record begun and not finished at the end (a power cut mid-append): its offset.
    pub torn_at: Option<usize>,
}

/// Reads every record of `bytes`. Never fails: damage is reported, and the search for the next
/// record moves on by one byte from a damaged record; a body is checked only behind a header
/// that checks, so the work stays linear in the input.
#[must_use]
pub fn parse_records(bytes: &[u8]) -> Records<'_> {
    let mut out = Records::default();
    let mut at = 0usize;
    let mut damage_from: Option<usize> = None;
    while at < bytes.len() {
        let rest = bytes.get(at..).unwrap_or_default();
        let header = match rest {
            [MAGIC, kind, l0, l1, l2, l3, h0, h1, c0, c1, c2, c3, ..] => {
                let len = u32::from_le_bytes([*l0, *l1, *l2, *l3]);
                (header_check(*kind, len) == u16::from_le_bytes([*h0, *h1]))
                    .then(|| (*kind, len, u32::from_le_bytes([*c0, *c1, *c2, *c3])))
            }
            _ => None,
        };
        let whole = header.and_then(|(kind, len, crc)| {
            let len = usize::try_from(len).ok().filter(|&l| l <= MAX_BODY)?;
            let end = HEADER.checked_add(len)?;
            match rest.get(HEADER..end) {
                Some(body) if crc32(&[body]) == crc => Some(Ok((Kind::from_code(kind), body, end))),
                Some(_) => None,
                // A checked header whose body is not all there: the append a power cut tore.
                None => Some(Err(())),
            }
        });
        match whole {
            Some(Ok((kind, body, used))) => {
                if let Some(from) = damage_from.take() {
                    out.damaged.push((from, at - from));
                }
                out.records.push((kind, body));
                at += used;
            }
            Some(Err(())) => {
                if let Some(from) = damage_from.take() {
                    out.damaged.push((from, at - from));
                }
                out.torn_at = Some(at);
                return out;
            }
            // A header cut short at the very end, right after a whole record: torn too.
            None if rest.len() < HEADER && rest.first() == Some(&MAGIC) && damage_from.is_none() => {
                out.torn_at = Some(at);
                return out;
            }
            None => {
                damage_from.get_or_insert(at);
                at += 1;
            }
        }
    }
    if let Some(from) = damage_from {
        out.damaged.push((from, bytes.len() - from));
    }
    out
}

/// A plain MQTT message as a record body.
#[must_use]
pub fn mqtt_body(topic: &str, qos: u8, retain: bool, payload: &[u8]) -> Option<Vec<u8>> {
    let tlen = u16::try_from(topic.len()).ok()?;
    let mut b = Vec::with_capacity(topic.len() + payload.len() + 4);
    b.extend_from_slice(&tlen.to_le_bytes());
    b.extend_from_slice(topic.as_bytes());
    b.push(qos);
    b.push(u8::from(retain));
    b.extend_from_slice(payload);
    Some(b)
}

/// A plain MQTT message back from a record body: (topic, QoS, retain, payload).
#[must_use]
pub fn parse_mqtt_body(body: &[u8]) -> Option<(&str, u8, bool, &[u8])> {
    let (len, rest) = body.split_first_chunk::<2>()?;
    let tlen = usize::from(u16::from_le_bytes(*len));
    let topic = std::str::from_utf8(rest.get(..tlen)?).ok()?;
    let [qos, retain, payload @ ..] = rest.get(tlen..)? else { return None };
    Some((topic, (*qos).min(2), *retain != 0, payload))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(bodies: &[&[u8]]) -> Vec<u8> {
        let mut out = Vec::new();
        for b in bodies {
            assert!(encode_record(Kind::Mqtt, b, &mut out));
        }
        out
    }

    #[test]
    fn records_come_back_in_order() {
        let f = file(&[b"one", b"", b"three"]);
        let r = parse_records(&f);
        assert_eq!(r.records, [(Kind::Mqtt, &b"one"[..]), (Kind::Mqtt, &b""[..]), (Kind::Mqtt, &b"three"[..])]);
        assert!(r.damaged.is_empty());
        assert_eq!(r.torn_at, None);
    }

    /// A power cut mid-append must cost the torn record only, never the buffer.
    #[test]
    fn a_torn_last_record_is_skipped_and_the_rest_kept() {
        let f = file(&[b"one", b"two", b"three"]);
        for cut in 1..HEADER + 5 {
            let torn = &f[..f.len() - cut];
            let r = parse_records(torn);
            assert_eq!(r.records.len(), 2, "cut {cut}");
            assert_eq!(r.torn_at, Some(f.len() - (HEADER + 5)), "cut {cut}");
        }
    }

    #[test]
    fn a_damaged_record_in_the_middle_is_skipped_and_said() {
        let mut f = file(&[b"one", b"two", b"three"]);
        f[HEADER + 3 + HEADER] ^= 0xFF; // a byte of "two"
        let r = parse_records(&f);
        assert_eq!(r.records, [(Kind::Mqtt, &b"one"[..]), (Kind::Mqtt, &b"three"[..])]);
        assert_eq!(r.damaged, [(HEADER + 3, HEADER + 3)]);
        // Garbage before and between records.
        let mut g = vec![0x00, MAGIC, 0x01];
        g.extend_from_slice(&file(&[b"x"]));
        let r = parse_records(&g);
        assert_eq!(r.records, [(Kind::Mqtt, &b"x"[..])]);
        assert_eq!(r.damaged, [(0, 3)]);
    }

    #[test]
    fn mqtt_bodies_round_trip() {
        let b = mqtt_body("a/b", 1, true, b"{\"v\":1}").unwrap();
        assert_eq!(parse_mqtt_body(&b), Some(("a/b", 1, true, &b"{\"v\":1}"[..])));
        assert_eq!(parse_mqtt_body(&[5, 0, b'a']), None);
        // CRC-32 check value of "123456789" (IEEE 802.3).
        assert_eq!(crc32(&[b"123456789"]), 0xCBF4_3926);
    }
}
