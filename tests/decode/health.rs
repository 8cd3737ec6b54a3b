//! The health report names each fault the virtual bus injects — with the right unit, count and
//! times — and says nothing about a healthy bus. Ground truth comes from the frames the bus
//! generated, not from the analyzer.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::collections::BTreeMap;
use std::sync::Arc;

use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings};
use mbtap_analysis::health::{Finding, Health, Report};
use mbtap_sim::Slave;
use mbtap_sim::bus::{Fault, LineFrame, VirtualBus};
use mbtap_sim::uart::Listener;

const START_NS: u64 = 1_000_000_000_000;

/// `n` transactions of the demo bus with `faults` (every 4th), heard at `heard_at`; the
/// frames of each transaction and the report.
fn run(n: usize, faults: &[Fault], heard_at: Option<LineSettings>) -> (Vec<Vec<LineFrame>>, Report) {
    run_with(n, heard_at, |bus, i| {
        if i == 0 {
            bus.faults = faults.to_vec();
        }
    })
}

/// As [`run`], with `setup` changing the bus before transaction `i`.
fn run_with(
    n: usize,
    heard_at: Option<LineSettings>,
    mut setup: impl FnMut(&mut VirtualBus, usize),
) -> (Vec<Vec<LineFrame>>, Report) {
    let profiles = mbtap_sim::demo_profiles().unwrap();
    let slaves = profiles.iter().map(|(&a, p)| Slave::new(Arc::new(p.clone()), a)).collect();
    let line = LineSettings::default();
    let mut bus = VirtualBus::new(slaves, line);
    let listen = heard_at.unwrap_or(line);
    let mut listener = Listener::new(line, listen);
    let mut health = Health::new(profiles);
    let mut analyzer =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(listen, 0), ..AnalyzerConfig::default() });
    let mut all = Vec::new();
    for i in 0..n {
        setup(&mut bus, i);
        let frames = bus.next_transaction();
        for f in &frames {
            let bytes: Vec<u8> = listener.hear(f).into_iter().map(|(_, b)| b).collect();
            let t = Timestamp(START_NS + f.end_ns);
            analyzer.push(&Chunk { port: PortId(0), t, bytes: &bytes }, &mut |e: &Event<'_>| health.event(e));
            analyzer.tick(Timestamp(t.0 + 2_000_000), &mut |e: &Event<'_>| health.event(e));
        }
        all.push(frames);
    }
    analyzer.finish(&mut |e: &Event<'_>| health.event(e));
    (all, health.report())
}

/// An RTU frame.
fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    mbtap_proto::encode_rtu(unit, pdu, &mut out);
    out
}

/// The report of `frames` — each `(silence before it in ns, bytes)`, sent at the default
/// line's character time — checked against `profiles`.
fn report_of(profiles: mbtap_analysis::decode::Profiles, frames: &[(u64, Vec<u8>)]) -> Report {
    let mut health = Health::new(profiles);
    let mut analyzer = Analyzer::new(AnalyzerConfig::default());
    let char_ns = LineSettings::default().char_ns();
    let mut t = START_NS;
    for (silence, frame) in frames {
        t += silence + char_ns * frame.len() as u64;
        analyzer.push(&Chunk { port: PortId(0), t: Timestamp(t), bytes: frame }, &mut |e: &Event<'_>| health.event(e));
    }
    analyzer.finish(&mut |e: &Event<'_>| health.event(e));
    health.report()
}

fn of_kind<'a>(r: &'a Report, kind: &str) -> Vec<&'a Finding> {
    r.findings.iter().filter(|f| f.kind == kind).collect()
}

fn crc_ok(f: &[u8]) -> bool {
    f.len() >= 4 && mbtap_proto::crc16(&f[..f.len() - 2]).to_le_bytes() == f[f.len() - 2..]
}

/// Start of a frame (ns, as the report's clock) from its end and length.
fn start_ns(f: &LineFrame) -> u64 {
    START_NS + f.end_ns - LineSettings::default().char_ns() * f.bytes.len() as u64
}

#[test]
fn a_healthy_bus_gives_a_clean_report() {
    let (_, r) = run(200, &[], None);
    assert!(r.findings.is_empty(), "{}", r.text());
    assert_eq!(r.units.len(), 3);
    assert!(r.units.iter().all(|u| (u.availability_percent - 100.0).abs() < 1e-9));
    assert!(r.text().contains("findings: none"));
}

#[test]
fn a_silent_slave_is_named_with_its_unanswered_requests_and_times() {
    // 120 transactions: the 120th is silent, and the capture ends while it waits.
    let (tx, r) = run(120, &[Fault::SilentSlave], None);
    assert_eq!(tx.last().unwrap().len(), 1);
    // Ground truth: transactions that are a request alone, but for the last one — no one can
    // know it went unanswered (regression: it was counted as no_response).
    let mut truth: BTreeMap<u8, Vec<u64>> = BTreeMap::new();
    for frames in &tx[..tx.len() - 1] {
        if frames.len() == 1 {
            truth.entry(frames[0].bytes[0]).or_default().push(start_ns(&frames[0]));
        }
    }
    let found = of_kind(&r, "no_response");
    assert_eq!(found.len(), truth.len(), "{}", r.text());
    for f in found {
        let times = &truth[&f.unit.unwrap()];
        assert_eq!(f.count, times.len() as u64);
        assert!(f.first_t_ns.abs_diff(times[0]) < 1_000_000, "first time");
        assert!(f.last_t_ns.abs_diff(*times.last().unwrap()) < 1_000_000, "last time");
        assert!(f.summary.contains("intermittently"), "they answer the other polls: {}", f.summary);
    }
}

#[test]
fn corrupted_answers_are_check_errors_of_their_units_or_of_the_bus() {
    let (tx, r) = run(120, &[Fault::Corrupt], None);
    let bad: u64 = tx.iter().filter(|f| f.len() == 2 && !crc_ok(&f[1].bytes)).count() as u64;
    let found = of_kind(&r, "check_errors");
    assert!(!found.is_empty(), "{}", r.text());
    assert_eq!(found.iter().map(|f| f.count).sum::<u64>(), bad, "{}", r.text());
    assert!(of_kind(&r, "no_response").is_empty(), "{}", r.text());
}

#[test]
fn noise_bursts_are_counted() {
    let (tx, r) = run(120, &[Fault::Noise], None);
    let bursts = tx.iter().filter(|f| f.len() == 3).count() as u64;
    let found = of_kind(&r, "noise");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!(found[0].unit, None);
    assert_eq!(found[0].count, bursts);
}

#[test]
fn a_slave_pausing_inside_its_frames_is_named() {
    let (tx, r) = run(120, &[Fault::SlowSlave], None);
    // Ground truth: answers sent in two parts.
    let mut truth: BTreeMap<u8, u64> = BTreeMap::new();
    for frames in &tx {
        if frames.len() == 3 {
            *truth.entry(frames[1].bytes[0]).or_default() += 1;
        }
    }
    let found: BTreeMap<u8, u64> = of_kind(&r, "gap_inside_frame").iter().map(|f| (f.unit.unwrap(), f.count)).collect();
    assert_eq!(found, truth, "{}", r.text());
}

#[test]
fn a_master_polling_faster_than_t35_is_named() {
    let (tx, r) = run(120, &[Fault::FastMaster], None);
    // Ground truth: requests that start less than t3.5 after the previous frame ended.
    let t35 = LineSettings::default().t35_ns();
    let fast = tx.windows(2).filter(|w| start_ns(&w[1][0]) - (START_NS + w[0].last().unwrap().end_ns) < t35).count();
    let found = of_kind(&r, "fast_master");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!(found[0].count, fast as u64, "{}", r.text());
}

#[test]
fn a_listener_at_the_wrong_baud_rate_is_told_so() {
    let (_, r) = run(60, &[], Some("9600 8N1".parse().unwrap()));
    let found = of_kind(&r, "wrong_line_settings");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert!(found[0].summary.contains("mbtap scan"));
}

#[test]
fn an_exception_storm_is_named_with_its_codes() {
    // A master polling registers the MK4 does not have: exception 02 every time.
    let profile = mbtap_device::profile::builtin::get("mk4").unwrap().unwrap();
    let mut slave = Slave::new(Arc::new(profile), 1);
    // Read input register 1000 (function 04, address 0x03E8, quantity 1).
    let pdu = [0x04, 0x03, 0xE8, 0x00, 0x01];
    let answer = rtu(1, &slave.handle(1, &pdu).unwrap());
    let frames: Vec<(u64, Vec<u8>)> =
        (0..20).flat_map(|_| [(100_000_000, rtu(1, &pdu)), (5_000_000, answer.clone())]).collect();
    let r = report_of(mbtap_analysis::decode::Profiles::new(), &frames);
    let found = of_kind(&r, "exception_storm");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!((found[0].unit, found[0].count), (Some(1), 20));
    assert!(found[0].summary.contains("0x02×20"), "{}", found[0].summary);
}

#[test]
fn the_json_report_has_the_documented_keys() {
    let (_, r) = run(60, &[Fault::SilentSlave], None);
    let j = r.json();
    let f = &j["findings"][0];
    for key in ["kind", "unit", "count", "first_t_ns", "last_t_ns", "evidence"] {
        assert!(!f[key].is_null() || key == "unit", "{key} missing in {f}");
    }
    assert!(j["units"].as_array().unwrap().len() == 3);
}

#[test]
fn the_html_report_is_self_contained_and_has_its_three_plots() {
    let (_, r) = run(120, &[Fault::SilentSlave, Fault::Noise], None);
    let html = mbtap_analysis::health::html::render(&r, "test <bus>");
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.contains("test &lt;bus&gt;"), "titles are escaped");
    for id in ["id=\"latency\"", "id=\"errors\"", "id=\"availability\""] {
        assert!(html.contains(id), "{id} missing");
    }
    // Points for latencies, bars for errors and units; no external resources.
    assert!(html.matches("<circle").count() > 50);
    assert!(html.contains("fill=\"#d62728\"><title>"), "error bars");
    assert!(!html.contains("src=") && !html.contains("href="), "nothing loaded from elsewhere");
    assert!(html.contains("data-kind=\"no_response\"") && html.contains("data-kind=\"noise\""));
}

