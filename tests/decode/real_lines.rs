//! Truth on real lines: the physics our own framer would never meet on traffic it made itself —
//! turnaround glitch bytes after frames, CRC look-alikes, reads that start inside damage — each
//! pinned with the case that was seen going wrong.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings, Parity};
use mbtap_analysis::health::{Health, Report};
use mbtap_proto::encode_rtu;
use mbtap_sim::traffic::{Observation, TrafficConfig, generate, observe, run_framer, score};

const L9600: LineSettings = LineSettings { baud: 9600, data_bits: 8, parity: Parity::Even, stop_bits: 1 };
const L19200: LineSettings = LineSettings { baud: 19_200, data_bits: 8, parity: Parity::Even, stop_bits: 1 };
const L115200: LineSettings = LineSettings { baud: 115_200, data_bits: 8, parity: Parity::None, stop_bits: 1 };

/// What the analyzer said, in order: `F+` valid frame, `F-` failed frame, `N` noise, `G`
/// glitch, with the bytes.
fn events(chunks: &[(u64, Vec<u8>)], line: LineSettings, latency_ns: u64) -> Vec<(String, Vec<u8>)> {
    let mut a =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(line, latency_ns), ..AnalyzerConfig::default() });
    let mut out = Vec::new();
    let mut sink = |e: &Event<'_>| match e {
        Event::Frame { frame, .. } => {
            out.push((if frame.check_ok { "F+" } else { "F-" }.to_owned(), frame.bytes.to_vec()));
        }
        Event::Noise(n) => out.push(("N".to_owned(), n.bytes.to_vec())),
        Event::Glitch(n) => out.push(("G".to_owned(), n.bytes.to_vec())),
        Event::Transaction(_) => {}
    };
    for (t, bytes) in chunks {
        a.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes }, &mut sink);
    }
    a.finish(&mut sink);
    out
}

fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = Vec::new();
    encode_rtu(unit, pdu, &mut f);
    f
}

/// Read 2 holding registers from 0x0405 (unit 1): `01 03 04 05 00 01 95 3B`, whose CRC high
/// byte… is not 00 — but the request followed by a `00` glitch, `01 03 04 05 00 01 95 3B 00`,
/// also reads as a CRC-valid 9-byte *response* with byte count 4 (CRC-16/MODBUS's shift
/// property). Seen on a line without fail-safe biasing.
const READ_REQUEST_THEN_GLITCH: [u8; 9] = [
    0x01, // unit 1
    0x03, // read holding registers
    0x04, 0x05, // start address 0x0405
    0x00, 0x01, // quantity 1
    0x95, 0x3B, // CRC (low byte first)
    0x00, // the master's driver switching off: a 00 with a framing error
];

#[test]
fn the_documented_lookalike_is_a_request_and_a_glitch_on_the_line() {
    // The request alone in its read, its glitch within a character, then the answer after t3.5.
    let c = L9600.char_ns();
    let answer = rtu(1, &[0x03, 0x02, 0x12, 0x34]);
    let chunks = vec![
        (1_000_000_000 + 8 * c, READ_REQUEST_THEN_GLITCH[..8].to_vec()),
        (1_000_000_000 + 9 * c, READ_REQUEST_THEN_GLITCH[8..].to_vec()),
        (1_000_000_000 + 20 * c + 7 * c, answer.clone()),
    ];
    let e = events(&chunks, L9600, 0);
    assert_eq!(
        e,
        [
            ("F+".to_owned(), READ_REQUEST_THEN_GLITCH[..8].to_vec()),
            ("G".to_owned(), vec![0x00]),
            ("F+".to_owned(), answer)
        ]
    );
}

