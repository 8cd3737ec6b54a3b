//! Fuzz harness bodies of the analysis (frames, framer, captures, health, learn): kept in the library so the
//! `fuzz/` targets stay one-liners and the same bodies run over the seed corpus in `cargo test`
//! (tests/decode/fuzz_corpus.rs).
//!
//! Each function must not panic on any input; a body that asserts a property says so in its
//! `# Panics` — there a panic is the finding.

use crate::decode::{self, Format};
use crate::report::{FrameView, jsonl, text};
use mbtap_proto::{
    DirectionHint, Mode, PduDecode, Streaming, decode_pdu, parse_adu, parse_ascii, parse_request, parse_response,
    parse_rtu, parse_tcp_frame, request_len, response_len,
};

fn render_all(wire: &[u8], mode: Mode) {
    if let Ok(adu) = parse_adu(wire, Some(mode)) {
        for hint in [DirectionHint::Request, DirectionHint::Response, DirectionHint::Unknown] {
            let decode = decode_pdu(&adu.pdu, hint);
            let view = FrameView { wire, adu: &adu, decode: &decode, request: None };
            let _ = text::frame(&view, "");
            let _ = jsonl::frame(&view);
        }
    }
}

/// One RTU frame.
pub fn rtu(data: &[u8]) {
    if let Ok(f) = parse_rtu(data) {
        let _ = f.check_ok();
        let _ = request_len(f.pdu);
        let _ = response_len(f.pdu);
    }
    render_all(data, Mode::Rtu);
    request_frames(data, mbtap_proto::serial_line::SerialMode::Rtu);
}

/// The same bytes heard by a slave's port in `mode`, in reads whose sizes the bytes choose and
/// with a silence after every fourth read: every request framed is a whole one (unit, non-empty
/// PDU) and the framer holds at most one longest frame's bytes while it waits.
fn request_frames(data: &[u8], mode: mbtap_proto::serial_line::SerialMode) {
    use mbtap_proto::request_frames::{RequestFrame, RequestFramer};
    let mut framer = RequestFramer::new(mode);
    let mut out: Vec<RequestFrame> = Vec::new();
    let mut rest = data;
    let mut reads = 0u32;
    while let Some((&size, tail)) = rest.split_first() {
        let (chunk, after) = tail.split_at(usize::from(size % 64).min(tail.len()));
        framer.push(chunk, &mut out);
        reads += 1;
        if reads.is_multiple_of(4) {
            out.extend(framer.silence());
        }
        if let RequestFramer::Rtu(f) = &framer {
            assert!(f.pending() <= 2 * mbtap_proto::rtu::RTU_MAX_LEN + 64, "{} bytes held", f.pending());
        }
        rest = after;
    }
    out.extend(framer.silence());
    assert!(out.iter().all(|r| !r.pdu.is_empty() && r.pdu.len() <= 253), "a frame outside the spec's sizes");
}

/// One ASCII frame.
pub fn ascii(data: &[u8]) {
    if let Ok(f) = parse_ascii(data) {
        let _ = (f.check_ok(), f.unit(), f.pdu());
    }
    render_all(data, Mode::Ascii);
    request_frames(data, mbtap_proto::serial_line::SerialMode::Ascii);
}

/// A TCP byte stream.
pub fn tcp_stream(data: &[u8]) {
    let mut rest = data;
    while let Ok(Streaming::Complete(frame, used)) = parse_tcp_frame(rest) {
        let _ = decode_pdu(frame.pdu, DirectionHint::Unknown);
        rest = &rest[used..];
    }
    render_all(data, Mode::Tcp);
}

/// A request PDU.
pub fn pdu_request(data: &[u8]) {
    let _ = request_len(data);
    if let PduDecode::One(d) = decode_pdu(data, DirectionHint::Request)
        && let mbtap_proto::Pdu::Request(r) = d.pdu
    {
        let _ = crate::report::fields::request_fields(&r);
    }
}

/// A response PDU.
pub fn pdu_response(data: &[u8]) {
    let _ = response_len(data);
    if let PduDecode::One(d) = decode_pdu(data, DirectionHint::Response)
        && let mbtap_proto::Pdu::Response(r) = d.pdu
    {
        let _ = crate::report::fields::response_fields(&r, None);
    }
}

/// Parse → encode must give back the input exactly.
///
/// # Panics
/// When it does not: that is the bug the fuzzer is looking for.
pub fn roundtrip(data: &[u8]) {
    if let Ok((trailing, req)) = parse_request(data) {
        let mut out = Vec::with_capacity(data.len());
        assert!(req.encode(&mut out).is_ok(), "a parsed request failed to encode: {req:?}");
        out.extend_from_slice(trailing);
        assert_eq!(out, data, "request round trip");
    }
    if let Ok((trailing, resp)) = parse_response(data) {
        let mut out = Vec::with_capacity(data.len());
        assert!(resp.encode(&mut out).is_ok(), "a parsed response failed to encode: {resp:?}");
        out.extend_from_slice(trailing);
        assert_eq!(out, data, "response round trip");
    }
}