/// The report of a recorded noisy line, as a user sees it (golden transcript).
#[test]
fn report_of_a_recorded_noisy_line() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-19200-8e1-usb1ms-noisy.pcapng");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap")).args(["report", capture]).output().unwrap();
    assert!(out.status.success());
    insta::assert_snapshot!(String::from_utf8(out.stdout).unwrap());
}

/// On the recorded line behind a 16 ms USB timer, an answer garbled in place (its address byte hit:
/// `A7 06 00 9B B9 4A 0B C6`, "unit 167") with an apparent pause inside it makes no `unit 167` row
/// in the report of a bus with no unit 167: a failed frame's address byte names a unit only where
/// that unit's answer is awaited.
#[test]
fn a_garbled_address_makes_no_unit_row() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-9600-8e1-usb16ms.pcapng");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap")).args(["report", capture]).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let units: Vec<&str> =
        text.lines().filter_map(|l| l.strip_prefix("unit ")).map(|l| l.split(':').next().unwrap().trim()).collect();
    assert_eq!(units, ["1", "5", "17", "33", "247"], "{text}");
    assert!(text.contains("no unit can be named"), "the garbled answer is still a finding: {text}");
}

/// `scan` on simulated lines: the virtual bus sent at the true settings, heard through the UART
/// model at every candidate's; the winner must be the truth and the units all three devices.
fn scan(truth: &str, ascii: bool) -> Vec<mbtap_analysis::scan::Score> {
    let line: LineSettings = truth.parse().unwrap();
    let profiles = mbtap_sim::demo_profiles().unwrap();
    let slaves = profiles.iter().map(|(&a, p)| Slave::new(Arc::new(p.clone()), a)).collect();
    let mut bus = VirtualBus::new(slaves, line);
    bus.ascii = ascii;
    let frames: Vec<LineFrame> = (0..20).flat_map(|_| bus.next_transaction()).collect();
    mbtap_sim::scan_line(&frames, line)
}

