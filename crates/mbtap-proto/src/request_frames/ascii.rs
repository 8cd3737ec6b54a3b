//! ASCII requests out of the characters a slave hears: ':' starts a frame,
//! CR LF ends it, the LRC confirms it (Serial Line v1.02 §2.5.2). Anything before a ':' is
//! noise; a frame that grows past 513 characters without its end is dropped.

use crate::ascii::{ASCII_END, ASCII_MAX_LEN, ASCII_START};
use crate::{AsciiFrame, parse_ascii};

use super::RequestFrame;

/// Collects characters and hands out whole requests.
#[derive(Debug, Default, Clone)]
pub struct AsciiRequestFramer {
    buf: Vec<u8>,
    /// Characters thrown away: noise, frames with a bad LRC or bad characters, overlong frames.
    pub discarded: u64,
}

impl AsciiRequestFramer {
    /// Adds characters as they were read.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next whole request, if the characters hold one.
    pub fn next_request(&mut self) -> Option<RequestFrame> {
        loop {
            // Noise before the start: a slave's receiver ignores it.
            let start = self.buf.iter().position(|&b| b == ASCII_START).unwrap_or(self.buf.len());
            self.drop_front(start);
            // A new ':' restarts the frame (§2.5.2.1): look for the end before any later start.
            let end = self.buf.windows(2).position(|w| w == ASCII_END);
            let restart = self.buf.iter().skip(1).position(|&b| b == ASCII_START).map(|p| p + 1);
            if let Some(e) = end
                && restart.is_none_or(|r| e < r)
            {
                let len = e + ASCII_END.len();
                let frame = self.buf.get(..len).and_then(|f| parse_ascii(f).ok()).filter(AsciiFrame::check_ok);
                match frame {
                    Some(f) if !f.pdu().is_empty() => {
                        self.buf.drain(..len);
                        return Some(RequestFrame { unit: f.unit(), pdu: f.pdu().to_vec() });
                    }
                    _ => self.drop_front(len),
                }
            } else if let Some(r) = restart {
                self.drop_front(r);
            } else if self.buf.len() > ASCII_MAX_LEN {
                self.drop_front(self.buf.len());
            } else {
                return None;
            }
        }
    }

    fn drop_front(&mut self, n: usize) {
        let n = n.min(self.buf.len());
        self.buf.drain(..n);
        self.discarded += n as u64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit 1, read input registers 430, quantity 4: 01 04 01AE 0004, LRC 0x48.
    const READ_VOLTAGES: &[u8] = b":01040 1AE000448\r\n";

    #[test]
    fn whole_request_after_noise() {
        let frame: Vec<u8> = READ_VOLTAGES.iter().copied().filter(|&b| b != b' ').collect();
        let mut a = AsciiRequestFramer::default();
        a.push(b"\x00\xFFjunk");
        a.push(&frame[..5]);
        assert_eq!(a.next_request(), None);
        a.push(&frame[5..]);
        assert_eq!(a.next_request(), Some(RequestFrame { unit: 1, pdu: vec![0x04, 0x01, 0xAE, 0x00, 0x04] }));
        assert_eq!(a.discarded, 6);
    }

    #[test]
    fn bad_lrc_is_dropped_and_a_restart_wins() {
        let mut a = AsciiRequestFramer::default();
        a.push(b":0104");
        a.push(b":01040");
        a.push(b"1AE000449\r\n"); // LRC off by one
        assert_eq!(a.next_request(), None);
        assert_eq!(a.discarded, 5 + 17);
    }

    #[test]
    fn any_bytes_never_panic() {
        let mut a = AsciiRequestFramer::default();
        for i in 0..5000u32 {
            let b = i.to_le_bytes();
            a.push(&[b[0] % 3 + b':', b[1], b'\r', b'\n'][..usize::try_from(i % 5).unwrap()]);
            while a.next_request().is_some() {}
        }
    }
}