/// One 195-byte read (a USB adapter at its 16 ms latency timer): an 89-byte answer corrupted in its
/// middle, then two valid 53-byte answers — three frames, not one 195-byte failed frame.
#[test]
fn a_read_with_a_corrupted_answer_then_two_valid_ones_gives_three_frames() {
    let regs = |seed: u8, n: u8| -> Vec<u8> {
        let mut pdu = vec![0x03, 2 * n];
        pdu.extend((0..2 * n).map(|i| i.wrapping_mul(seed).wrapping_add(7)));
        pdu
    };
    let mut corrupted = rtu(1, &regs(3, 42));
    assert_eq!(corrupted.len(), 89);
    corrupted[40] ^= 0x5A;
    let second = rtu(5, &regs(5, 24));
    let third = rtu(17, &regs(11, 24));
    assert_eq!(second.len() + third.len(), 106);
    let read: Vec<u8> = [corrupted.clone(), second.clone(), third.clone()].concat();
    assert_eq!(read.len(), 195);
    let e = events(&[(5_000_000_000, read)], L19200, 16_000_000);
    assert_eq!(e, [("F-".to_owned(), corrupted), ("F+".to_owned(), second), ("F+".to_owned(), third)]);
}

/// A clean capture whose first read gained a `00` in front (a glitch as the port opened) keeps
/// every frame after it.
#[test]
fn a_zero_before_the_first_frame_hides_no_frame_after_it() {
    let c = L19200.char_ns();
    let mut chunks = Vec::new();
    let mut t = 2_000_000_000u64;
    let mut frames = Vec::new();
    for i in 0..30u8 {
        let f = if i % 2 == 0 { rtu(1, &[0x03, 0x00, i, 0x00, 0x02]) } else { rtu(1, &[0x03, 0x04, i, 1, 2, 3]) };
        t += (f.len() as u64 + 10) * c;
        frames.push(f.clone());
        chunks.push((t, f));
    }
    chunks[0].1.insert(0, 0x00);
    let e = events(&chunks, L19200, 0);
    let valid: Vec<_> = e.iter().filter(|(k, _)| k == "F+").map(|(_, b)| b.clone()).collect();
    assert_eq!(valid, frames, "{e:?}");
}

/// Turnaround glitches after every frame, through every observation model and line speed:
/// every good frame byte-exact, none invented, nearly every glitch reported as one.
#[test]
fn glitches_after_every_frame_invent_and_lose_no_frame() {
    for (line, seed) in [(L9600, 31), (L19200, 32), (L115200, 33)] {
        let wire = generate(&TrafficConfig { seed, line, transactions: 2000, glitch: 1.0, ..TrafficConfig::default() });
        for model in [Observation::PerByte, Observation::FIFO_16550, Observation::USB_1MS, Observation::USB_16MS] {
            let chunks = observe(&wire, model, line.char_ns());
            let s =
                score(&wire, &run_framer(&wire, &chunks, FramerConfig::new(line, model.latency_ns(line.char_ns()))));
            assert!(s.good_ratio() >= 0.998, "{line} {}: {s:?}", model.name());
            assert_eq!(s.false_valid, 0, "{line} {}: {s:?}", model.name());
            assert!(s.glitch_reported * 100 >= s.glitch_total * 97, "{line} {}: {s:?}", model.name());
        }
    }
}

/// Answers made CRC look-alikes (their CRC high byte 00): no shorter twin reported.
#[test]
fn crc_lookalike_answers_are_not_cut_short() {
    let wire = generate(&TrafficConfig {
        seed: 34,
        line: L19200,
        transactions: 3000,
        lookalike: 1.0,
        ..TrafficConfig::default()
    });
    for model in [Observation::PerByte, Observation::USB_16MS] {
        let chunks = observe(&wire, model, L19200.char_ns());
        let s =
            score(&wire, &run_framer(&wire, &chunks, FramerConfig::new(L19200, model.latency_ns(L19200.char_ns()))));
        assert_eq!(s.false_valid, 0, "{}: {s:?}", model.name());
        assert!(s.good_ratio() >= 0.999, "{}: {s:?}", model.name());
    }
}

