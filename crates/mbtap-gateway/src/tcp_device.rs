//! A Modbus TCP device behind the bridge (`--serial tcp://HOST:PORT`): every client's request
//! goes out on the bridge's one connection under a transaction id of the bridge's own, and the
//! answer is matched back by it (Messaging on TCP/IP v1.0b §3.1.3: the transaction identifier
//! "is used for transaction pairing"). Many devices accept one or two connections: the bridge
//! holds one and lets every client through it. Sans-IO: bytes in, decisions out.

use mbtap_proto::tcp::{Streaming, encode_tcp, parse_tcp_frame};

/// The bridge's side of the one connection to a Modbus TCP device.
#[derive(Debug, Clone, Default)]
pub struct TcpDevice {
    next_id: u16,
    /// Bytes read and not yet taken as a whole answer.
    buf: Vec<u8>,
}

/// What the bytes read so far make of the answer awaited.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Heard {
    /// Not a whole answer yet.
    More,
    /// The answer to the request awaited (its PDU, exception or not), for `unit`.
    Answer { unit: u8, pdu: Vec<u8> },
    /// A stream that is not Modbus TCP (protocol id ≠ 0, a length no PDU has): the connection
    /// must be dropped and made again — nothing after it can be trusted.
    Broken,
}

/// Answers to other transaction ids than the one awaited (a late answer to a request that
/// timed out) are dropped; more than this many bytes without a whole frame break the stream.
const MAX_BUFFERED: usize = 4 * 260;

impl TcpDevice {
    /// A fresh connection: nothing buffered.
    pub fn reset(&mut self) {
        self.buf.clear();
    }

    /// The ADU to send for `unit`'s `pdu`, and the transaction id to await.
    pub fn request(&mut self, unit: u8, pdu: &[u8]) -> (u16, Vec<u8>) {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        self.buf.clear();
        let mut adu = Vec::with_capacity(7 + pdu.len());
        encode_tcp(id, unit, pdu, &mut adu);
        (id, adu)
    }

    /// Bytes read from the device while awaiting transaction `id`; answers to other ids are
    /// dropped (counted in the returned number).
    pub fn bytes(&mut self, id: u16, bytes: &[u8]) -> (Heard, u32) {
        self.buf.extend_from_slice(bytes);
        let mut dropped = 0;
        loop {
            match parse_tcp_frame(&self.buf) {
                Ok(Streaming::Incomplete(_)) => {
                    let heard = if self.buf.len() > MAX_BUFFERED { Heard::Broken } else { Heard::More };
                    return (heard, dropped);
                }
                Ok(Streaming::Complete(f, used)) => {
                    let mine = f.header.transaction_id == id;
                    let answer = Heard::Answer { unit: f.header.unit, pdu: f.pdu.to_vec() };
                    self.buf.drain(..used);
                    if mine {
                        return (answer, dropped);
                    }
                    dropped += 1;
                }
                Err(_) => return (Heard::Broken, dropped),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A read-holding-registers answer, transaction id 0x0001, unit 17: two registers.
    const ANSWER_1: [u8; 13] = [
        0x00, 0x01, // transaction id
        0x00, 0x00, // protocol id: Modbus
        0x00, 0x07, // length: unit + PDU (6)
        0x11, // unit 17
        0x03, 0x04, 0x00, 0x0A, 0x01, 0x02, // PDU: fc 03, 4 bytes, 0x000A, 0x0102
    ];

    #[test]
    fn ids_are_the_bridges_own_and_count_up() {
        let mut d = TcpDevice::default();
        let (a, adu) = d.request(17, &[0x03, 0x00, 0x6B, 0x00, 0x02]);
        assert_eq!((a, &adu[..7]), (0, &[0x00, 0x00, 0x00, 0x00, 0x00, 0x06, 0x11][..]));
        assert_eq!(d.request(17, &[0x03, 0x00, 0x6B, 0x00, 0x02]).0, 1);
    }

    #[test]
    fn an_answer_is_matched_by_its_id_even_in_pieces() {
        let mut d = TcpDevice::default();
        let _ = d.request(17, &[0x03]);
        let (id, _) = d.request(17, &[0x03, 0x00, 0x6B, 0x00, 0x02]);
        assert_eq!(id, 1);
        assert_eq!(d.bytes(1, &ANSWER_1[..5]), (Heard::More, 0));
        assert_eq!(d.bytes(1, &ANSWER_1[5..]), (Heard::Answer { unit: 17, pdu: ANSWER_1[7..].to_vec() }, 0));
    }

    #[test]
    fn a_late_answer_to_another_request_is_dropped_not_taken() {
        let mut d = TcpDevice::default();
        let (id, _) = d.request(17, &[0x03]);
        assert_eq!(id, 0);
        // The answer to id 1 arrives while id 0 is awaited (a device answering out of turn).
        let mut late = ANSWER_1.to_vec();
        let mut mine = ANSWER_1.to_vec();
        mine[1] = 0x00;
        late.extend_from_slice(&mine);
        assert_eq!(d.bytes(0, &late), (Heard::Answer { unit: 17, pdu: ANSWER_1[7..].to_vec() }, 1));
    }

    #[test]
    fn a_stream_that_is_not_modbus_tcp_is_broken() {
        let mut d = TcpDevice::default();
        let (id, _) = d.request(1, &[0x03]);
        assert_eq!(d.bytes(id, b"HTTP/1.1 400 Bad Request\r\n").0, Heard::Broken);
    }
}