#[test]
fn scan_finds_the_settings_of_simulated_lines() {
    use mbtap_analysis::analyzer::SerialMode;
    // A two-stop-bit line reads alike at one stop bit: one ranks first, the tie is said.
    for (truth, found, ascii) in [
        ("9600 8E1", "9600 8E1", false),
        ("19200 8N2", "19200 8N1", false),
        ("115200 8N1", "115200 8N1", false),
        ("9600 7E1", "9600 7E1", true),
    ] {
        let ranked = scan(truth, ascii);
        let best = &ranked[0];
        let expected: LineSettings = found.parse().unwrap();
        assert_eq!(
            mbtap_analysis::scan::tied_stop_bits(&ranked),
            (truth != found).then_some(2),
            "{truth}: the tie between stop bits is found only where there is one"
        );
        assert_eq!(
            best.candidate.line, expected,
            "{truth}: best {:?} (runner-up {:?})",
            best.candidate, ranked[1].candidate
        );
        assert_eq!(best.candidate.mode, if ascii { SerialMode::Ascii } else { SerialMode::Rtu }, "{truth}");
        assert_eq!(best.units, [1, 5, 17].into_iter().collect(), "{truth}");
        assert_eq!(best.valid_frames, 40, "{truth}: every frame of 20 transactions");
    }
}

