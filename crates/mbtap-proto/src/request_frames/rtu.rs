//! RTU requests out of the bytes a slave hears, the way a slave's UART sees them: the function
//! code says how long a request is (MAP v1.1b3 §6) and the CRC confirms it (Serial Line v1.02
//! §2.5.1.2); when neither can tell, the silence after the frame ends it (t3.5, Serial Line
//! v1.02 §2.5.1.1), which the caller reports with [`RtuRequestFramer::silence`].

use super::RequestFrame;
use crate::{PduLength, crc16, request_len};

/// Collects bytes and hands out whole requests.
#[derive(Debug, Default, Clone)]
pub struct RtuRequestFramer {
    buf: Vec<u8>,
    /// Bytes thrown away because no request could be made of them (noise, a bad CRC).
    pub discarded: u64,
}

/// Address byte and CRC around the PDU (Serial Line v1.02 §2.5.1).
const OVERHEAD: usize = 3;
/// The longest RTU frame (Serial Line v1.02 §2.5.1: 256 bytes).
const RTU_MAX_LEN: usize = crate::rtu::RTU_MAX_LEN;

impl RtuRequestFramer {
    /// Adds bytes as they were read.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next whole request whose length the function code fixes, if the bytes hold one.
    /// A frame whose CRC is wrong costs its first byte (resynchronising on the next).
    pub fn next_request(&mut self) -> Option<RequestFrame> {
        loop {
            let pdu_len = match request_len(self.buf.get(1..)?) {
                PduLength::Exact(n) => n,
                PduLength::AtLeast(_) => return None,
                PduLength::Unknown => {
                    // A function only silence can end — or noise in front of a request. When a
                    // whole request with a good CRC starts further on, the bytes before it are noise.
                    let Some(skip) = (1..self.buf.len()).find(|&k| exact_request_at(&self.buf[k..])) else {
                        // No frame is longer than 256 bytes (Serial Line v1.02 §2.5.1): what lies
                        // further back can start none. Dropping it bounds both the memory and the
                        // rescan of every later read — a stream of garbage costs linear time.
                        let excess = self.buf.len().saturating_sub(RTU_MAX_LEN);
                        self.buf.drain(..excess);
                        self.discarded += excess as u64;
                        return None;
                    };
                    self.buf.drain(..skip);
                    self.discarded += skip as u64;
                    continue;
                }
            };
            let total = pdu_len.checked_add(OVERHEAD)?;
            let frame = self.buf.get(..total)?;
            if let Some(request) = checked(frame) {
                self.buf.drain(..total);
                return Some(request);
            }
            // Not a request at the length its fields give. A whole request further on means the
            // bytes before it are noise. Otherwise the fields may lie (a byte count that
            // disagrees with its quantity): such a request still stands or falls by its CRC
            // over what arrives before the silence ([`Self::silence`]) — the device, not the
            // gateway, answers it (with exception 03).
            if let Some(skip) = (1..self.buf.len()).find(|&k| exact_request_at(&self.buf[k..])) {
                self.buf.drain(..skip);
                self.discarded += skip as u64;
                continue;
            }
            let excess = self.buf.len().saturating_sub(RTU_MAX_LEN);
            self.buf.drain(..excess);
            self.discarded += excess as u64;
            return None;
        }
    }

    /// The line went quiet: whatever is buffered is one frame (a function whose length only
    /// the silence tells) or noise, which is dropped.
    pub fn silence(&mut self) -> Option<RequestFrame> {
        let request = checked(&self.buf);
        if request.is_none() {
            self.discarded += self.buf.len() as u64;
        }
        self.buf.clear();
        request
    }

    /// Bytes waiting for more.
    #[must_use]
    pub fn pending(&self) -> usize {
        self.buf.len()
    }
}

/// Whether `bytes` start with a whole request of a length the function code fixes, CRC good.
fn exact_request_at(bytes: &[u8]) -> bool {
    let Some(PduLength::Exact(n)) = bytes.get(1..).map(request_len) else { return false };
    n.checked_add(OVERHEAD).and_then(|total| bytes.get(..total)).and_then(checked).is_some()
}