/// A healthy bus whose only fault is missing fail-safe biasing: the report names that, and
/// nothing the glitches would otherwise fake (check errors, noise, unanswered requests).
#[test]
fn a_healthy_line_with_glitches_reports_only_turnaround_glitches() {
    let line = L19200;
    let wire = generate(&TrafficConfig {
        seed: 35,
        line,
        transactions: 1500,
        glitch: 1.0,
        noise: 0.0,
        corrupt: 0.0,
        slow: 0.0,
        ..TrafficConfig::default()
    });
    for model in [Observation::PerByte, Observation::FIFO_16550, Observation::USB_1MS, Observation::USB_16MS] {
        let report = health_of(&wire, model, line);
        let kinds: Vec<_> = report.findings.iter().map(|f| (f.kind, f.unit)).collect();
        // The generator polls one address nobody answers (33): that one is real.
        let expected_extra = [("no_response", Some(33))];
        for (kind, unit) in &kinds {
            assert!(
                *kind == "turnaround_glitch" || expected_extra.contains(&(*kind, *unit)),
                "{}: unexpected {kind} {unit:?} in {kinds:?}",
                model.name()
            );
        }
        assert!(kinds.contains(&("turnaround_glitch", None)), "the master's glitches: {kinds:?}");
        assert!(kinds.iter().filter(|(k, u)| *k == "turnaround_glitch" && u.is_some()).count() >= 3, "{kinds:?}");
    }
}

fn health_of(wire: &mbtap_sim::traffic::Wire, model: Observation, line: LineSettings) -> Report {
    let chunks = observe(wire, model, line.char_ns());
    let mut a = Analyzer::new(AnalyzerConfig {
        framer: FramerConfig::new(line, model.latency_ns(line.char_ns())),
        ..AnalyzerConfig::default()
    });
    let mut health = Health::new(mbtap_device::profile::Profiles::new());
    for (t, r) in &chunks {
        a.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes: &wire.bytes[r.clone()] }, &mut |e: &Event<'_>| {
            health.event(e);
        });
    }
    a.finish(&mut |e: &Event<'_>| health.event(e));
    health.report()
}

/// The report of chunks `(read time ns, bytes)`.
fn report_of(chunks: &[(u64, Vec<u8>)], line: LineSettings, latency_ns: u64) -> Report {
    let mut a =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(line, latency_ns), ..AnalyzerConfig::default() });
    let mut health = Health::new(mbtap_device::profile::Profiles::new());
    for (t, bytes) in chunks {
        a.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes }, &mut |e: &Event<'_>| health.event(e));
    }
    a.finish(&mut |e: &Event<'_>| health.event(e));
    health.report()
}

/// Junk only, or nothing, never ends the report with "findings: none — the bus looks healthy".
#[test]
fn nothing_that_frames_is_never_healthy() {
    // Bytes with the top bit set and no structure: what a listener at the wrong settings reads.
    let junk: Vec<(u64, Vec<u8>)> = (0..50u8)
        .map(|i| {
            let bytes = (0..40u8).map(|j| i.wrapping_mul(37).wrapping_add(j.wrapping_mul(11)) | 0x80).collect();
            (1_000_000_000 + u64::from(i) * 10_000_000, bytes)
        })
        .collect();
    for chunks in [junk, Vec::new()] {
        let r = report_of(&chunks, L19200, 0);
        let kinds: Vec<_> = r.findings.iter().map(|f| f.kind).collect();
        assert!(kinds.contains(&"no_valid_frames"), "{}", r.text());
        assert!(kinds.iter().all(|k| matches!(*k, "no_valid_frames" | "wrong_line_settings")), "{}", r.text());
        assert!(!r.text().contains("healthy"), "{}", r.text());
    }
}

