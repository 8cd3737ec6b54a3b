//! The health report through the adapters people have, with no `--latency-ms` — a
//! healthy bus gets no timing finding, a slow unit is named alone where the observer can see
//! its pauses, and what the reads cannot resolve is said once. The traffic's physics (observer
//! delays, 1.05 × t3.5 pauses, a unit pausing 30 characters) come from the generator's models.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings, Parity};
use mbtap_analysis::health::{Health, Report};
use mbtap_sim::traffic::{Observation, TrafficConfig, generate, observe};

const L9600: LineSettings = LineSettings { baud: 9600, data_bits: 8, parity: Parity::Even, stop_bits: 1 };
const L19200: LineSettings = LineSettings { baud: 19_200, data_bits: 8, parity: Parity::Even, stop_bits: 1 };
const TIMING: [&str; 3] = ["gap_inside_frame", "fast_answer", "fast_master"];

/// A bus with no fault but unit 33's absence, masters and slaves keeping 1.05 × t3.5.
fn tight_bus(line: LineSettings, glitch: f64, slow_unit: Option<u8>) -> TrafficConfig {
    let t35 = line.t35_ns();
    TrafficConfig {
        seed: 2501,
        line,
        transactions: 1500,
        noise: 0.0,
        corrupt: 0.0,
        slow: 0.0,
        glitch,
        slow_unit,
        min_idle_ns: Some(t35 + t35 / 20),
        ..TrafficConfig::default()
    }
}

/// The report as `mbtap report` makes it from a capture with no latency recorded.
fn report(cfg: &TrafficConfig, model: Observation) -> Report {
    let wire = generate(cfg);
    let chunks = observe(&wire, model, cfg.line.char_ns());
    let mut a = Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(cfg.line, 0), ..AnalyzerConfig::default() });
    let mut health = Health::new(mbtap_device::profile::Profiles::new());
    for (t, r) in &chunks {
        a.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes: &wire.bytes[r.clone()] }, &mut |e: &Event<'_>| {
            health.event(e);
        });
    }
    a.finish(&mut |e: &Event<'_>| health.event(e));
    for (port, estimate) in a.observers() {
        health.observer(port, &estimate);
    }
    health.report()
}

fn timing_findings(r: &Report) -> Vec<(&'static str, Option<u8>)> {
    r.findings.iter().filter(|f| TIMING.contains(&f.kind)).map(|f| (f.kind, f.unit)).collect()
}

#[test]
fn a_healthy_bus_through_a_16_ms_usb_timer_gives_no_timing_finding() {
    for glitch in [0.0, 1.0] {
        let r = report(&tight_bus(L9600, glitch, None), Observation::USB_16MS);
        assert_eq!(timing_findings(&r), [], "glitch {glitch}: {}", r.text());
    }
}

#[test]
fn a_healthy_bus_through_a_16550_fifo_gives_no_timing_finding() {
    for line in [L9600, L19200] {
        let r = report(&tight_bus(line, 0.3, None), Observation::FIFO_16550);
        assert_eq!(timing_findings(&r), [], "{line}: {}", r.text());
    }
}

#[test]
fn a_master_waiting_just_past_t35_is_not_fast_through_a_1_ms_usb_timer() {
    let r = report(&tight_bus(L19200, 1.0, None), Observation::USB_1MS);
    assert_eq!(timing_findings(&r), [], "{}", r.text());
}

#[test]
fn the_slow_unit_is_named_alone_through_a_fifo_and_a_16_ms_timer() {
    for model in [Observation::FIFO_16550, Observation::USB_16MS] {
        let r = report(&tight_bus(L9600, 0.0, Some(17)), model);
        assert_eq!(timing_findings(&r), [("gap_inside_frame", Some(17))], "{}: {}", model.name(), r.text());
    }
}

/// A unit pausing 2 characters inside its answers at 9600 8E1 (2.3 ms of silence; t1.5 is 1.72 ms),
/// read one byte per read up to 0.2 ms late, is named: where every read holds one byte only the
/// delays' spread is uncertain, not the latency plus a character (1.4 ms, which would hide it). The
/// unit is named, no other.
#[test]
fn a_two_character_pause_read_byte_by_byte_names_the_unit() {
    let cfg = TrafficConfig { slow_unit_chars: 2, ..tight_bus(L9600, 0.0, Some(17)) };
    let r = report(&cfg, Observation::PER_BYTE_JITTER);
    assert_eq!(timing_findings(&r), [("gap_inside_frame", Some(17))], "{}", r.text());
    // The healthy bus through the same reads: nothing.
    let r = report(&tight_bus(L9600, 0.0, None), Observation::PER_BYTE_JITTER);
    assert_eq!(timing_findings(&r), [], "{}", r.text());
}

#[test]
fn pauses_the_reads_cannot_resolve_are_said_once_not_blamed() {
    // 30 characters at 115200 are 2.6 ms: nothing a 16 ms timer can show.
    let line = LineSettings { baud: 115_200, data_bits: 8, parity: Parity::None, stop_bits: 1 };
    let r = report(&tight_bus(line, 0.0, Some(17)), Observation::USB_16MS);
    assert_eq!(timing_findings(&r), [], "{}", r.text());
    assert_eq!(r.limits.len(), 1, "{}", r.text());
    assert!(r.limits[0].contains("cannot be seen") && r.limits[0].contains("--latency-ms"), "{}", r.text());
    assert!(r.text().contains(&r.limits[0]));
}

/// On the adapter matrix's cells (`examples/findings_by_adapter.rs`, 3 000 transactions, its seeds)
/// that are hardest on a healthy bus — units whose vendor request and answer (or answer and `FE`
/// glitch) come glued at the line's start, lone glitch bytes behind a 16 ms timer — a healthy bus
/// gets no finding but its turnaround glitches (and unit 33's absence, which is true): no
/// `check_errors`, no noise.
#[test]
fn healthy_glitchy_lines_get_no_finding_but_their_glitches() {
    let l115200 = LineSettings { baud: 115_200, data_bits: 8, parity: Parity::None, stop_bits: 1 };
    let cells = [
        (Observation::PerByte, L9600, 700, 1.0),
        (Observation::FIFO_16550, L9600, 700, 0.3),
        (Observation::FIFO_16550, L9600, 700, 1.0),
        (Observation::USB_1MS, L9600, 700, 1.0),
        (Observation::USB_16MS, L9600, 700, 0.3),
        (Observation::USB_16MS, L9600, 700, 1.0),
        (Observation::USB_16MS, L19200, 701, 1.0),
        (Observation::USB_16MS, l115200, 702, 0.3),
    ];
    for (model, line, seed, glitch) in cells {
        let cfg = TrafficConfig { seed, transactions: 3000, ..tight_bus(line, glitch, None) };
        let r = report(&cfg, model);
        let wrong: Vec<_> = r
            .findings
            .iter()
            .filter(|f| f.kind != "turnaround_glitch" && !(f.kind == "no_response" && f.unit == Some(33)))
            .map(|f| (f.kind, f.unit, f.count))
            .collect();
        assert_eq!(wrong, [], "{} {line} glitch {glitch}: {}", model.name(), r.text());
    }
}
