//! Framer accuracy per observation model, against plain gap cutting, on generated traffic with
//! ground truth. Prints a Markdown table for BENCHMARKS.md.
//!
//! Run: `cargo run --release --example framer_accuracy [transactions]`

use mbtap::framer::{FramerConfig, LineSettings, Parity};
use mbtap::traffic::{Observation, TrafficConfig, generate, observe, run_framer, run_gap_cutter, score};

fn main() {
    let transactions: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(20_000);
    println!(
        "| line | observation | mbtap good | mbtap false valid | mbtap corrupted exact | gap-cut good | gap-cut false valid | gap-cut corrupted exact |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let lines = [
        LineSettings { baud: 9600, parity: Parity::Even, ..LineSettings::default() },
        LineSettings { baud: 19_200, parity: Parity::Even, ..LineSettings::default() },
        LineSettings { baud: 115_200, parity: Parity::None, ..LineSettings::default() },
    ];
    let models = [Observation::PerByte, Observation::FIFO_16550, Observation::USB_1MS, Observation::USB_16MS];
    for (i, line) in lines.into_iter().enumerate() {
        let cfg = TrafficConfig { seed: 42 + i as u64, line, transactions, ..TrafficConfig::default() };
        let wire = generate(&cfg);
        for model in models {
            let chunks = observe(&wire, model, line.char_ns());
            let fc = FramerConfig::new(line, model.latency_ns(line.char_ns()));
            let m = score(&wire, &run_framer(&wire, &chunks, fc));
            let g = score(&wire, &run_gap_cutter(&wire, &chunks, fc));
            println!(
                "| {line} | {} | {:.3} % ({}/{}) | {} | {:.1} % ({}/{}) | {:.3} % | {} | {:.1} % |",
                model.name(),
                m.good_ratio() * 100.0,
                m.good_recovered,
                m.good_total,
                m.false_valid,
                m.corrupted_ratio() * 100.0,
                m.corrupted_exact,
                m.corrupted_total,
                g.good_ratio() * 100.0,
                g.false_valid,
                g.corrupted_ratio() * 100.0,
            );
        }
    }
}
