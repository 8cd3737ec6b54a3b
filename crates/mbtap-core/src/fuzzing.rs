//! Fuzz harness bodies, kept in the library so the `fuzz/` targets stay one-liners and the same
//! bodies run over the seed corpus in `cargo test` (tests/decode/fuzz_corpus.rs).
//!
//! Each function must not panic on any input; `roundtrip` additionally asserts the
//! parse → encode identity, which is the one place a panic here is the point.

use crate::decode::{self, Format};
use crate::proto::{
    DirectionHint, Mode, PduDecode, Streaming, decode_pdu, parse_adu, parse_ascii, parse_request, parse_response,
    parse_rtu, parse_tcp_frame, request_len, response_len,
};
use crate::report::{FrameView, jsonl, text};

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
}

/// One ASCII frame.
///
/// # Panics
/// When the ASCII line behind an RTU master hands back more bytes than it heard: that is the
/// bug the fuzzer is looking for.
pub fn ascii(data: &[u8]) {
    if let Ok(f) = parse_ascii(data) {
        let _ = (f.check_ok(), f.unit(), f.pdu());
    }
    render_all(data, Mode::Ascii);
    // The same bytes heard by `read --mode ascii`, and sent by it.
    let mut link = crate::proto::ascii_link::AsciiLink::new();
    link.heard(data);
    // Two hex characters per byte, plus ':' and CR LF, give way to one byte and the CRC: what
    // comes out is never more than what went in.
    let answer = link.take_answer(usize::MAX);
    assert!(answer.len() <= data.len(), "{} RTU bytes from {} characters", answer.len(), data.len());
    link.sent(data);
    let _ = link.take_request();
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
        && let crate::proto::Pdu::Request(r) = d.pdu
    {
        let _ = crate::report::fields::request_fields(&r);
    }
}