/// A failed frame starting with 02 in place of unit 1's answer counts against the bus, not unit 1.
#[test]
fn a_damaged_answer_with_another_address_counts_against_the_bus() {
    let c = L19200.char_ns();
    let mut chunks = Vec::new();
    let mut t = 1_000_000_000u64;
    for i in 0..40u8 {
        let req = rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]);
        let mut answer = rtu(1, &[0x03, 0x02, 0x00, i]);
        if i % 10 == 3 {
            // Address and data hit: `02 …`, CRC wrong.
            answer[0] = 0x02;
            answer[4] ^= 0x10;
        }
        t += 8 * c;
        chunks.push((t, req));
        t += 5 * c + 7 * c;
        chunks.push((t, answer));
        t += 50_000_000;
    }
    let r = report_of(&chunks, L19200, 0);
    let unit1 = r.units.iter().find(|u| u.unit == 1).unwrap();
    assert_eq!(unit1.bad_responses, 0, "{}", r.text());
    let bus = r.findings.iter().find(|f| f.kind == "check_errors").unwrap();
    assert_eq!((bus.unit, bus.count), (None, 4), "{}", r.text());
}

/// Request and answer delivered in one read (a 16 ms USB latency timer): the latency is not
/// measurable, never reported as 0.000 ms with a p50 of 0.0 ms.
#[test]
fn a_latency_no_read_can_resolve_is_not_measurable() {
    let mut chunks = Vec::new();
    for i in 0..20u64 {
        let mut read = rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01]);
        read.extend(rtu(1, &[0x03, 0x02, 0x12, 0x34]));
        chunks.push((1_000_000_000 + i * 100_000_000, read));
    }
    let mut latencies = Vec::new();
    let mut a =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(L9600, 16_000_000), ..AnalyzerConfig::default() });
    for (t, bytes) in &chunks {
        a.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes }, &mut |e: &Event<'_>| {
            if let Event::Transaction(t) = e {
                latencies.push(t.latency_ns);
            }
        });
    }
    assert_eq!(latencies.len(), 20);
    assert!(latencies.iter().all(Option::is_none), "{latencies:?}");
    let r = report_of(&chunks, L9600, 16_000_000);
    assert_eq!(r.units[0].latency_p50_ns, None, "{}", r.text());
}

/// `report` names answers sooner than t3.5 after the request, as `replay` flags them ("only N µs
/// after previous frame").
#[test]
fn an_answer_sooner_than_t35_is_a_fast_answer() {
    let c = L19200.char_ns();
    let mut chunks = Vec::new();
    let mut t = 1_000_000_000u64;
    for _ in 0..10 {
        let req = rtu(5, &[0x04, 0x00, 0x00, 0x00, 0x01]);
        let answer = rtu(5, &[0x04, 0x02, 0x00, 0x2A]);
        t += 8 * c;
        chunks.push((t, req));
        // One character of silence, not 3.5.
        t += c + 7 * c;
        chunks.push((t, answer));
        t += 30_000_000;
    }
    let r = report_of(&chunks, L19200, 0);
    let fast = r.findings.iter().find(|f| f.kind == "fast_answer").unwrap_or_else(|| panic!("{}", r.text()));
    assert_eq!((fast.unit, fast.count), (Some(5), 10));
}

/// `cat /dev/ttyUSB0 > dump.bin` starts wherever the line was: mid-frame, as a rule. `scan` of such
/// a dump finds the frames after the cut.
#[test]
fn scan_of_a_raw_dump_that_starts_mid_frame_finds_the_frames() {
    let wire = generate(&TrafficConfig { seed: 36, line: L19200, transactions: 300, ..TrafficConfig::default() });
    let good = wire.truth.iter().filter(|t| t.kind == mbtap_sim::traffic::generate::TruthKind::Good).count() as u64;
    for cut in [1, 3, 5] {
        // A raw dump: no timing at all, one chunk.
        let dump = vec![(0u64, wire.bytes[cut..].to_vec())];
        let scores = mbtap_analysis::scan::scan_stored(&dump, L19200);
        let best = &scores[0];
        assert_eq!(best.mode, mbtap_analysis::analyzer::SerialMode::Rtu);
        // All but the cut one, less a few vendor frames that only timing could have ended.
        assert!(best.score.valid_frames * 100 >= good * 99, "cut {cut}: {} of {good} frames", best.score.valid_frames);
    }
}

