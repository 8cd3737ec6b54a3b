//! Requests out of the bytes a slave's port hears — the one framer of every front where mbtap is
//! the slave on a serial line or a stream that behaves like one (`simulate`'s pseudo-terminal and
//! `--serial`, the bridge's `--listen-serial` and reverse mode, RTU over TCP clients): RTU by
//! function-code length, CRC and silence ([`rtu`]), ASCII by `:` … CR LF and LRC ([`ascii`]).
//! Bytes and silences in, whole requests out; the caller owns the port and the timer.

pub mod ascii;
pub mod rtu;

use std::time::Duration;

pub use ascii::AsciiRequestFramer;
pub use rtu::RtuRequestFramer;

use crate::serial_line::{LineSettings, SerialMode};

/// Slack on top of t3.5 before a silence ends a request: a timer's 1 ms steps and a
/// pseudo-terminal's or USB adapter's delivery.
const SILENCE_SLACK: Duration = Duration::from_millis(2);

/// The silence after which the bytes heard end a request on `line`: t3.5 (at least 1.75 ms above
/// 19200 baud, Serial Line v1.02 §2.5.1.1) and [`SILENCE_SLACK`] — one rule for every serial front
/// that frames requests as a slave.
#[must_use]
pub fn end_silence(line: LineSettings) -> Duration {
    Duration::from_nanos(line.t35_ns()) + SILENCE_SLACK
}

/// One request: the unit it is addressed to and its PDU.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RequestFrame {
    pub unit: u8,
    pub pdu: Vec<u8>,
}

/// Requests framed in a line's mode: the one framer the serial fronts share.
#[derive(Debug, Clone)]
pub enum RequestFramer {
    Rtu(RtuRequestFramer),
    Ascii(AsciiRequestFramer),
}

impl RequestFramer {
    /// An empty framer for `mode`.
    #[must_use]
    pub fn new(mode: SerialMode) -> Self {
        match mode {
            SerialMode::Rtu => Self::Rtu(RtuRequestFramer::default()),
            SerialMode::Ascii => Self::Ascii(AsciiRequestFramer::default()),
        }
    }

    /// Adds bytes as they were read and appends the requests they complete to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<RequestFrame>) {
        match self {
            Self::Rtu(f) => {
                f.push(bytes);
                out.extend(std::iter::from_fn(|| f.next_request()));
            }
            Self::Ascii(f) => {
                f.push(bytes);
                out.extend(std::iter::from_fn(|| f.next_request()));
            }
        }
    }

    /// The line went quiet: RTU ends a begun frame by silence; ASCII waits for CR LF.
    pub fn silence(&mut self) -> Option<RequestFrame> {
        match self {
            Self::Rtu(f) => f.silence(),
            Self::Ascii(_) => None,
        }
    }

    /// Whether a silence would end something: RTU bytes wait for more. An ASCII frame ends only
    /// at CR LF, so it never waits on a silence.
    #[must_use]
    pub fn waits_for_silence(&self) -> bool {
        matches!(self, Self::Rtu(f) if f.pending() > 0)
    }

    /// Bytes or characters thrown away so far: noise, bad checks, overlong frames.
    #[must_use]
    pub fn discarded(&self) -> u64 {
        match self {
            Self::Rtu(f) => f.discarded,
            Self::Ascii(f) => f.discarded,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit 1, read input registers 430, quantity 4, CRC 0xD491 (the MK4 document's example).
    const READ_VOLTAGES_RTU: [u8; 8] = [0x01, 0x04, 0x01, 0xAE, 0x00, 0x04, 0x91, 0xD4];
    /// The same request in ASCII: `:` unit 01, function 04, 01AE, 0004, LRC 48, CR LF.
    const READ_VOLTAGES_ASCII: &[u8] = b":010401AE000448\r\n";

    #[test]
    fn each_mode_frames_the_same_request_from_its_own_bytes() {
        let want = RequestFrame { unit: 1, pdu: vec![0x04, 0x01, 0xAE, 0x00, 0x04] };
        for (mode, bytes) in [(SerialMode::Rtu, &READ_VOLTAGES_RTU[..]), (SerialMode::Ascii, READ_VOLTAGES_ASCII)] {
            let mut framer = RequestFramer::new(mode);
            let mut out = Vec::new();
            framer.push(&bytes[..3], &mut out);
            assert!(out.is_empty());
            framer.push(&bytes[3..], &mut out);
            assert_eq!(out, vec![want.clone()], "{mode:?}");
            assert!(!framer.waits_for_silence());
            assert_eq!(framer.discarded(), 0);
        }
    }

    #[test]
    fn only_rtu_bytes_wait_for_a_silence() {
        let mut rtu = RequestFramer::new(SerialMode::Rtu);
        let mut ascii = RequestFramer::new(SerialMode::Ascii);
        let mut out = Vec::new();
        rtu.push(&[0x01, 0x04], &mut out);
        ascii.push(b":0104", &mut out);
        assert!(rtu.waits_for_silence());
        assert!(!ascii.waits_for_silence());
        assert_eq!(rtu.silence(), None, "two bytes are no request");
        assert_eq!(rtu.discarded(), 2);
        assert_eq!(ascii.silence(), None);
        assert_eq!(ascii.discarded(), 0, "the ASCII frame is still open");
    }

    #[test]
    fn the_end_silence_is_t3_5_and_its_slack() {
        let line: LineSettings = "9600 8E1".parse().unwrap();
        assert_eq!(end_silence(line), Duration::from_nanos(line.t35_ns()) + SILENCE_SLACK);
        // Above 19200 baud t3.5 is fixed at 1.75 ms (Serial Line v1.02 §2.5.1.1).
        let fast: LineSettings = "115200 8E1".parse().unwrap();
        assert_eq!(end_silence(fast), Duration::from_micros(1750) + SILENCE_SLACK);
    }
}