/// A response PDU.
pub fn pdu_response(data: &[u8]) {
    let _ = response_len(data);
    if let PduDecode::One(d) = decode_pdu(data, DirectionHint::Response)
        && let crate::proto::Pdu::Response(r) = d.pdu
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
        let mut decoder = decode::Decoder::new(None, format, &profiles, crate::profile::annotate::Lang::En);
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

/// Any text as a profile; when it loads, annotate a sweep of values with it.
pub fn profile(data: &[u8]) {
    use crate::profile::Table;
    use crate::profile::annotate::{annotate_bits, annotate_registers};
    let text = String::from_utf8_lossy(data);
    if let Ok(p) = crate::profile::load("fuzz.toml", &text) {
        let values: Vec<u16> =
            data.chunks(2).map(|c| u16::from_le_bytes([c[0], *c.get(1).unwrap_or(&0)])).take(64).collect();
        for table in [Table::HoldingRegisters, Table::InputRegisters] {
            for start in [0u16, 1, 100, 400, 500, 65_500] {
                let _ = annotate_registers(&p, table, start, &values, false);
                let _ = annotate_registers(&p, table, start, &values, true);
            }
        }
        let bits: Vec<bool> = data.iter().map(|b| b & 1 == 1).take(64).collect();
        let _ = annotate_bits(&p, Table::Coils, 0, &bits, true);
        let _ = annotate_bits(&p, Table::DiscreteInputs, 65_535, &bits, false);
    }
}

/// Any request PDU to the simulated built-in devices: an answer or silence, never a panic.
/// The first byte is the unit address, the rest the PDU.
///
/// # Panics
/// When an answer is not a well-formed response: that is the bug the fuzzer is looking for.
pub fn sim(data: &[u8]) {
    use std::sync::{Arc, OnceLock};
    static SLAVES: OnceLock<Vec<crate::sim::Slave>> = OnceLock::new();
    let slaves = SLAVES.get_or_init(|| {
        ["mk4", "mkzp", "display"]
            .into_iter()
            .filter_map(|name| crate::profile::builtin::get(name).and_then(Result::ok))
            .map(|p| crate::sim::Slave::new(Arc::new(p), 1))
            .collect()
    });
    let Some((&unit, pdu)) = data.split_first() else { return };
    for s in slaves {
        let mut s = s.clone();
        if let Some(answer) = s.handle(unit, pdu) {
            // Whatever the slave says must itself be a well-formed response.
            assert!(crate::proto::parse_response(&answer).is_ok(), "unparseable answer {answer:02X?} to {pdu:02X?}");
        }
    }
    // A device emulated from a recording (`simulate --from`): holding 0–9 and coils 0–15 heard.
    let mut values = std::collections::BTreeMap::new();
    for a in 0..16u16 {
        values.insert((crate::profile::Table::Coils, a), a % 2);
        values.insert((crate::profile::Table::HoldingRegisters, a % 10), a);
    }
    let mut recorded = crate::sim::RecordedDevice::from_image(1, values);
    if let Some(answer) = recorded.handle(unit, pdu) {
        assert!(crate::proto::parse_response(&answer).is_ok(), "unparseable answer {answer:02X?} to {pdu:02X?}");
    }
}

/// Any bytes sent at one line setting and heard at another through the UART model: it ends,
/// delivers bytes in time order, and at matching settings delivers exactly what was sent.
/// Byte 0 picks the sender's settings, byte 1 the receiver's; the rest is the frame.
///
/// # Panics
/// When one of those properties fails: that is the bug the fuzzer is looking for.
pub fn uart(data: &[u8]) {
    use crate::framer::{LineSettings, Parity};
    use crate::sim::bus::LineFrame;
    use crate::sim::uart::UartListener;
    const BAUDS: [u32; 8] = [1200, 2400, 9600, 14_400, 19_200, 56_000, 115_200, 256_000];
    let settings = |b: u8| LineSettings {
        baud: BAUDS[usize::from(b & 7)],
        data_bits: if b & 8 == 0 { 8 } else { 7 },
        parity: [Parity::None, Parity::Even, Parity::Odd, Parity::Even][usize::from(b >> 4 & 3)],
        stop_bits: if b & 0x40 == 0 { 1 } else { 2 },
    };
    let [s, r, bytes @ ..] = data else { return };
    let (sender, receiver) = (settings(*s), settings(*r));
    let chars = u64::try_from(bytes.len()).unwrap_or(u64::MAX);
    let frame = LineFrame { end_ns: 1_000_000 + sender.char_ns() * chars, bytes: bytes.to_vec() };
    let heard = UartListener::new(sender, receiver).hear(&frame);
    assert!(heard.windows(2).all(|w| w[0].t_ns < w[1].t_ns), "bytes out of time order");
    if sender == receiver {
        let mask = if sender.data_bits == 7 { 0x7F } else { 0xFF };
        let sent: Vec<u8> = bytes.iter().map(|b| b & mask).collect();
        let got: Vec<u8> = heard.iter().map(|h| h.byte).collect();
        assert_eq!(got, sent, "matching settings must hear what was sent");
        assert!(heard.iter().all(|h| !h.framing_error && !h.parity_error));
    }
}

/// Any bytes as a slave's answer to the bridge: byte 0 is the unit asked, byte 1 the function,
/// the rest what was read; judged both before and after the silence, RTU and ASCII.
///
/// # Panics
/// When an answer claims more bytes than were read: that is the bug the fuzzer is looking for.
pub fn bridge_response(data: &[u8]) {
    use crate::proto::answer_end::{Verdict, judge_ascii, judge_rtu};
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
    static PROFILES: std::sync::OnceLock<crate::profile::Profiles> = std::sync::OnceLock::new();
    let profiles = PROFILES.get_or_init(|| crate::sim::demo_profiles().unwrap_or_default());
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

/// Any text as the items of `mbtap read`/`write` (one per line), with the MK4 profile and with
/// none: parsed, resolved, planned and encoded — never a panic, every planned read inside the
/// spec's quantity limits and the target's addresses, every write within 123 registers.
///
/// # Panics
/// When one of those holds not: that is what the fuzzer looks for.
pub fn query(data: &[u8]) {
    use crate::query::{encode, items, plan, resolve};
    static MK4: std::sync::OnceLock<Option<crate::profile::Profile>> = std::sync::OnceLock::new();
    let mk4 = MK4.get_or_init(|| crate::profile::builtin::get("mk4").and_then(Result::ok));
    let text = String::from_utf8_lossy(data);
    let tokens: Vec<&str> = text.split('\n').collect();
    let Ok(parsed) = items::parse_items(&tokens) else { return };
    for profile in [None, mk4.as_ref()] {
        let targets: Vec<_> = parsed.iter().filter_map(|i| resolve::resolve(i, profile).ok()).collect();
        if let Ok(p) = plan::plan(&targets, profile) {
            for r in &p.reads {
                let max = if crate::query::is_bits(r.table) { plan::MAX_READ_BITS } else { plan::MAX_READ_REGISTERS };
                assert!((1..=max).contains(&r.quantity), "read of {} registers", r.quantity);
                let t = &targets[r.target];
                assert!(r.address >= t.first && u32::from(r.address) + u32::from(r.quantity) - 1 <= u32::from(t.last));
            }
        }
        for t in &targets {
            for force in [false, true] {
                if let Ok(w) = encode::encode_write(t, profile, force) {
                    assert!(!w.words.is_empty() && w.words.len() <= 123, "{} words", w.words.len());
                    let _ = w.pdu();
                }
            }
        }
    }
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
            table: crate::profile::Table::HoldingRegisters,
            address: 0,
            value: 12.5,
        };
        let toml = crate::learn::draft::profile_toml(*unit, u, "fuzz", &[hint]);
        let loaded = crate::profile::load("draft.toml", &toml);
        assert!(loaded.is_ok(), "a draft that does not load: {loaded:?}\n{toml}");
    }
}