/// Text lines through the whole `decode` command.
pub fn decode_text(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let lines: Vec<String> = text.lines().map(str::to_owned).collect();
    for format in [Format::Text, Format::Jsonl] {
        let _ = decode::run(&lines, None, format, &mut std::io::sink(), &mut std::io::sink());
    }
}

/// Any bytes as `decode`'s standard input: the streaming line reader, then the decoder, as
/// the command runs them. Lines are numbered 1, 2, 3… with none lost: one per line end, plus
/// one for a last line without it, however long each line is.
///
/// # Panics
/// When a line is lost, numbered twice or kept longer than the cap.
pub fn decode_lines(data: &[u8]) {
    use crate::decode_lines::{Lines, MAX_LINE};
    let profiles = decode::Profiles::new();
    for format in [Format::Text, Format::Jsonl] {
        let mut lines = Lines::new(data);
        let mut decoder = decode::Decoder::new(None, format, &profiles, mbtap_device::profile::annotate::Lang::En);
        let mut seen = 0usize;
        while let Ok(Some(line)) = lines.next_line() {
            seen += 1;
            assert_eq!(line.number, seen, "lines are numbered in order");
            // U+FFFD takes 3 bytes for each 1 invalid byte.
            assert!(line.text.len() <= 3 * MAX_LINE, "a line is held to the cap");
            let _ = decoder.line(&line.text, &mut std::io::sink(), &mut std::io::sink());
        }
        #[allow(clippy::naive_bytecount)] // a fuzz oracle: no crate for speed here
        let ends = data.iter().filter(|&&b| b == b'\n').count();
        let last = usize::from(data.last().is_some_and(|&b| b != b'\n'));
        assert_eq!(seen, ends + last, "every line read, once");
        let _ = decoder.finish(&mut std::io::sink(), &mut std::io::sink());
    }
}

/// Fuzz bytes as timed chunks: each 4-byte header gives a chunk length (its first byte, mod
/// 64) and a time step (the next three, ×10 ns); the data follows. `(time, step, bytes)`.
fn chunks(mut rest: &[u8]) -> Vec<(u64, u64, &[u8])> {
    let mut out = Vec::new();
    let mut t = 1_000_000_000u64;
    while let [len, s0, s1, s2, after @ ..] = rest {
        let step = u64::from(u32::from_le_bytes([*s0, *s1, *s2, 0])) * 10;
        let (bytes, after) = after.split_at(usize::from(len % 64).min(after.len()));
        rest = after;
        t = t.wrapping_add(step);
        out.push((t, step, bytes));
    }
    out
}

