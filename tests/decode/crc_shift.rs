//! CRC-16/MODBUS's shift property on lines with turnaround glitches: a frame whose CRC high byte
//! is `00` also checks one byte shorter, so `… 00` reads both as that frame and as a shorter
//! frame plus a `00` glitch. Where a function's structure fixes no length (vendor codes,
//! Diagnostics 0000) these pin how the framer decides: by structure where there is one, by who
//! sent the frame (the master's driver leaves `00`, slaves' `FE`/`FF`), and — where only the odds
//! on this line are left — by showing both lengths rather than passing a guess off as certain.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings, Parity};
use mbtap_analysis::report::events::text_line;
use mbtap_proto::{crc16, encode_rtu};

const L9600: LineSettings = LineSettings { baud: 9600, data_bits: 8, parity: Parity::Even, stop_bits: 1 };

/// A user-defined function code (MAP v1.1b3 §5: 65–72): no structure tells its length.
const VENDOR: u8 = 0x41;
/// Diagnostics (MAP v1.1b3 §6.8), sub-function 0000 Return Query Data: the data is echoed, any
/// N × 2 bytes.
const DIAGNOSTICS: u8 = 0x08;

/// One event as the tests compare it: kind (`F+`, `F-`, `N`, `G`), bytes, other length shown.
type Seen = (&'static str, Vec<u8>, Option<usize>);

fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = Vec::new();
    encode_rtu(unit, pdu, &mut f);
    f
}

/// `unit` + `pdu` with the PDU's last byte chosen so the frame's CRC high byte is `00`.
fn ending_in_zero(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut p = pdu.to_vec();
    for v in 0..=255u8 {
        *p.last_mut().unwrap() = v;
        let f = rtu(unit, &p);
        if f.last() == Some(&0) {
            return f;
        }
    }
    panic!("no last byte gives a CRC ending in 00 for {pdu:02X?}");
}

/// Builds a per-byte-stamped line at 9600 8E1: each item is bytes sent back to back after
/// `silence_chars` of silence.
struct Line {
    t: u64,
    chunks: Vec<(u64, Vec<u8>)>,
}

impl Line {
    fn new() -> Self {
        Self { t: 1_000_000_000, chunks: Vec::new() }
    }

    fn send(&mut self, silence_chars: u64, bytes: &[u8]) {
        let c = L9600.char_ns();
        self.t += silence_chars * c;
        for &b in bytes {
            self.t += c;
            self.chunks.push((self.t, vec![b]));
        }
    }

    /// Bytes that arrived in one read, `chars` character times after the last.
    fn read(&mut self, chars: u64, bytes: &[u8]) {
        self.t += chars * L9600.char_ns();
        self.chunks.push((self.t, bytes.to_vec()));
    }

    /// A read of 1 register and its answer, each followed by its driver's glitch when asked.
    fn poll(&mut self, master_glitch: bool, slave_glitch: bool) {
        self.send(10, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
        if master_glitch {
            self.send(0, &[0x00]);
        }
        self.send(5, &rtu(1, &[0x03, 0x02, 0x12, 0x34]));
        if slave_glitch {
            self.send(0, &[0xFE]);
        }
    }

    fn events(&self) -> Vec<Seen> {
        self.events_with_latency(0)
    }

    /// As read by an observer that delivers up to `latency_ns` late (told so).
    fn events_with_latency(&self, latency_ns: u64) -> Vec<Seen> {
        let mut a =
            Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(L9600, latency_ns), ..AnalyzerConfig::default() });
        let mut out = Vec::new();
        let mut sink = |e: &Event<'_>| match e {
            Event::Frame { frame, .. } => {
                out.push((if frame.check_ok { "F+" } else { "F-" }, frame.bytes.to_vec(), frame.alt_len));
            }
            Event::Noise(n) => out.push(("N", n.bytes.to_vec(), None)),
            Event::Glitch(n) => out.push(("G", n.bytes.to_vec(), None)),
            Event::Transaction(_) => {}
        };
        for (t, bytes) in &self.chunks {
            a.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes }, &mut sink);
        }
        a.finish(&mut sink);
        out
    }
}