/// Any bytes as a register sheet (lines of `,`-separated cells; the first byte chooses the
/// default table and whether columns are given) and as Home Assistant YAML (issue 27): read,
/// imported, exported — never a panic, and every imported profile loads and exports.
///
/// # Panics
/// When an imported profile does not load: the fuzzer's finding.
pub fn profile_import(data: &[u8]) {
    use crate::profile::import::{home_assistant, sheet};
    let Some((&mode, rest)) = data.split_first() else { return };
    let text = String::from_utf8_lossy(rest);
    let rows = crate::profile::import::grid::Grid::from_rows(text.lines().map(|l| l.split(',')));
    let table = [
        None,
        Some(crate::profile::Table::HoldingRegisters),
        Some(crate::profile::Table::InputRegisters),
        Some(crate::profile::Table::Coils),
    ][usize::from(mode & 3)];
    let columns = if mode & 4 != 0 {
        sheet::parse_columns("address=A,name=B,type=C,scale=D").unwrap_or_default()
    } else {
        Vec::new()
    };
    let mut imported =
        vec![sheet::parse_sheet(&rows, &sheet::SheetOptions { columns, table, word_order: None, value_type: None })];
    if let Ok((i, _)) = home_assistant::parse_home_assistant(&text, Some(mode)) {
        imported.push(i);
    }
    for i in imported {
        let _ = i.problems.iter().map(ToString::to_string).count();
        let toml = i.to_toml("fuzz", "fuzz \"device\"", "fuzz\ninput");
        let loaded = crate::profile::load("imported.toml", &toml);
        assert!(loaded.is_ok(), "an import that does not load: {loaded:?}\n{toml}");
        // The import's load-back in parts agrees with the whole load.
        let parts = crate::profile::import::load_back("imported.toml", &toml);
        assert!(parts.is_ok(), "loads whole, not in parts: {parts:?}\n{toml}");
        if let Ok(p) = loaded {
            for target in [
                crate::profile::export::Target::HomeAssistant,
                crate::profile::export::Target::Esphome,
                crate::profile::export::Target::Telegraf,
            ] {
                let _ = crate::profile::export::export(&p, mode, target);
            }
        }
    }
}