/// Arbitrary chunks through the RTU and ASCII framers: the first byte of each 4-byte header
/// gives a chunk length, the next three a time step; the rest is data. Every byte must come
/// out in exactly one event.
///
/// # Panics
/// When bytes are lost or duplicated: that is the bug the fuzzer is looking for.
pub fn framer(data: &[u8]) {
    use crate::chunk::{Chunk, PortId, Timestamp};
    use crate::framer::{AsciiFramer, FrameEvent, FramerConfig, LineSettings, RtuFramer};
    let line = LineSettings {
        baud: 9600 * (1 + u32::from(data.first().copied().unwrap_or(0) % 12)),
        ..LineSettings::default()
    };
    let mut rtu =
        RtuFramer::new(PortId(0), FramerConfig::new(line, u64::from(data.get(1).copied().unwrap_or(0)) * 100_000));
    let mut ascii = AsciiFramer::new(PortId(0), line);
    let (mut fed, mut out_rtu) = (0usize, 0usize);
    for (t, step, bytes) in chunks(data.get(2..).unwrap_or(&[])) {
        let chunk = Chunk { port: PortId(0), t: Timestamp(t), bytes };
        fed += bytes.len();
        rtu.push(&chunk, &mut |e: FrameEvent<'_>| out_rtu += e.bytes().len());
        assert!(rtu.pending() <= crate::framer::rtu::MAX_PENDING, "the RTU framer holds {} bytes", rtu.pending());
        assert!(rtu.held() <= crate::framer::rtu::MAX_HELD_BYTES, "the twin hold keeps {} bytes", rtu.held());
        ascii.push(&chunk, &mut |_e: FrameEvent<'_>| {});
        if step % 7 == 0 {
            rtu.tick(Timestamp(t.wrapping_add(step)), &mut |e: FrameEvent<'_>| out_rtu += e.bytes().len());
        }
    }
    rtu.finish(&mut |e: FrameEvent<'_>| out_rtu += e.bytes().len());
    ascii.finish(&mut |_e: FrameEvent<'_>| {});
    assert_eq!(fed, out_rtu, "RTU framer lost or duplicated bytes");
}

/// Any bytes as a capture file, replayed through the analyzer in both output formats.
pub fn capture(data: &[u8]) {
    use crate::analyzer::{Event, Sink};
    use crate::line_args::LineOverrides;
    use crate::report::events::{Stats, json, text_line};
    /// Renders every event both ways, as `replay` does for text and JSON lines.
    struct Render(Stats);
    impl Sink for Render {
        fn event(&mut self, e: &Event<'_>) {
            self.0.add(e);
            let _ = (text_line(e), json(e).to_string());
        }
        fn warning(&mut self, message: &str) {
            let _ = serde_json::json!({"event": "warning", "message": message}).to_string();
        }
    }
    let mut sink = Render(Stats::default());
    let _ = crate::replay::replay_into(data, LineOverrides::default(), &mut sink);
    let _ = (sink.0.text(), sink.0.json());
}

/// Any bytes as a slave's answer to the bridge: byte 0 is the unit asked, byte 1 the function,
/// the rest what was read; judged both before and after the silence, RTU and ASCII.
///
/// # Panics
/// When an answer claims more bytes than were read: that is the bug the fuzzer is looking for.
pub fn bridge_response(data: &[u8]) {
    use mbtap_proto::answer_end::{Verdict, judge_ascii, judge_rtu};
    let [unit, function, buf @ ..] = data else { return };
    for silent in [false, true] {
        for v in [judge_rtu(buf, *unit, *function, silent), judge_ascii(buf, *unit, silent)] {
            if let Verdict::Answer { len } = v {
                assert!(len <= buf.len(), "answer of {len} bytes from {} read", buf.len());
            }
        }
    }
}

/// Arbitrary chunks (framed as in [`framer`]) through the analyzer in RTU or ASCII into the
/// bus health report with the built-in profiles, rendered as text, JSON and HTML; and the
/// same bytes through the stored-bytes scan.
pub fn health(data: &[u8]) {
    use crate::analyzer::{Analyzer, AnalyzerConfig, Event, SerialMode};
    use crate::chunk::{Chunk, PortId, Timestamp};
    use crate::framer::{FramerConfig, LineSettings};
    static PROFILES: std::sync::OnceLock<mbtap_device::profile::Profiles> = std::sync::OnceLock::new();
    let profiles = PROFILES.get_or_init(|| mbtap_device::profile::builtin::demo_profiles().unwrap_or_default());
    let mode = if data.first().is_some_and(|b| b & 1 == 1) { SerialMode::Ascii } else { SerialMode::Rtu };
    let line = LineSettings::default();
    let mut analyzer =
        Analyzer::new(AnalyzerConfig { mode, framer: FramerConfig::new(line, 0), ..AnalyzerConfig::default() });
    let mut health = crate::health::Health::new(profiles.clone());
    let mut stored = Vec::new();
    for (t, _, bytes) in chunks(data.get(1..).unwrap_or(&[])) {
        analyzer.push(&Chunk { port: PortId(0), t: Timestamp(t), bytes }, &mut |e: &Event<'_>| health.event(e));
        stored.push((t, bytes.to_vec()));
    }
    analyzer.finish(&mut |e: &Event<'_>| health.event(e));
    let report = health.report();
    let _ = (report.text(), report.json(), crate::health::html::render(&report, "fuzz"));
    let _ = crate::scan::scan_stored(&stored, line);
}

/// Any bytes as answered transactions for `learn` (records of unit, request length, request,
/// response length, response): observed, guessed, drafted — never a panic, and the draft of
/// every unit always loads as a profile.
///
/// # Panics
/// When a draft does not load: the fuzzer's finding.
pub fn learn(data: &[u8]) {
    let mut l = crate::learn::Learner::default();
    let mut rest = data;
    let mut t = 0u64;
    while let [unit, n, tail @ ..] = rest {
        let Some((req, tail)) = tail.split_at_checked(usize::from(*n)) else { break };
        let [m, tail @ ..] = tail else { break };
        let Some((resp, tail)) = tail.split_at_checked(usize::from(*m)) else { break };
        l.observe(*unit, req, resp, t);
        t += 1_000_000;
        rest = tail;
    }
    let _ = (crate::learn::draft::text(&l), crate::learn::draft::json(&l));
    for (unit, u) in &l.units {
        let hint = crate::learn::hint::Hint {
            unit: *unit,
            table: mbtap_device::profile::Table::HoldingRegisters,
            address: 0,
            value: 12.5,
        };
        let toml = crate::learn::draft::profile_toml(*unit, u, "fuzz", &[hint]);
        let loaded = mbtap_device::profile::load("draft.toml", &toml);
        assert!(loaded.is_ok(), "a draft that does not load: {loaded:?}\n{toml}");
    }
}