/// The events from the first frame that is `from` or the start of it on.
fn tail(events: &[Seen], from: &[u8]) -> Vec<Seen> {
    let at = events.iter().position(|(_, b, _)| b.starts_with(&from[..2]) && b[..] == from[..b.len().min(from.len())]);
    events[at.expect("the frame was reported")..].to_vec()
}

/// On a line whose master leaves a `00` after every request, a vendor answer whose CRC ends in `00`
/// is taken whole — the slave's driver never leaves a `00` (nor anything), so its last byte is no
/// glitch; the shorter reading is shown beside it, since the master, which always glitches `00`,
/// could have sent these bytes.
#[test]
fn a_slave_answer_ending_in_00_stays_whole_where_only_the_master_glitches_00() {
    let mut line = Line::new();
    for _ in 0..40 {
        line.poll(true, false);
    }
    let request = rtu(1, &[VENDOR, 0x10, 0x20]);
    let answer = ending_in_zero(1, &[VENDOR, 0x01, 0x02, 0x03, 0x00]);
    line.send(10, &request);
    line.send(0, &[0x00]);
    line.send(5, &answer);
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = tail(&line.events(), &request);
    let n = answer.len();
    assert_eq!(e[..3], [("F+", request, None), ("G", vec![0x00], None), ("F+", answer, Some(n - 1))], "{e:02X?}");
}

/// Where slaves leave `FE` after every frame, they leave no `00`: an answer ending in `00`
/// followed by the slave's `FE` is the whole answer, without doubt.
#[test]
fn a_slave_answer_ending_in_00_and_its_fe_glitch_is_whole_without_doubt() {
    let mut line = Line::new();
    for _ in 0..40 {
        line.poll(true, true);
    }
    let request = rtu(1, &[VENDOR, 0x10, 0x20]);
    let answer = ending_in_zero(1, &[VENDOR, 0x01, 0x02, 0x03, 0x00]);
    line.send(10, &request);
    line.send(0, &[0x00]);
    line.send(5, &answer);
    line.send(0, &[0xFE]);
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = tail(&line.events(), &request);
    assert_eq!(
        e[..4],
        [("F+", request, None), ("G", vec![0x00], None), ("F+", answer, None), ("G", vec![0xFE], None)],
        "{e:02X?}"
    );
}

/// A Diagnostics 0000 request whose CRC ends in `00`, on a line whose master glitches, keeps its
/// even data (Diagnostics data is N × 2 bytes), never read as 3 data bytes and a glitch; its echo
/// likewise.
#[test]
fn a_diagnostics_echo_ending_in_00_keeps_its_even_data() {
    let mut line = Line::new();
    for i in 0..40 {
        line.poll(i % 3 == 0, false);
    }
    let request = ending_in_zero(1, &[DIAGNOSTICS, 0x00, 0x00, 0xA5, 0x37, 0x11, 0x00]);
    assert_eq!(request.len(), 10);
    line.send(10, &request);
    line.send(5, &request);
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = tail(&line.events(), &request);
    assert_eq!(e[..2], [("F+", request.clone(), None), ("F+", request, None)], "{e:02X?}");
}