/// Any strings as a profile's device, name, register names and units (issue 39): exported to
/// every target, each export parsed back as its tool reads it (YAML, TOML) and every name and
/// unit read back equal — nothing a string holds can end a comment or a scalar early.
///
/// Returns how many names were checked (none when the strings make no loadable profile).
///
/// # Panics
/// When an export does not parse or a string does not come back as written.
pub fn export_escape(data: &[u8]) -> usize {
    use crate::profile::escape::toml_str;
    use crate::profile::export::{Target, export};
    let text = String::from_utf8_lossy(data);
    let mut parts = text.split('\u{1}');
    let device = parts.next().unwrap_or_default();
    let name = parts.next().unwrap_or_default();
    let mut toml = format!("[profile]\nname = {}\ndevice = {}\n", toml_str(name), toml_str(device));
    let mut wanted = Vec::new();
    for (i, reg) in parts.take(8).enumerate() {
        let (reg_name, unit) = reg.split_once('\u{2}').unwrap_or((reg, ""));
        if reg_name.trim().is_empty() || wanted.iter().any(|(n, _)| n == reg_name) {
            continue;
        }
        let _ = std::fmt::Write::write_fmt(
            &mut toml,
            format_args!("[[holding_registers]]\naddress = {}\nname = {}\n", i * 2, toml_str(reg_name)),
        );
        if !unit.is_empty() {
            let _ = std::fmt::Write::write_fmt(&mut toml, format_args!("unit = {}\n", toml_str(unit)));
        }
        wanted.push((reg_name.to_owned(), unit.to_owned()));
    }
    let Ok(p) = crate::profile::load("fuzz.toml", &toml) else { return 0 };
    let names: Vec<(String, Option<String>)> = p
        .tables
        .values()
        .flat_map(|slots| slots.values())
        .filter_map(|slot| p.defs.get(slot.def).map(|d| (slot.name.clone(), d.unit.clone())))
        .collect();
    for target in [Target::HomeAssistant, Target::Esphome, Target::Telegraf] {
        let e = export(&p, 1, target);
        let first = e.text.lines().next().unwrap_or_default();
        assert!(
            first.chars().all(|c| c == ' ' || c.is_ascii_graphic() || (!c.is_ascii() && c.is_alphanumeric())),
            "{first:?}"
        );
        let back: serde_json::Value = if target == Target::Telegraf {
            let v = toml::from_str::<toml::Value>(&e.text);
            assert!(v.is_ok(), "TOML: {v:?}\n{}", e.text);
            v.ok().and_then(|v| serde_json::to_value(v).ok()).unwrap_or_default()
        } else {
            let v = serde_norway::from_str::<serde_json::Value>(&e.text);
            assert!(v.is_ok(), "YAML: {v:?}\n{}", e.text);
            v.unwrap_or_default()
        };
        let list = match target {
            Target::HomeAssistant => back["modbus"][0]["sensors"].clone(),
            Target::Esphome => back["sensor"].clone(),
            Target::Telegraf => back["inputs"]["modbus"][0]["holding_registers"].clone(),
        };
        let got: Vec<&str> =
            list.as_array().map(|a| a.iter().filter_map(|x| x["name"].as_str()).collect()).unwrap_or_default();
        for (n, unit) in &names {
            assert!(got.contains(&n.as_str()), "{target:?}: {n:?} not read back from\n{}", e.text);
            if let (Some(u), Target::HomeAssistant) = (unit, target) {
                // A known unit goes out as Home Assistant spells it (issue 42), any other as written.
                let u = crate::profile::ha_classes::ha_class(u).map_or(u.as_str(), |c| c.unit);
                let found =
                    list.as_array().is_some_and(|a| a.iter().any(|x| x["unit_of_measurement"].as_str() == Some(u)));
                assert!(found, "unit {u:?} not read back\n{}", e.text);
            }
        }
    }
    names.len()
}