#[test]
fn two_devices_on_one_address_answer_twice() {
    // Unit 1 asked to read holding register 100 (function 03, address 0x0064, quantity 1); two
    // answers (7, then 9 from the other device at address 1).
    let req = rtu(1, &[0x03, 0x00, 0x64, 0x00, 0x01]);
    let a = rtu(1, &[0x03, 0x02, 0x00, 0x07]);
    let b = rtu(1, &[0x03, 0x02, 0x00, 0x09]);
    let frames: Vec<(u64, Vec<u8>)> =
        (0..5).flat_map(|_| [(100_000_000, req.clone()), (5_000_000, a.clone()), (5_000_000, b.clone())]).collect();
    let r = report_of(mbtap_analysis::decode::Profiles::new(), &frames);
    let found = of_kind(&r, "duplicate_address");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!((found[0].unit, found[0].count), (Some(1), 5));
}

#[test]
fn two_devices_answering_together_garble_like_a_wired_and() {
    let (tx, r) = run(200, &[Fault::Collision], None);
    // Ground truth: answers that failed their check (the fault hits unit 1 only).
    let garbled: Vec<&Vec<LineFrame>> = tx.iter().filter(|f| f.len() == 2 && !crc_ok(&f[1].bytes)).collect();
    assert!(garbled.iter().all(|f| f[0].bytes[0] == 1));
    let truth: Vec<u64> = garbled.iter().map(|f| start_ns(&f[0])).collect();
    assert!(truth.len() >= 5, "the fault happened: {}", truth.len());
    let found = of_kind(&r, "duplicate_address");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!(found[0].unit, Some(1));
    // Recognised only against an earlier good answer to the same request, and only when
    // enough bits were cleared: most of them, and never one that was not a collision.
    let n = usize::try_from(found[0].count).unwrap();
    assert!(n * 2 >= truth.len() && n <= truth.len(), "{n} of {}: {}", truth.len(), r.text());
    for t in &found[0].evidence {
        assert!(truth.iter().any(|x| x.abs_diff(*t) < 1_000_000), "evidence {t} is not a collision");
    }
}

#[test]
fn flipped_bits_are_not_taken_for_a_second_device() {
    let (_, r) = run(200, &[Fault::Corrupt], None);
    assert!(of_kind(&r, "duplicate_address").is_empty(), "{}", r.text());
}

