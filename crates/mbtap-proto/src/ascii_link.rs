//! A Modbus ASCII line behind an RTU-speaking master: the frames the master writes (address,
//! PDU, CRC) leave as ASCII frames (':', hex, LRC, CR LF — Modbus over Serial Line v1.02
//! §2.5.2.1), and the ASCII frames heard come back as RTU frames. The same address and PDU
//! both ways; only the envelope changes, so a master that frames RTU (tokio-modbus's) reads
//! and writes ASCII devices unchanged. Sans-IO: bytes in, bytes out.
//!
//! Heard characters: ':' always starts a new frame (§2.5.2.1: a receiver that sees ':' drops
//! what it had), LF ends one; characters outside a frame are noise and skipped; a frame longer
//! than 513 characters, with a bad character or a wrong LRC is dropped and counted. Work per
//! character is constant, and a frame is decoded once, at its LF.

use crate::ascii::{ASCII_MAX_LEN, ASCII_START, encode_ascii, parse_ascii};
use crate::error::AduError;
use crate::rtu::{RTU_MAX_LEN, encode_rtu, parse_rtu};

/// RTU bytes decoded and not yet taken, at most: 16 answers of the largest RTU frame. A reader
/// that stops taking them must not grow memory.
const READY_MAX: usize = 16 * RTU_MAX_LEN;

/// The translation, both ways.
#[derive(Debug, Default, Clone)]
pub struct AsciiLink {
    /// RTU bytes the master wrote since the last [`Self::take_request`].
    sent: Vec<u8>,
    /// Characters of the frame being heard (from its ':'); empty outside a frame.
    heard: Vec<u8>,
    /// RTU frames decoded from what was heard, for the master to read.
    ready: Vec<u8>,
    /// Frames heard and dropped: too long, a bad character, a wrong LRC, no CR before LF.
    pub dropped: u64,
}

impl AsciiLink {
    /// Nothing sent or heard yet.
    #[must_use]
    pub const fn new() -> Self {
        Self { sent: Vec::new(), heard: Vec::new(), ready: Vec::new(), dropped: 0 }
    }

    /// Bytes the master wrote (part of one RTU frame, or all of it). More than one RTU frame's
    /// worth before [`Self::take_request`] is cut there (and refused by it).
    pub fn sent(&mut self, rtu: &[u8]) {
        let room = (RTU_MAX_LEN + 1).saturating_sub(self.sent.len());
        self.sent.extend_from_slice(rtu.get(..room.min(rtu.len())).unwrap_or_default());
    }

    /// The master flushed: what it wrote, as one ASCII frame (`None` when it wrote nothing).
    /// What was heard of an earlier answer is dropped: the new request's answer is awaited.
    ///
    /// # Errors
    /// What was written is not one RTU frame with a good CRC (too short, too long, a bad CRC):
    /// nothing is sent.
    pub fn take_request(&mut self) -> Result<Option<Vec<u8>>, AduError> {
        if self.sent.is_empty() {
            return Ok(None);
        }
        let written = std::mem::take(&mut self.sent);
        if written.len() > RTU_MAX_LEN {
            return Err(AduError::TooLong { mode: "RTU", len: written.len(), max: RTU_MAX_LEN });
        }
        let frame = parse_rtu(&written)?;
        if !frame.check_ok() {
            return Err(AduError::BadCheck { mode: "RTU" });
        }
        self.heard.clear();
        self.ready.clear();
        let mut out = Vec::with_capacity(written.len() * 2 + 5);
        encode_ascii(frame.unit, frame.pdu, &mut out);
        Ok(Some(out))
    }

    /// Characters heard on the line.
    pub fn heard(&mut self, chars: &[u8]) {
        for &c in chars {
            if c == ASCII_START {
                self.heard.clear();
                self.heard.push(c);
            } else if !self.heard.is_empty() {
                self.heard.push(c);
                if c == b'\n' {
                    self.end_frame();
                } else if self.heard.len() > ASCII_MAX_LEN {
                    self.heard.clear();
                    self.dropped += 1;
                }
            }
        }
    }