/// Mask Write Register 0x004D of unit 5 (AND F2F2, OR 0025), and its answer (the same echo):
/// 10 bytes each way, fixed by the request.
fn mask_write(unit: u8) -> Vec<u8> {
    rtu(unit, &[0x16, 0x00, 0x4D, 0xF2, 0xF2, 0x00, 0x25])
}

/// Behind a 16 ms USB timer, a damaged answer (its function code hit: 0x16 → 0x58) and the damaged
/// request after it, in one read, are cut where the request fixed the answer's length (10), not one
/// 17-byte failed frame.
#[test]
fn a_damaged_answer_glued_to_more_damage_is_cut_at_the_length_its_request_fixed() {
    let c = L9600.char_ns();
    let request = mask_write(5);
    let mut answer = mask_write(5);
    answer[1] = 0x58;
    let mut next = rtu(1, &[0x2B, 0x0E, 0x01, 0x00]);
    next[0] = 0xEE;
    let t0 = 3_000_000_000u64;
    // A transaction before it, so the bus is known to await a request (an echo-shaped frame
    // alone could be either).
    let chunks = vec![
        (t0 - 100_000_000, rtu(5, &[0x03, 0x00, 0x10, 0x00, 0x01])),
        (t0 - 80_000_000, rtu(5, &[0x03, 0x02, 0x12, 0x34])),
        (t0, request.clone()),
        (t0 + 16_000_000, [answer.clone(), next.clone()].concat()),
        (t0 + 200_000_000 + 8 * c, rtu(1, &[0x03, 0x00, 0x10, 0x00, 0x01])),
    ];
    let e = events(&chunks, L9600, 16_000_000);
    assert_eq!(e[2..4], [("F+".to_owned(), request), ("F-".to_owned(), answer)], "{e:02X?}");
}

/// On a line whose slaves leave `FE` after their frames, a damaged answer whose last byte the
/// damage made `FE` keeps that byte: the request fixed the answer at 10 bytes, and 10 arrived — no
/// "glitch".
#[test]
fn a_damaged_answer_ending_in_fe_keeps_its_last_byte_where_slaves_glitch_fe() {
    let c = L9600.char_ns();
    let mut chunks = Vec::new();
    let mut t = 4_000_000_000u64;
    let mut send = |gap_chars: u64, bytes: &[u8], chunks: &mut Vec<(u64, Vec<u8>)>| {
        t += gap_chars * c;
        for &b in bytes {
            t += c;
            chunks.push((t, vec![b]));
        }
    };
    for _ in 0..40 {
        send(10, &rtu(0x11, &[0x03, 0x00, 0x10, 0x00, 0x01]), &mut chunks);
        send(0, &[0x00], &mut chunks);
        send(5, &rtu(0x11, &[0x03, 0x02, 0x12, 0x34]), &mut chunks);
        send(0, &[0xFE], &mut chunks);
    }
    let request = mask_write(0x11);
    let mut answer = mask_write(0x11);
    answer[9] = 0xFE;
    send(10, &request, &mut chunks);
    send(0, &[0x00], &mut chunks);
    send(5, &answer, &mut chunks);
    send(20, &rtu(0x11, &[0x03, 0x00, 0x10, 0x00, 0x01]), &mut chunks);
    let e = events(&chunks, L9600, 0);
    let at = e.iter().position(|(_, b)| *b == request).expect("the request");
    assert_eq!(e[at + 2], ("F-".to_owned(), answer), "{:02X?}", &e[at..]);
}