/// A vendor request ending in `00` with no glitch after it, on a line whose master glitches
/// after about one request in three: a `00` glitch is the likelier reading there (1 in 3
/// against 1 in 256), so the framer reads a shorter request and a glitch — and says the frame
/// may be one byte longer, in the event and in its text.
#[test]
fn a_vendor_request_ending_in_00_where_the_master_glitches_sometimes_shows_both_lengths() {
    let mut line = Line::new();
    for i in 0..60 {
        line.poll(i % 3 == 0, false);
    }
    let request = ending_in_zero(1, &[VENDOR, 0x10, 0x20, 0x30]);
    let n = request.len();
    line.send(10, &request);
    line.send(5, &rtu(1, &[VENDOR, 0x55]));
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = tail(&line.events(), &request);
    assert_eq!(e[..2], [("F+", request[..n - 1].to_vec(), Some(n)), ("G", vec![0x00], None)], "{e:02X?}");
    assert_eq!(crc16(&request[..n - 2]).to_le_bytes(), [request[n - 2], 0x00]);
}

/// The same request on a line that never glitched: its `00` is its CRC's, without doubt.
#[test]
fn a_vendor_request_ending_in_00_on_a_line_that_never_glitched_is_whole() {
    let mut line = Line::new();
    for _ in 0..60 {
        line.poll(false, false);
    }
    let request = ending_in_zero(1, &[VENDOR, 0x10, 0x20, 0x30]);
    line.send(10, &request);
    line.send(5, &rtu(1, &[VENDOR, 0x55]));
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = tail(&line.events(), &request);
    assert_eq!(e[0], ("F+", request, None), "{e:02X?}");
}

/// What the user reads for such a frame: the other length and why, in text and JSON.
#[test]
fn the_other_length_is_said_in_text_and_json() {
    let request = ending_in_zero(1, &[VENDOR, 0x10, 0x20, 0x30]);
    let n = request.len();
    let frame = mbtap_analysis::framer::Frame {
        port: PortId(0),
        bytes: &request[..n - 1],
        t_start: Timestamp(0),
        t_end: Timestamp(1),
        check_ok: true,
        gap_violation_ns: None,
        short_gap_before_ns: None,
        gap_tolerance_ns: None,
        short_gap_tolerance_ns: None,
        resolution_ns: 0,
        gap_before_known: true,
        bad_chars: false,
        alt_len: Some(n),
    };
    let pdu = &request[1..n - 3];
    let e = Event::Frame { frame: &frame, role: mbtap_analysis::pairing::Role::Unknown, unit: Some(1), pdu: Some(pdu) };
    let text = text_line(&e);
    assert!(text.contains(&format!("[or {n} bytes: the 00 after it checks as its CRC's high byte too")), "{text}");
    let json = mbtap_analysis::report::events::json(&e);
    assert_eq!(json["or_len"], n, "{json}");
}

/// On a line that never glitches, a vendor request ending in `00` that comes in one read (a 16 ms
/// USB timer) with a damaged frame after it keeps its `00`: `00 01 …` looking like a frame start
/// too makes it no glitch.
#[test]
fn a_vendor_frame_glued_to_a_damaged_one_keeps_its_00_where_nothing_glitched() {
    let mut line = Line::new();
    for _ in 0..60 {
        line.poll(false, false);
    }
    let request = ending_in_zero(1, &[VENDOR, 0x15, 0xF3, 0x1F]);
    // The answer of unit 1 to the vendor code, its function code hit on the way (0x41 → 0x6D).
    let damaged = [0x01, 0x6D, 0xEF, 0xC3, 0x96, 0xEC, 0x97];
    line.read(30, &[request.clone(), damaged.to_vec()].concat());
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = tail(&line.events_with_latency(16_000_000), &request);
    assert_eq!(e[..2], [("F+", request, None), ("F-", damaged.to_vec(), None)], "{e:02X?}");
}

