//! A Modbus TCP device behind the bridge (`--serial tcp://HOST:PORT`): every client's request
//! goes out on the bridge's one connection under a transaction id of the bridge's own, and the
//! answer is matched back by it (Messaging on TCP/IP v1.0b §3.1.3: the transaction identifier
//! "is used for transaction pairing"). Many devices accept one or two connections: the bridge
//! holds one and lets every client through it. Sans-IO: bytes in, decisions out.

use mbtap_proto::tcp::{Streaming, encode_tcp, parse_tcp_frame};

use crate::answer::{Misfit, check};

/// The bridge's side of the one connection to a Modbus TCP device.
#[derive(Debug, Clone, Default)]
pub struct TcpDevice {
    /// The id generator's state (splitmix64): each request's id is drawn from it, so neither the
    /// first nor the next id can be told from the ids seen (ids counted from 0, and a
    /// device answering ahead under id + 1 had its answer taken for the next request's).
    state: u64,
    last_id: Option<u16>,
    /// The request awaited: its transaction id, unit and PDU (the answer check needs them).
    awaiting: Option<(u16, u8, Vec<u8>)>,
    /// Bytes read and not yet taken as a whole answer.
    buf: Vec<u8>,
}

/// What the bytes read so far make of the answer awaited.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Heard {
    /// Not a whole answer yet.
    More,
    /// The answer to the request awaited (its PDU, exception or not), checked against it.
    Answer { unit: u8, pdu: Vec<u8> },
    /// A stream that is not Modbus TCP (protocol id ≠ 0, a length no PDU has): the connection
    /// must be dropped and made again — nothing after it can be trusted.
    Broken,
}

/// What was dropped while the answer was awaited.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Dropped {
    /// Answers under another transaction id (late, duplicated, unsolicited).
    pub late: u32,
    /// Answers under the awaited id that do not fit the request ([`check`]): why, each.
    pub misfits: Vec<Misfit>,
}

/// Answers to other transaction ids than the one awaited (a late answer to a request that
/// timed out) are dropped; more than this many bytes without a whole frame break the stream
/// (the longest MBAP ADU is 260 bytes, Messaging on TCP/IP v1.0b §4.1).
const MAX_BUFFERED: usize = 4 * 260;

impl TcpDevice {
    /// A device whose transaction ids are drawn from `seed` — the shell's random pick.
    #[must_use]
    pub fn seeded(seed: u64) -> Self {
        Self { state: seed, ..Self::default() }
    }

    /// The next transaction id: never the last one, otherwise unpredictable without the seed.
    fn next_id(&mut self) -> u16 {
        loop {
            // splitmix64 (Steele, Lea, Flood 2014): any seed, small ones included, mixes at once.
            self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            let id = u16::try_from(z >> 48).unwrap_or(0);
            if Some(id) != self.last_id {
                self.last_id = Some(id);
                return id;
            }
        }
    }

    /// A fresh connection: nothing buffered, nothing awaited.
    pub fn reset(&mut self) {
        self.buf.clear();
        self.awaiting = None;
    }

    /// The ADU to send for `unit`'s `pdu`; its answer is awaited from now on.
    pub fn request(&mut self, unit: u8, pdu: &[u8]) -> Vec<u8> {
        let id = self.next_id();
        self.buf.clear();
        let mut adu = Vec::with_capacity(7 + pdu.len());
        encode_tcp(id, unit, pdu, &mut adu);
        self.awaiting = Some((id, unit, pdu.to_vec()));
        adu
    }