#[test]
fn a_second_master_is_named_with_the_times_of_its_requests() {
    let (tx, r) = run(160, &[Fault::SecondMaster], None);
    // Ground truth: the transactions with the other master's request (frame 1 of 4).
    let truth: Vec<u64> = tx.iter().filter(|f| f.len() == 4).map(|f| start_ns(&f[1])).collect();
    assert!(truth.len() >= 20, "{}", truth.len());
    let found = of_kind(&r, "second_master");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!((found[0].unit, found[0].count), (None, truth.len() as u64), "{}", r.text());
    for (t, x) in found[0].evidence.iter().zip(&truth) {
        assert!(t.abs_diff(*x) < 1_000_000, "evidence {t} vs {x}");
    }
    // Every request was answered: the overlap is not mistaken for a silent unit.
    for kind in ["no_response", "late_answer", "duplicate_address", "check_errors"] {
        assert!(of_kind(&r, kind).is_empty(), "{kind}: {}", r.text());
    }
    assert!(r.units.iter().all(|u| (u.availability_percent - 100.0).abs() < 1e-9), "{}", r.text());
}

#[test]
fn an_answer_after_the_master_gave_up_is_a_late_answer() {
    // Unit 1 answers in about 30 ms; the master waits 20 ms, then asks unit 5, whose answer
    // follows unit 1's. Read holding register 100 of each (function 03, quantity 1).
    let ask1 = rtu(1, &[0x03, 0x00, 0x64, 0x00, 0x01]);
    let ask5 = rtu(5, &[0x03, 0x00, 0x64, 0x00, 0x01]);
    let answer1 = rtu(1, &[0x03, 0x02, 0x00, 0x07]);
    let answer5 = rtu(5, &[0x03, 0x02, 0x00, 0x08]);
    let frames: Vec<(u64, Vec<u8>)> = (0..6)
        .flat_map(|_| {
            [
                (100_000_000, ask1.clone()),
                (20_000_000, ask5.clone()),
                (5_000_000, answer1.clone()),
                (3_000_000, answer5.clone()),
            ]
        })
        .collect();
    let r = report_of(mbtap_analysis::decode::Profiles::new(), &frames);
    let found = of_kind(&r, "late_answer");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!((found[0].unit, found[0].count), (Some(1), 6), "{}", r.text());
    assert!(found[0].summary.contains("waited only 20.0 ms"), "{}", found[0].summary);
    assert!(of_kind(&r, "second_master").is_empty(), "{}", r.text());
}

#[test]
fn check_errors_in_one_burst_are_told_apart_from_steady_ones() {
    // Every answer corrupted for 15 transactions in the middle of 300, none elsewhere.
    let (_, r) = run_with(300, None, |bus, i| {
        bus.fault_every = 1;
        bus.faults = if (150..165).contains(&i) { vec![Fault::Corrupt] } else { Vec::new() };
    });
    let found = of_kind(&r, "check_errors");
    assert!(!found.is_empty(), "{}", r.text());
    assert!(found.iter().all(|f| f.summary.contains("in bursts")), "{}", r.text());
    let (_, steady) = run(300, &[Fault::Corrupt], None);
    let found = of_kind(&steady, "check_errors");
    assert!(!found.is_empty() && found.iter().all(|f| f.summary.contains("spread over")), "{}", steady.text());
}

#[test]
fn the_polling_period_is_the_time_between_identical_requests() {
    let (tx, r) = run(200, &[], None);
    // Ground truth: per unit, the median interval between a request and the next identical one.
    let mut last: BTreeMap<Vec<u8>, u64> = BTreeMap::new();
    let mut periods: BTreeMap<u8, Vec<u64>> = BTreeMap::new();
    for f in &tx {
        let t = start_ns(&f[0]);
        if let Some(prev) = last.insert(f[0].bytes.clone(), t) {
            periods.entry(f[0].bytes[0]).or_default().push(t - prev);
        }
    }
    for u in &r.units {
        let p = periods.get_mut(&u.unit).unwrap();
        p.sort_unstable();
        let truth = p[p.len() / 2];
        let found = u.poll_period_ns.unwrap();
        assert!(found.abs_diff(truth) < 1_000_000, "unit {}: {found} vs {truth}", u.unit);
    }
}

