//! The health report's findings through the adapters people have, with no `--latency-ms`: for
//! each observation model × line setting × share of frames followed by a turnaround glitch, a
//! healthy bus (masters and slaves keeping only 1.05 × t3.5 between frames) and the same bus
//! with unit 17 pausing 30 characters inside every answer. Prints a Markdown table for
//! BENCHMARKS.md.
//!
//! Run: `cargo run --release --example findings_by_adapter [transactions]`
//!
//! A cell is right when the healthy bus gets no finding but `turnaround_glitch` (and
//! `no_response` for unit 33, which the generator polls and nobody answers — a true finding)
//! and the slow bus gets `gap_inside_frame` against unit 17 where the observer can see its
//! pause, and no timing finding against any other unit or the master.

use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings, Parity};
use mbtap_analysis::health::{Health, Report};
use mbtap_sim::traffic::{Observation, TrafficConfig, generate, observe};

const TIMING: [&str; 3] = ["gap_inside_frame", "fast_answer", "fast_master"];

fn report(wire: &mbtap_sim::traffic::Wire, model: Observation, line: LineSettings) -> (Report, u64) {
    let chunks = observe(wire, model, line.char_ns());
    // No latency given: what a user who does not know their adapter's timer runs.
    let mut a = Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(line, 0), ..AnalyzerConfig::default() });
    let mut health = Health::new(mbtap_device::profile::Profiles::new());
    for (t, r) in &chunks {
        a.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes: &wire.bytes[r.clone()] }, &mut |e: &Event<'_>| {
            health.event(e);
        });
    }
    a.finish(&mut |e: &Event<'_>| health.event(e));
    let mut latency = 0;
    for (port, est) in a.observers() {
        health.observer(port, &est);
        latency = latency.max(est.effective_latency_ns());
    }
    (health.report(), latency)
}

fn main() {
    let transactions: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(3000);
    let lines = [
        LineSettings { baud: 9600, parity: Parity::Even, ..LineSettings::default() },
        LineSettings { baud: 19_200, parity: Parity::Even, ..LineSettings::default() },
        LineSettings { baud: 115_200, parity: Parity::None, ..LineSettings::default() },
    ];
    let models = [
        Observation::PerByte,
        Observation::PER_BYTE_JITTER,
        Observation::FIFO_16550,
        Observation::USB_1MS,
        Observation::USB_16MS,
    ];
    println!("{transactions} transactions per cell; no latency given to the framer\n");
    println!(
        "| observation | line | glitch | healthy: wrong findings | slow unit 17 named | slow: wrong timing findings | latency worked with |"
    );
    println!("|---|---|---|---|---|---|---|");
    let (mut wrong_total, mut cells, mut missed) = (0usize, 0usize, 0usize);
    for model in models {
        for (li, line) in lines.into_iter().enumerate() {
            for glitch in [0.0, 0.3, 1.0] {
                let t35 = line.t35_ns();
                let base = TrafficConfig {
                    seed: 700 + li as u64,
                    line,
                    transactions,
                    noise: 0.0,
                    corrupt: 0.0,
                    slow: 0.0,
                    glitch,
                    min_idle_ns: Some(t35 + t35 / 20),
                    ..TrafficConfig::default()
                };
                let healthy_wire = generate(&base);
                let (healthy, latency) = report(&healthy_wire, model, line);
                if std::env::var_os("DUMP_WRONG").is_some() {
                    dump_wrong(&healthy_wire, model, line);
                }
                let wrong: Vec<String> = healthy
                    .findings
                    .iter()
                    .filter(|f| f.kind != "turnaround_glitch" && !(f.kind == "no_response" && f.unit == Some(33)))
                    .map(|f| format!("{}{}×{}", f.kind, f.unit.map_or(String::new(), |u| format!("@{u}")), f.count))
                    .collect();
                let slow_wire = generate(&TrafficConfig { slow_unit: Some(17), ..base });
                let (slow, _) = report(&slow_wire, model, line);
                let named = slow.findings.iter().find(|f| f.kind == "gap_inside_frame" && f.unit == Some(17));
                // Whether this observer can show a 30-character pause at all: the pause beyond
                // t1.5 must exceed the adapter's true latency plus a character.
                let c = line.char_ns();
                let visible = 30 * c - line.t15_ns() >= model.latency_ns(c) + c;
                let said = slow.limits.iter().any(|l| l.contains("pause"));
                let others: Vec<String> = slow
                    .findings
                    .iter()
                    .filter(|f| TIMING.contains(&f.kind) && f.unit != Some(17))
                    .map(|f| format!("{}{}×{}", f.kind, f.unit.map_or(String::new(), |u| format!("@{u}")), f.count))
                    .collect();
                cells += 1;
                wrong_total += usize::from(!wrong.is_empty()) + usize::from(!others.is_empty());
                missed += usize::from(visible && named.is_none());
                let slow_cell = match (named, visible) {
                    (Some(f), _) => format!("yes ×{}", f.count),
                    (None, true) => "**missed**".to_owned(),
                    (None, false) => format!(
                        "cannot be seen ({})",
                        if said { "said as a limit" } else { "no trace in the reads either" }
                    ),
                };
                let latency = format!("{}.{:02} ms", latency / 1_000_000, latency % 1_000_000 / 10_000);
                println!(
                    "| {} | {line} | {glitch} | {} | {} | {} | {latency} |",
                    model.name(),
                    if wrong.is_empty() { "none".to_owned() } else { wrong.join(", ") },
                    slow_cell,
                    if others.is_empty() { "none".to_owned() } else { others.join(", ") },
                );
            }
        }
    }
    println!("\n{cells} cells: {wrong_total} with a wrong finding, slow unit missed where visible in {missed}");
}

/// With `DUMP_WRONG` set: every stretch of a healthy line the framer did not read as a valid
/// frame or a glitch (noise, a failed check), with what the wire held there, for finding out why.
fn dump_wrong(wire: &mbtap_sim::traffic::Wire, model: Observation, line: LineSettings) {
    use mbtap_sim::traffic::run_framer;
    let chunks = observe(wire, model, line.char_ns());
    for d in run_framer(wire, &chunks, FramerConfig::new(line, 0)) {
        if d.glitch || (d.frame && d.check_ok) {
            continue;
        }
        let around = wire.truth_around(&d.range, 4);
        println!(
            "WRONG {} {line} {}..{} {} [{}]\n    wire: {}",
            model.name(),
            d.range.start,
            d.range.end,
            if d.frame { "bad-check frame" } else { "noise" },
            wire.hex(d.range.clone()),
            around.join(" | ")
        );
    }
}