/// `01 C0 00 70 00` — a damaged answer's first five bytes — is no valid exception "00" to function
/// 0x40: exception codes start at 01 (MAP v1.1b3 §7).
#[test]
fn an_exception_with_code_00_is_no_frame() {
    let mut line = Line::new();
    for _ in 0..60 {
        line.poll(true, true);
    }
    let request = rtu(1, &[0x0F, 0x00, 0x70, 0x00, 0x06, 0x01, 0x1F]);
    let mut answer = rtu(1, &[0x0F, 0x00, 0x70, 0x00, 0x06]);
    answer[1] = 0xC0; // the function code hit on the way
    assert_eq!(crc16(&answer[..3]).to_le_bytes(), [answer[3], answer[4]], "the look-alike this pins");
    line.send(10, &request);
    line.send(0, &[0x00]);
    line.read(5 + 8, &[answer.clone(), vec![0xFE]].concat());
    line.send(40, &rtu(0x11, &[0x2B, 0x0E, 0x01, 0x00]));
    let e = tail(&line.events_with_latency(16_000_000), &request);
    assert!(!e.iter().any(|(k, b, _)| *k == "F+" && b[..] == answer[..5]), "{e:02X?}");
    assert_eq!(e[2], ("F-", answer, None), "{e:02X?}");
}

/// Unit 247's vendor request as the generator sends it at a line's start in the adapter matrix
/// (seed 700, 9600 8E1): unit `F7`, function `41` (user-defined), data `87 01 4C`,
/// CRC `75 A5`.
const VENDOR_REQUEST_247: [u8; 7] = [0xF7, 0x41, 0x87, 0x01, 0x4C, 0x75, 0xA5];
/// Its answer: unit `F7`, function `41`, 9 data bytes, CRC `79 15`.
const VENDOR_ANSWER_247: [u8; 13] = [0xF7, 0x41, 0x78, 0x8D, 0xBA, 0x23, 0x93, 0xAD, 0x03, 0x49, 0x32, 0x79, 0x15];

/// At a line's start (no unit heard yet), a vendor request and its answer delivered in one read by
/// a FIFO or a USB timer (the 1.05 × t3.5 between them invisible) are two frames, not one 20-byte
/// frame failing its check (`check_errors` against a healthy unit): the answer starts with the
/// request's unit and function, so the CRC match before it ends the request.
#[test]
fn a_vendor_request_and_answer_in_one_read_at_the_line_start_are_two_frames() {
    assert_eq!(rtu(0xF7, &VENDOR_REQUEST_247[1..5]), VENDOR_REQUEST_247, "the request's CRC");
    assert_eq!(rtu(0xF7, &VENDOR_ANSWER_247[1..11]), VENDOR_ANSWER_247, "the answer's CRC");
    let mut line = Line::new();
    line.read(0, &[VENDOR_REQUEST_247.as_slice(), VENDOR_ANSWER_247.as_slice()].concat());
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = line.events();
    assert_eq!(
        e[..2],
        [("F+", VENDOR_REQUEST_247.to_vec(), None), ("F+", VENDOR_ANSWER_247.to_vec(), None)],
        "{e:02X?}"
    );
}

/// At a line's start, with per-byte stamps, the master's `00` glitch after the vendor request and
/// the slave's `FE` after the answer: the answer and its `FE` are a frame and a glitch, not one
/// 14-byte frame failing its check, before the line is known to glitch — a CRC match followed by
/// one byte a slave's driver leaves and a silence ends the frame. The request and its `00` check as
/// one 8-byte frame too (CRC-16's shift property) and nothing is known yet of the master's
/// glitches: both readings are shown.
#[test]
fn a_vendor_answer_and_its_fe_glitch_at_the_line_start_are_a_frame_and_a_glitch() {
    let mut line = Line::new();
    line.send(0, &VENDOR_REQUEST_247);
    line.send(0, &[0x00]);
    line.send(4, &VENDOR_ANSWER_247);
    line.send(0, &[0xFE]);
    line.send(40, &rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]));
    let e = line.events();
    assert_eq!(
        e[..3],
        [
            ("F+", [VENDOR_REQUEST_247.as_slice(), &[0x00]].concat(), Some(VENDOR_REQUEST_247.len())),
            ("F+", VENDOR_ANSWER_247.to_vec(), None),
            ("G", vec![0xFE], None)
        ],
        "{e:02X?}"
    );
}