/// A failed answer to a request that overtook an unanswered one is a failed answer, not noise: the
/// overtaken request's timeout leaves the newer one awaited.
#[test]
fn a_failed_answer_to_a_request_that_overtook_another_is_not_noise() {
    // Unit 9 (absent) asked, then after 200 ms unit 1, whose answer's CRC is damaged.
    let mut bad = rtu(1, &[0x03, 0x02, 0x00, 0x07]);
    *bad.last_mut().unwrap() ^= 0x55;
    let frames = [
        (0, rtu(9, &[0x03, 0x00, 0x64, 0x00, 0x01])),
        (200_000_000, rtu(1, &[0x03, 0x00, 0x64, 0x00, 0x01])),
        (5_000_000, bad),
    ];
    let r = report_of(mbtap_analysis::decode::Profiles::new(), &frames);
    assert!(of_kind(&r, "noise").is_empty(), "{}", r.text());
    let units = |kind| of_kind(&r, kind).iter().map(|f| (f.unit, f.count)).collect::<Vec<_>>();
    assert_eq!(units("check_errors"), [(Some(1), 1)], "{}", r.text());
    assert_eq!(units("no_response"), [(Some(9), 1)], "{}", r.text());
}

/// Reads of the MK4's phase A voltage (unit 1, input register 430 = 0x01AE, quantity 1),
/// 100 ms apart, each answered after 5 ms with one raw value (0.1 V).
fn mk4_phase_a_reads(raw: &[u16]) -> Vec<(u64, Vec<u8>)> {
    let req = rtu(1, &[0x04, 0x01, 0xAE, 0x00, 0x01]);
    raw.iter()
        .flat_map(|v| {
            let [h, l] = v.to_be_bytes();
            [(100_000_000, req.clone()), (5_000_000, rtu(1, &[0x04, 0x02, h, l]))]
        })
        .collect()
}

#[test]
fn a_reading_that_jumps_implausibly_is_named() {
    // MK4 phase A voltage (input register 430, 0.1 V, documented 0–4000): 230 V, then 0 V,
    // then 230 V again — a sensor or wiring fault, not mains.
    let frames = mk4_phase_a_reads(&[2300, 2301, 2299, 0, 2300, 2302]);
    let r = report_of(mbtap_sim::demo_profiles().unwrap(), &frames);
    let found = of_kind(&r, "implausible_jump");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!((found[0].unit, found[0].count), (Some(1), 2), "down to 0 and back up: {}", r.text());
}

#[test]
fn replay_ends_with_the_same_report_when_asked() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-19200-8e1-usb1ms-noisy.pcapng");
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let out =
        std::process::Command::new(bin).args(["replay", capture, "--report", "--format", "jsonl"]).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let last: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    assert_eq!(last["event"], "report");
    let report = std::process::Command::new(bin).args(["report", capture, "--format", "json"]).output().unwrap();
    let report: serde_json::Value = serde_json::from_slice(&report.stdout).unwrap();
    assert_eq!(last["findings"], report["findings"], "one analysis, two ways to ask for it");
}

