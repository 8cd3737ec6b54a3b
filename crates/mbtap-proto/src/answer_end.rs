//! Where a slave's answer ends, as a serial master reads it: by structure and check, not by a
//! table of guesses. An exception is recognised from its five bytes (unit, function | 0x80,
//! code, CRC — MAP v1.1b3 §7, Serial Line v1.02 §2.5.1) and forwarded at once; a response whose
//! function fixes its length ends when that many bytes have a valid CRC; anything else — a
//! vendor function, Diagnostics echoing data — ends with the silence after it (t3.5, Serial Line
//! v1.02 §2.5.1.1) and stands or falls by its CRC. ASCII frames end with CR LF and carry an LRC
//! (§2.5.2). Pure: the caller says when the line has been silent.

use crate::{PduLength, crc16, response_len};

/// What the bytes read so far are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Not finished: read on (until the silence or the response timeout).
    Pending,
    /// A whole answer from the unit asked, `len` bytes from the start, check valid.
    Answer { len: usize },
    /// A whole frame whose check fails: retry or give up.
    BadCheck,
    /// Bytes that are not an answer to this request (another unit, noise): ignore them and
    /// keep waiting for the real one.
    Foreign,
}

/// RTU: judges `buf` as the answer to a request to `unit` with `function`; `silent` says the
/// line has been quiet for t3.5 since the last byte.
#[must_use]
pub fn judge_rtu(buf: &[u8], unit: u8, function: u8, silent: bool) -> Verdict {
    let crc_ok = |n: usize| {
        n >= 4
            && buf.get(..n).is_some_and(|f| {
                let (body, crc) = f.split_at(n - 2);
                crc16(body).to_le_bytes() == [crc[0], crc[1]]
            })
    };
    let (Some(&u), Some(&fc)) = (buf.first(), buf.get(1)) else {
        // One byte: the start of the answer (wait for more) unless it names another unit.
        return if silent && buf.first().is_some_and(|&u| u != unit) { Verdict::Foreign } else { Verdict::Pending };
    };
    if u != unit {
        return if silent { Verdict::Foreign } else { Verdict::Pending };
    }
    // A frame whose structure says more bytes are coming waits for them (until the response
    // timeout) even across a silence: USB adapters deliver in bursts, and a pause inside an
    // answer is the adapter's latency far more often than a truncated frame.
    if fc == function | 0x80 {
        // Exception: unit, function | 0x80, code, CRC (MAP v1.1b3 §7).
        return match buf.len() {
            0..5 => Verdict::Pending,
            _ if crc_ok(5) => Verdict::Answer { len: 5 },
            _ if silent => Verdict::BadCheck,
            _ => Verdict::Pending,
        };
    }
    let known = if fc == function { response_len(&buf[1..]) } else { PduLength::Unknown };
    match known {
        PduLength::Exact(pdu) => {
            let total = pdu.saturating_add(3);
            if buf.len() >= total && crc_ok(total) {
                Verdict::Answer { len: total }
            } else if silent && buf.len() >= total {
                Verdict::BadCheck
            } else {
                Verdict::Pending
            }
        }
        // Only the silence ends it; then the whole of it must check.
        PduLength::Unknown if silent && crc_ok(buf.len()) => Verdict::Answer { len: buf.len() },
        PduLength::Unknown if silent => Verdict::BadCheck,
        PduLength::AtLeast(_) | PduLength::Unknown => Verdict::Pending,
    }
}