/// Any bytes as a SunSpec device's registers (issue 27): the chain walked from register 0 the
/// way `read --device sunspec` walks it, every model decoded whatever its ID and length, and
/// the bytes as a point name — never a panic.
pub fn sunspec(data: &[u8]) {
    let regs: Vec<u16> = data.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect();
    let _ = crate::sunspec::parse_point_ref(&String::from_utf8_lossy(data));
    let mut at = Some(0u16);
    let mut found = 0;
    while let Some(a) = at {
        let i = usize::from(a);
        let (Some(&id), Some(&len)) = (regs.get(i), regs.get(i + 1)) else { break };
        let f = crate::sunspec::Found { id, address: a, len };
        let end = (i + 2 + usize::from(len)).min(regs.len());
        let values = crate::sunspec::decode_model(crate::sunspec::model(id), f, &regs[i..end]);
        for v in &values {
            let _ = v.shown.as_ref().map(ToString::to_string);
        }
        // Any model's layout over the same registers, too.
        let _ = crate::sunspec::decode_model(
            crate::sunspec::model(u16::from(data.first().copied().unwrap_or(1))),
            f,
            &regs[i..end],
        );
        found += 1;
        at = crate::sunspec::next_header(a, id, len, found);
    }
}

/// Any bytes as a store-and-forward buffer file (torn, damaged, someone else's), every record
/// read back as the publisher forwards it; and as one record's body, written and read again.
///
/// # Panics
/// When a record written does not read back as written: the point of this harness.
pub fn spool(data: &[u8]) {
    let parsed = crate::spool::parse_records(data);
    for (kind, body) in &parsed.records {
        if *kind == crate::spool::Kind::Mqtt {
            let _ = crate::spool::parse_mqtt_body(body);
        }
    }
    let mut file = Vec::new();
    if crate::spool::encode_record(crate::spool::Kind::Sparkplug, data, &mut file) {
        let again = crate::spool::parse_records(&file);
        assert_eq!(again.records, [(crate::spool::Kind::Sparkplug, data)], "a record reads back as written");
    }
}

/// Any bytes as a Sparkplug payload from the broker (an NCMD to the node), as a held update
/// read back from the buffer, and as a value the node publishes.
pub fn sparkplug(data: &[u8]) {
    use crate::sparkplug::{EdgeNode, Sample};
    let _ = crate::sparkplug::Payload::parse_payload(data);
    let mut node = EdgeNode::new("g", "n", 1);
    let _ = node.will();
    node.online(0);
    let _ = node.command("spBv1.0/g/NCMD/n", data, 1);
    let _ = node.historical(data, 2);
    let text = String::from_utf8_lossy(data);
    let value = serde_json::from_str(&text).unwrap_or(serde_json::Value::String(text.clone().into_owned()));
    let sample = Sample {
        name: crate::sparkplug::node::metric_name(&text),
        value,
        bits: data.first().is_some_and(|b| b & 1 == 1),
        unit: Some(text.into_owned()),
        t_ms: 3,
    };
    let _ = node.update(&String::from_utf8_lossy(data), vec![sample], 5, 3);
    let _ = node.tick(u64::MAX, 4);
    node.offline();
}

#[cfg(test)]
mod tests {
    /// The fuzz target's seed (`fuzz/seeds/export_escape/hostile`): device with U+2028 and
    /// U+0085 before YAML keys, registers `yes` (unit `kWh`), `1:20` (unit `=cmd`), `<<`, and
    /// ` a<VT>b` (unit `V`), fields split by 0x01, name and unit by 0x02.
    const HOSTILE_SEED: &[u8] =
        b"meter\xe2\x80\xa8shell_command:\x01evil\xc2\x85x\x01yes\x02kWh\x011:20\x02=cmd\x01<<\x01 a\x0bb\x02V";

    #[test]
    fn every_export_of_hostile_strings_reads_back_as_written() {
        assert!(super::export_escape(HOSTILE_SEED) >= 3);
    }
}