    /// Bytes read from the device while awaiting the last request's answer. Answers under
    /// other ids, and answers under its id that do not fit it (another unit, function or
    /// quantity — another client's answer), are dropped and counted; the awaited answer may
    /// still follow them.
    pub fn bytes(&mut self, bytes: &[u8]) -> (Heard, Dropped) {
        self.buf.extend_from_slice(bytes);
        let mut dropped = Dropped::default();
        loop {
            match parse_tcp_frame(&self.buf) {
                Ok(Streaming::Incomplete(_)) => {
                    let heard = if self.buf.len() > MAX_BUFFERED { Heard::Broken } else { Heard::More };
                    return (heard, dropped);
                }
                Ok(Streaming::Complete(f, used)) => {
                    let verdict = match &self.awaiting {
                        Some((id, unit, pdu)) if *id == f.header.transaction_id => {
                            Some(check(*unit, pdu, f.header.unit, f.pdu))
                        }
                        _ => None,
                    };
                    let answer = Heard::Answer { unit: f.header.unit, pdu: f.pdu.to_vec() };
                    self.buf.drain(..used);
                    match verdict {
                        Some(Ok(())) => {
                            self.awaiting = None;
                            return (answer, dropped);
                        }
                        Some(Err(why)) => {
                            dropped.misfits.push(why);
                        }
                        None => dropped.late += 1,
                    }
                }
                Err(_) => return (Heard::Broken, dropped),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Read holding registers 0x6B–0x6C (MAP v1.1b3 §6.3): function 03, address 006B, quantity 0002.
    const READ_TWO: [u8; 5] = [0x03, 0x00, 0x6B, 0x00, 0x02];
    /// Its answer, transaction id 0x0001, unit 17: two registers.
    const ANSWER_1: [u8; 13] = [
        0x00, 0x01, // transaction id
        0x00, 0x00, // protocol id: Modbus
        0x00, 0x07, // length: unit + PDU (6)
        0x11, // unit 17
        0x03, 0x04, 0x00, 0x0A, 0x01, 0x02, // PDU: fc 03, 4 bytes, 0x000A, 0x0102
    ];

    /// `ANSWER_1` under transaction id `id`, with byte `at` of the ADU set to `value` (at 0:
    /// nothing changed but the id).
    fn answer_with(id: u16, at: usize, value: u8) -> Vec<u8> {
        let mut a = ANSWER_1.to_vec();
        a[..2].copy_from_slice(&id.to_be_bytes());
        if at >= 2 {
            a[at] = value;
        }
        a
    }

    /// The id a request went out under.
    fn id_of(adu: &[u8]) -> u16 {
        u16::from_be_bytes([adu[0], adu[1]])
    }

    /// Ids come from the shell's seed, and the next is not the last + 1: a device answering ahead
    /// under id + 1 cannot have that answer taken for the next request's.
    #[test]
    fn ahead_ids_are_not_predictable_from_the_last() {
        let mut d = TcpDevice::seeded(0x5EED);
        let adu = d.request(17, &READ_TWO);
        assert_eq!(&adu[2..7], &[0x00, 0x00, 0x00, 0x06, 0x11][..]);
        let ids: Vec<u16> =
            std::iter::once(id_of(&adu)).chain((0..999).map(|_| id_of(&d.request(17, &READ_TWO)))).collect();
        let successors = ids.windows(2).filter(|w| w[1] == w[0].wrapping_add(1)).count();
        assert!(successors <= 2, "{successors} of 999 ids were the last + 1");
        assert!(ids.windows(2).all(|w| w[0] != w[1]));
        let mut other = TcpDevice::seeded(0xBEEF);
        assert_ne!(id_of(&other.request(17, &READ_TWO)), ids[0], "another seed, another first id");
    }

    #[test]
    fn an_answer_is_matched_by_its_id_even_in_pieces() {
        let mut d = TcpDevice::seeded(1);
        let _ = d.request(17, &[0x11]);
        let id = id_of(&d.request(17, &READ_TWO));
        let answer = answer_with(id, 0, 0);
        assert_eq!(d.bytes(&answer[..5]), (Heard::More, Dropped::default()));
        let heard = d.bytes(&answer[5..]);
        assert_eq!(heard, (Heard::Answer { unit: 17, pdu: ANSWER_1[7..].to_vec() }, Dropped::default()));
    }

    #[test]
    fn a_late_answer_to_another_request_is_dropped_not_taken() {
        let mut d = TcpDevice::seeded(2);
        let id = id_of(&d.request(17, &READ_TWO));
        // Another id's answer arrives while `id` is awaited (a device answering out of turn).
        let mut late = answer_with(id ^ 0x5A5A, 0, 0);
        late.extend_from_slice(&answer_with(id, 0, 0));
        let (heard, dropped) = d.bytes(&late);
        assert_eq!(heard, Heard::Answer { unit: 17, pdu: ANSWER_1[7..].to_vec() });
        assert_eq!(dropped.late, 1);
    }

    /// Answers under the awaited id that do not fit its request are dropped, never handed to the
    /// client, and the right one is taken.
    #[test]
    fn tcp_device_answers_that_do_not_fit_the_request_are_dropped() {
        let mut d = TcpDevice::seeded(7);
        let id = id_of(&d.request(17, &READ_TWO));
        let [hi, lo] = id.to_be_bytes();
        let misfits = [
            (answer_with(id, 6, 18), Misfit::Unit),       // unit 18 answers for 17
            (answer_with(id, 7, 0x04), Misfit::Function), // an FC04 answer to FC03
        ];
        for (bytes, why) in misfits {
            let (heard, dropped) = d.bytes(&bytes);
            assert_eq!((heard, dropped.misfits), (Heard::More, vec![why]));
        }
        // One register more than asked: another client's request's answer.
        let longer = [hi, lo, 0x00, 0x00, 0x00, 0x09, 0x11, 0x03, 0x06, 0, 1, 0, 2, 0, 3];
        let (heard, dropped) = d.bytes(&longer);
        assert_eq!((heard, dropped.misfits), (Heard::More, vec![Misfit::Length]));
        let (heard, _) = d.bytes(&answer_with(id, 0, 0));
        assert_eq!(heard, Heard::Answer { unit: 17, pdu: ANSWER_1[7..].to_vec() });
        // Taken once: the same id again is late.
        assert_eq!(d.bytes(&answer_with(id, 0, 0)).1.late, 1);
    }

    #[test]
    fn a_stream_that_is_not_modbus_tcp_is_broken() {
        let mut d = TcpDevice::default();
        let _ = d.request(1, &[0x03]);
        assert_eq!(d.bytes(b"HTTP/1.1 400 Bad Request\r\n").0, Heard::Broken);
    }
}