/// ASCII: ':' … CR LF; judged when the frame is complete (or on silence, which in ASCII is the
/// 1 s inter-character timeout the caller applies).
#[must_use]
pub fn judge_ascii(buf: &[u8], unit: u8, silent: bool) -> Verdict {
    let Some(start) = buf.iter().position(|&b| b == b':') else {
        return if silent && !buf.is_empty() { Verdict::Foreign } else { Verdict::Pending };
    };
    let Some(end) = buf[start..].windows(2).position(|w| w == b"\r\n").map(|p| start + p + 2) else {
        return if silent { Verdict::BadCheck } else { Verdict::Pending };
    };
    match crate::parse_ascii(&buf[start..end]) {
        Ok(f) if f.unit() != unit => Verdict::Foreign,
        Ok(f) if f.check_ok() => Verdict::Answer { len: end },
        _ => Verdict::BadCheck,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rtu(body: &[u8]) -> Vec<u8> {
        let mut v = body.to_vec();
        v.extend_from_slice(&crc16(body).to_le_bytes());
        v
    }

    #[test]
    fn an_exception_ends_after_five_bytes_without_waiting() {
        // MK4 §3.1: unit 1, 0x83, code 02.
        let exc = rtu(&[0x01, 0x83, 0x02]);
        assert_eq!(judge_rtu(&exc[..4], 1, 0x03, false), Verdict::Pending);
        assert_eq!(judge_rtu(&exc, 1, 0x03, false), Verdict::Answer { len: 5 });
    }

    #[test]
    fn a_known_length_ends_when_its_crc_holds() {
        let resp = rtu(&[0x01, 0x03, 0x04, 0x00, 0x0A, 0x00, 0x0B]);
        for cut in 0..resp.len() {
            assert_eq!(judge_rtu(&resp[..cut], 1, 0x03, false), Verdict::Pending, "{cut}");
        }
        assert_eq!(judge_rtu(&resp, 1, 0x03, false), Verdict::Answer { len: 9 });
        let mut bad = resp.clone();
        bad[4] ^= 1;
        assert_eq!(judge_rtu(&bad, 1, 0x03, false), Verdict::Pending, "more may come, or the silence");
        assert_eq!(judge_rtu(&bad, 1, 0x03, true), Verdict::BadCheck);
    }

    /// A USB adapter (or a relay) delivering an answer in bursts with pauses longer than t3.5: an
    /// answer whose length is known is waited out, never half of it called a CRC error.
    #[test]
    fn a_pause_inside_a_known_length_answer_is_waited_out() {
        let resp = rtu(&[0x01, 0x04, 0x08, 0x08, 0xF7, 0x09, 0x07, 0x08, 0xF6, 0x08, 0xFC]);
        for cut in 1..resp.len() {
            assert_eq!(judge_rtu(&resp[..cut], 1, 0x04, true), Verdict::Pending, "{cut} bytes then a pause");
        }
        assert_eq!(judge_rtu(&resp, 1, 0x04, true), Verdict::Answer { len: resp.len() });
    }

    #[test]
    fn a_vendor_function_ends_with_the_silence() {
        let resp = rtu(&[0x05, 0x41, 0x01, 0x02, 0x03]);
        assert_eq!(judge_rtu(&resp, 5, 0x41, false), Verdict::Pending);
        assert_eq!(judge_rtu(&resp, 5, 0x41, true), Verdict::Answer { len: resp.len() });
        assert_eq!(judge_rtu(&resp[..4], 5, 0x41, true), Verdict::BadCheck);
    }

    #[test]
    fn another_units_frame_or_noise_is_foreign() {
        let other = rtu(&[0x02, 0x03, 0x02, 0x00, 0x01]);
        assert_eq!(judge_rtu(&other, 1, 0x03, true), Verdict::Foreign);
        assert_eq!(judge_rtu(&[0xFF], 1, 0x03, true), Verdict::Foreign);
        assert_eq!(judge_rtu(&[], 1, 0x03, true), Verdict::Pending);
    }

    #[test]
    fn ascii_frames_end_with_cr_lf_and_their_lrc() {
        let mut f = Vec::new();
        crate::encode_ascii(1, &[0x03, 0x02, 0x00, 0x07], &mut f);
        assert_eq!(judge_ascii(&f[..f.len() - 1], 1, false), Verdict::Pending);
        assert_eq!(judge_ascii(&f, 1, false), Verdict::Answer { len: f.len() });
        assert_eq!(judge_ascii(&f, 2, false), Verdict::Foreign);
        let mut bad = f.clone();
        bad[5] = b'9';
        assert_eq!(judge_ascii(&bad, 1, false), Verdict::BadCheck);
    }

    #[test]
    fn no_bytes_can_panic_the_judge() {
        for len in 0..40usize {
            let buf: Vec<u8> = (0..len).map(|i| u8::try_from(i * 37 % 256).unwrap()).collect();
            for silent in [false, true] {
                for fc in [0x01, 0x03, 0x08, 0x17, 0x2B, 0x41] {
                    let _ = judge_rtu(&buf, buf.first().copied().unwrap_or(0), fc, silent);
                    let _ = judge_ascii(&buf, 0, silent);
                }
            }
        }
    }
}