    fn end_frame(&mut self) {
        let chars = std::mem::take(&mut self.heard);
        match parse_ascii(&chars) {
            Ok(f) if f.check_ok() && f.terminated && !f.pdu().is_empty() => {
                if self.ready.len() + f.pdu().len() + 3 > READY_MAX {
                    self.ready.clear();
                }
                encode_rtu(f.unit(), f.pdu(), &mut self.ready);
            }
            _ => self.dropped += 1,
        }
    }

    /// Up to `max` of the RTU bytes decoded so far, taken from the front.
    pub fn take_answer(&mut self, max: usize) -> Vec<u8> {
        let n = max.min(self.ready.len());
        self.ready.drain(..n).collect()
    }

    /// Whether decoded RTU bytes wait to be taken.
    #[must_use]
    pub fn has_answer(&self) -> bool {
        !self.ready.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// RTU: unit 1, FC 03, address 0x0065, quantity 3, CRC 0xD415 low byte first (the MK4
    /// document's read of holding registers 101–103).
    const RTU_READ: [u8; 8] = [
        /* unit */ 0x01, /* fc */ 0x03, /* address */ 0x00, 0x65, /* qty */ 0x00, 0x03,
        /* crc */ 0x15, 0xD4,
    ];
    /// The same request in ASCII: ':', "01 03 0065 0003", LRC 0x94, CR LF.
    const ASCII_READ: &[u8] = b":010300650003 94\r\n";
    /// The answer in ASCII: unit 1, FC 03, 6 bytes 0000 0000 0190, LRC 0x65.
    const ASCII_ANSWER: &[u8] = b":0103060000000001906 5\r\n";

    fn no_spaces(s: &[u8]) -> Vec<u8> {
        s.iter().copied().filter(|&c| c != b' ').collect()
    }

    #[test]
    fn a_request_leaves_as_ascii_and_its_answer_comes_back_as_rtu() {
        let mut link = AsciiLink::default();
        link.sent(&RTU_READ[..3]);
        link.sent(&RTU_READ[3..]);
        assert_eq!(link.take_request().unwrap().unwrap(), no_spaces(ASCII_READ));
        // Noise before the frame, the frame in two reads.
        let answer = no_spaces(ASCII_ANSWER);
        link.heard(b"\x00\xFF");
        link.heard(&answer[..9]);
        assert!(!link.has_answer());
        link.heard(&answer[9..]);
        let mut expected = Vec::new();
        encode_rtu(1, &[0x03, 0x06, 0x00, 0x00, 0x00, 0x00, 0x01, 0x90], &mut expected);
        assert_eq!(link.take_answer(4), expected[..4]);
        assert_eq!(link.take_answer(usize::MAX), expected[4..]);
        assert_eq!(link.dropped, 0);
    }

    #[test]
    fn a_bad_lrc_or_an_overlong_frame_is_dropped_and_counted() {
        let mut link = AsciiLink::default();
        link.heard(b":01030600000000019066\r\n");
        assert!(!link.has_answer());
        assert_eq!(link.dropped, 1, "LRC 66 where 65 is right");
        let long: Vec<u8> = std::iter::once(b':').chain(std::iter::repeat_n(b'0', 600)).collect();
        link.heard(&long);
        assert_eq!(link.dropped, 2);
        // A ':' restarts: the good frame after a broken start is kept.
        link.heard(b":0103");
        link.heard(&no_spaces(ASCII_ANSWER));
        assert!(link.has_answer());
    }

    #[test]
    fn what_is_not_one_good_rtu_frame_is_not_sent() {
        let mut link = AsciiLink::default();
        assert_eq!(link.take_request(), Ok(None));
        let mut bad = RTU_READ;
        bad[7] ^= 1;
        link.sent(&bad);
        assert!(link.take_request().is_err());
        link.sent(&[0u8; 300]);
        assert!(link.take_request().is_err());
    }
}