#[test]
fn report_every_gives_the_report_so_far_by_bus_time() {
    // The capture spans 5.9 s of bus time: reports after 2 and 4 s, then the final one.
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-19200-8e1-usb1ms-noisy.pcapng");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["replay", capture, "--report-every", "2", "--format", "jsonl"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let events: Vec<serde_json::Value> =
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let reports: Vec<&serde_json::Value> = events.iter().filter(|e| e["event"] == "report").collect();
    let finals: Vec<bool> = reports.iter().map(|r| r["final"].as_bool().unwrap()).collect();
    assert_eq!(finals, [false, false, true]);
    // Each covers more of the bus than the one before, and the last all of it.
    let transactions: Vec<u64> = reports.iter().map(|r| r["transactions"].as_u64().unwrap()).collect();
    assert!(transactions.windows(2).all(|w| w[0] < w[1]), "{transactions:?}");
    let first = reports[0]["first_t_ns"].as_u64().unwrap();
    let until = reports[0]["last_t_ns"].as_u64().unwrap();
    assert!((2_000_000_000..2_200_000_000).contains(&(until - first)), "first after 2 s: {}", until - first);
    // A bad value is an error that names the option.
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["replay", capture, "--report-every", "0"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(said.contains("--report-every") && said.contains("'0'") && said.contains("above 0"), "{said}");
}

/// The frames of `n` transactions of the demo bus at `sent`, as a receiver at `heard` got them:
/// one untimed byte stream, as `cat /dev/ttyUSB0 > dump.bin` stores it.
fn dump(sent: &str, heard: &str, ascii: bool, n: usize) -> Vec<u8> {
    let sent: LineSettings = sent.parse().unwrap();
    let profiles = mbtap_sim::demo_profiles().unwrap();
    let slaves = profiles.iter().map(|(&a, p)| Slave::new(Arc::new(p.clone()), a)).collect();
    let mut bus = VirtualBus::new(slaves, sent);
    bus.ascii = ascii;
    let mut listener = Listener::new(sent, heard.parse().unwrap());
    (0..n).flat_map(|_| bus.next_transaction()).flat_map(|f| listener.hear(&f)).map(|(_, b)| b).collect()
}

#[test]
fn scan_of_stored_bytes_tells_the_mode_and_the_character_size() {
    use mbtap_analysis::analyzer::SerialMode;
    use mbtap_analysis::scan::{EighthBit, scan_stored};
    let untimed = |bytes: Vec<u8>| vec![(0u64, bytes)];
    // RTU recorded at the right settings: every frame, all three units.
    let best = &scan_stored(&untimed(dump("19200 8E1", "19200 8E1", false, 20)), LineSettings::default())[0];
    assert_eq!((best.mode, best.seven_bit), (SerialMode::Rtu, None));
    assert_eq!((best.score.valid_frames, best.score.bad_frames), (40, 0));
    assert_eq!(best.score.units, [1, 5, 17].into_iter().collect());
    // A 7E1 ASCII line recorded at 8N1: the parity bit is stored as the eighth data bit.
    let best = &scan_stored(&untimed(dump("9600 7E1", "9600 8N1", true, 20)), LineSettings::default())[0];
    assert_eq!((best.mode, best.seven_bit), (SerialMode::Ascii, Some(EighthBit::Even)));
    assert_eq!(best.score.valid_frames, 40);
    // ... and at 7E1: plain ASCII.
    let best = &scan_stored(&untimed(dump("9600 7E1", "9600 7E1", true, 20)), LineSettings::default())[0];
    assert_eq!((best.mode, best.seven_bit, best.score.valid_frames), (SerialMode::Ascii, None, 40));
    // Recorded at the wrong baud rate: nothing can be recovered from the bytes.
    let ranked = scan_stored(&untimed(dump("19200 8E1", "9600 8N1", false, 20)), LineSettings::default());
    assert!(ranked.iter().all(|r| r.score.valid_frames == 0), "{ranked:?}");
}

#[test]
fn scan_of_a_file_reads_captures_and_raw_dumps() {
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/mk4-doc-examples-ascii.pcapng");
    let out = std::process::Command::new(bin).args(["scan", capture]).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(out.status.success(), "{text}");
    assert!(text.contains("recorded at 19200 7E1") && text.contains("best: ascii — 20 valid frames"), "{text}");
    // A raw dump of a 7E1 ASCII line taken at 8N1.
    let dir = std::env::temp_dir().join(format!("mbtap-scan-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let raw = dir.join("dump.bin");
    std::fs::write(&raw, dump("9600 7E1", "9600 8N1", true, 20)).unwrap();
    let out = std::process::Command::new(bin).arg("scan").arg(&raw).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(out.status.success(), "{text}");
    assert!(text.contains("best: ascii, 7 data bits + even parity"), "{text}");
    assert!(text.contains("units heard: 1, 5, 17"), "{text}");
    // Recorded at the wrong baud rate: said so, exit 1.
    std::fs::write(&raw, dump("19200 8E1", "9600 8N1", false, 20)).unwrap();
    let out = std::process::Command::new(bin).arg("scan").arg(&raw).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8(out.stdout).unwrap().contains("no reading gave a valid Modbus frame"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_value_outside_the_profiles_range_is_named_with_its_times() {
    // MK4 phase A voltage (input register 430, 0.1 V, documented 0–4000): 230 V, then 3 reads
    // of 6553.5 V (0xFFFF: a sensor input floating), then 230 V.
    let frames = mk4_phase_a_reads(&[2300, 0xFFFF, 0xFFFF, 2301, 0xFFFF, 2299]);
    let r = report_of(mbtap_sim::demo_profiles().unwrap(), &frames);
    let found = of_kind(&r, "value_out_of_range");
    assert_eq!(found.len(), 1, "{}", r.text());
    assert_eq!((found[0].unit, found[0].count), (Some(1), 3), "{}", r.text());
    // The times are those of the transactions that carried the values (their requests' starts).
    let char_ns = LineSettings::default().char_ns();
    let start = |i: u64| START_NS + (i + 1) * 100_000_000 + i * (5_000_000 + char_ns * 7) + i * char_ns * 8;
    assert_eq!(found[0].evidence, [start(1), start(2), start(4)], "{}", r.text());
    // Without the profile, nothing to judge values by.
    let r = report_of(mbtap_analysis::decode::Profiles::new(), &frames);
    assert!(of_kind(&r, "value_out_of_range").is_empty());
}

/// Regression: a listener that starts in the middle of a frame heard its tail as noise, and
/// the report of a healthy bus named `noise`.
#[test]
fn joining_the_line_mid_frame_is_not_noise() {
    // The last 5 bytes of an answer, then healthy polls of unit 1.
    let answer = rtu(1, &[0x03, 0x02, 0x00, 0x07]);
    let mut frames = vec![(0, answer[2..].to_vec())];
    for _ in 0..5 {
        frames.push((100_000_000, rtu(1, &[0x03, 0x00, 0x64, 0x00, 0x01])));
        frames.push((5_000_000, answer.clone()));
    }
    let r = report_of(mbtap_analysis::decode::Profiles::new(), &frames);
    assert!(r.findings.is_empty(), "{}", r.text());
    assert_eq!((r.noise_bytes, r.cut_at_start_bytes), (0, 5));
    // The same bytes later on are noise.
    frames.push((100_000_000, answer[2..].to_vec()));
    let r = report_of(mbtap_analysis::decode::Profiles::new(), &frames);
    assert_eq!(of_kind(&r, "noise").len(), 1, "{}", r.text());
}

/// `replay` and `report` count the recorded noisy line's noise alike (one count, one meaning:
/// failed frames nothing awaited are strays, not noise), and the units' failed checks and the
/// strays add up to the bus's.
#[test]
fn report_and_replay_count_noise_and_failed_frames_alike() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-19200-8e1-usb1ms-noisy.pcapng");
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let out = std::process::Command::new(bin).args(["replay", capture, "--format", "jsonl"]).output().unwrap();
    let summary: serde_json::Value = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|j| j["event"] == "summary")
        .unwrap();
    let out = std::process::Command::new(bin).args(["report", capture, "--format", "json"]).output().unwrap();
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["noise_bursts"], summary["noise_events"]);
    assert_eq!(report["noise_bytes"], summary["noise_bytes"]);
    assert_eq!(report["bad_frames"], summary["bad_frames"]);
    let units: u64 = report["units"].as_array().unwrap().iter().map(|u| u["bad_responses"].as_u64().unwrap()).sum();
    assert_eq!(units + report["stray_frames"].as_u64().unwrap(), report["bad_frames"].as_u64().unwrap());
}