/// `frame` as a request when it fits an RTU frame (at most 256 bytes, Serial Line v1.02 §2.5.1)
/// and its CRC (low byte first) matches.
fn checked(frame: &[u8]) -> Option<RequestFrame> {
    if frame.len() > RTU_MAX_LEN {
        return None;
    }
    let body_len = frame.len().checked_sub(2)?;
    let (body, crc) = frame.split_at(body_len);
    let (&unit, pdu) = body.split_first()?;
    if pdu.is_empty() || u16::from_le_bytes([crc[0], crc[1]]) != crc16(body) {
        return None;
    }
    Some(RequestFrame { unit, pdu: pdu.to_vec() })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit 1, read input registers 430, quantity 4, CRC 0xD491 (the MK4 document's example).
    const READ_VOLTAGES: [u8; 8] = [0x01, 0x04, 0x01, 0xAE, 0x00, 0x04, 0x91, 0xD4];

    #[test]
    fn whole_request_in_pieces() {
        let mut a = RtuRequestFramer::default();
        a.push(&READ_VOLTAGES[..3]);
        assert_eq!(a.next_request(), None);
        a.push(&READ_VOLTAGES[3..]);
        assert_eq!(a.next_request(), Some(RequestFrame { unit: 1, pdu: READ_VOLTAGES[1..6].to_vec() }));
        assert_eq!(a.pending(), 0);
    }

    #[test]
    fn noise_before_a_request_is_skipped_and_counted() {
        let mut a = RtuRequestFramer::default();
        a.push(&[0xFF, 0x00]);
        a.push(&READ_VOLTAGES);
        assert_eq!(a.next_request().map(|r| r.unit), Some(1));
        assert_eq!(a.discarded, 2);
    }

    #[test]
    fn silence_ends_a_frame_of_unknown_length_or_drops_noise() {
        let mut a = RtuRequestFramer::default();
        a.push(&[0x01, 0x04, 0x01]);
        assert_eq!(a.silence(), None);
        assert_eq!(a.discarded, 3);
        assert_eq!(a.pending(), 0);
    }

    /// A CRC-valid request whose byte count disagrees with its quantity (write 0 registers from
    /// 0x0160 with 6 data bytes) is still a request: the silence after it ends it, and the
    /// device, not the framer, answers it (exception 03), so the master never waits in vain.
    const LYING_BYTE_COUNT: [u8; 15] = [
        0x11, // unit 17
        0x10, // write multiple registers
        0x01, 0x60, // start 0x0160
        0x00, 0x00, // quantity 0
        0x00, // byte count 0 …
        0x02, 0x2B, 0x00, 0x01, 0x00, 0x64, // … and six data bytes
        0x8C, 0x88, // CRC over all of it
    ];

    #[test]
    fn a_request_whose_byte_count_lies_is_forwarded_at_the_silence() {
        let mut a = RtuRequestFramer::default();
        a.push(&LYING_BYTE_COUNT);
        assert_eq!(a.next_request(), None, "its length is not what its fields say");
        assert_eq!(a.pending(), LYING_BYTE_COUNT.len(), "kept for the silence");
        assert_eq!(a.silence(), Some(RequestFrame { unit: 0x11, pdu: LYING_BYTE_COUNT[1..13].to_vec() }));
    }

    /// A client streaming `0x41` (a function whose length only silence ends) costs at most one
    /// frame's bytes held and each byte scanned a bounded number of times: linear, not quadratic.
    #[test]
    fn a_stream_of_garbage_is_held_to_one_frame_and_scanned_once() {
        let mut a = RtuRequestFramer::default();
        for _ in 0..1000 {
            a.push(&[0x41; 1024]);
            assert_eq!(a.next_request(), None);
            assert!(a.pending() <= RTU_MAX_LEN, "{} bytes held", a.pending());
        }
        assert!(a.discarded >= 1000 * 1024 - RTU_MAX_LEN as u64);
        // A real request after it is still found.
        a.push(&READ_VOLTAGES);
        assert_eq!(a.next_request(), Some(RequestFrame { unit: 1, pdu: READ_VOLTAGES[1..6].to_vec() }));
    }

    /// Write multiple registers to unit 1 from 0 with a byte count of 250: its fields make a
    /// frame of 259 bytes, longer than any RTU frame (256, Serial Line v1.02 §2.5.1), so even with
    /// a good CRC it is no request a slave can have heard.
    fn overlong_write() -> Vec<u8> {
        let mut frame = vec![0x01, 0x10, 0x00, 0x00, 0x00, 0x7D, 0xFA];
        frame.extend(std::iter::repeat_n(0xAB, 250));
        let crc = crc16(&frame);
        frame.extend(crc.to_le_bytes());
        frame
    }

    #[test]
    fn a_frame_longer_than_rtu_allows_is_never_a_request() {
        let frame = overlong_write();
        assert_eq!(frame.len(), 259);
        let mut a = RtuRequestFramer::default();
        a.push(&frame);
        assert_eq!(a.next_request(), None);
        assert_eq!(a.silence(), None);
        a.push(&READ_VOLTAGES);
        assert_eq!(a.next_request().map(|r| r.unit), Some(1), "the next request is still heard");
    }

    #[test]
    fn any_bytes_never_panic() {
        let mut a = RtuRequestFramer::default();
        for i in 0..5000u32 {
            a.push(&i.to_le_bytes());
            while a.next_request().is_some() {}
            if i % 7 == 0 {
                let _ = a.silence();
            }
        }
    }
}
