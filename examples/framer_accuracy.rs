//! Framer accuracy per observation model, against plain gap cutting, on generated traffic with
//! ground truth. Prints a Markdown table for BENCHMARKS.md.
//!
//! Run: `cargo run --release --example framer_accuracy [transactions] [glitch] [lookalike]`
//! (glitch: share of frames followed by a turnaround glitch byte; lookalike: share of register
//! answers made CRC look-alikes; both 0 by default; then `unknown` to give the framer no
//! latency, so it has only what it learns from valid frames, or `fixed` to give it 0 and no
//! learning — what it did before it learned); then `vendor` for vendor functions with the
//! same lengths per unit all day and a quarter of their CRCs ending in `00` (add `nolengths`
//! to keep the framer from learning those lengths — what it did before issue 25).

use mbtap_analysis::framer::{FramerConfig, LineSettings, Parity};
use mbtap_sim::traffic::{Observation, TrafficConfig, generate, observe, run_framer, run_gap_cutter, score};

fn main() {
    let arg = |i: usize| std::env::args().nth(i);
    let transactions: usize = arg(1).and_then(|s| s.parse().ok()).unwrap_or(20_000);
    let glitch: f64 = arg(2).and_then(|s| s.parse().ok()).unwrap_or(0.0);
    let lookalike: f64 = arg(3).and_then(|s| s.parse().ok()).unwrap_or(0.0);
    // "unknown": the framer is not told the observer's latency (a capture from another tool,
    // `--latency-ms` not given) and has only what it learns; "fixed": told 0 and not learning.
    let latency = arg(4).unwrap_or_default();
    let vendor = arg(5).as_deref() == Some("vendor");
    let learn_lengths = arg(6).as_deref() != Some("nolengths");
    println!("{transactions} transactions per line setting, glitch {glitch}, look-alikes {lookalike}\n");
    println!(
        "| line | observation | mbtap good | mbtap false valid | mbtap corrupted exact | mbtap glitches | gap-cut good | gap-cut false valid | gap-cut corrupted exact |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let lines = [
        LineSettings { baud: 9600, parity: Parity::Even, ..LineSettings::default() },
        LineSettings { baud: 19_200, parity: Parity::Even, ..LineSettings::default() },
        LineSettings { baud: 115_200, parity: Parity::None, ..LineSettings::default() },
    ];
    let models = [Observation::PerByte, Observation::FIFO_16550, Observation::USB_1MS, Observation::USB_16MS];
    // Per observation model, summed over the line settings: (good, total, false valid, exact,
    // corrupted, reported with two lengths, of those the wrong one first).
    let mut per_model = [(0usize, 0usize, 0usize, 0usize, 0usize, 0usize, 0usize); 4];
    for (i, line) in lines.into_iter().enumerate() {
        let cfg = TrafficConfig {
            seed: 42 + i as u64,
            line,
            transactions,
            glitch,
            lookalike,
            vendor_fixed: vendor,
            vendor_lookalike: if vendor { 0.25 } else { 0.0 },
            ..TrafficConfig::default()
        };
        let wire = generate(&cfg);
        for (mi, model) in models.into_iter().enumerate() {
            let chunks = observe(&wire, model, line.char_ns());
            let mut fc = FramerConfig::new(line, model.latency_ns(line.char_ns()));
            fc.learn_lengths = learn_lengths;
            match latency.as_str() {
                "unknown" => fc.latency_ns = 0,
                "fixed" => (fc.latency_ns, fc.learn_latency) = (0, false),
                _ => {}
            }
            let decided = run_framer(&wire, &chunks, fc);
            if std::env::var_os("DUMP_FALSE_VALID").is_some() {
                dump_false_valid(&wire, &decided, model);
            }
            let m = score(&wire, &decided);
            let g = score(&wire, &run_gap_cutter(&wire, &chunks, fc));
            let a = &mut per_model[mi];
            *a = (
                a.0 + m.good_recovered,
                a.1 + m.good_total,
                a.2 + m.false_valid,
                a.3 + m.corrupted_exact,
                a.4 + m.corrupted_total,
                a.5 + m.ambiguous,
                a.6 + m.ambiguous_wrong,
            );
            println!(
                "| {line} | {} | {:.3} % ({}/{}) | {} | {:.1} % ({}/{}) | {}/{} | {:.3} % | {} | {:.1} % |",
                model.name(),
                m.good_ratio() * 100.0,
                m.good_recovered,
                m.good_total,
                m.false_valid,
                m.corrupted_ratio() * 100.0,
                m.corrupted_exact,
                m.corrupted_total,
                m.glitch_reported,
                m.glitch_total,
                g.good_ratio() * 100.0,
                g.false_valid,
                g.corrupted_ratio() * 100.0,
            );
        }
    }
    println!();
    println!(
        "| observation (all line settings) | good | false valid | corrupted exact | two lengths shown (wrong one first) |"
    );
    println!("|---|---|---|---|---|");
    for (model, (good, total, false_valid, exact, corrupted, ambiguous, wrong)) in models.into_iter().zip(per_model) {
        #[allow(clippy::cast_precision_loss)]
        let (g, c) = (good as f64 * 100.0 / total.max(1) as f64, exact as f64 * 100.0 / corrupted.max(1) as f64);
        println!(
            "| {} | {g:.3} % ({good}/{total}) | {false_valid} | {c:.1} % ({exact}/{corrupted}) | {ambiguous} ({wrong}) |",
            model.name()
        );
    }
}

/// With `DUMP_FALSE_VALID` set: each frame reported valid that was never on the wire, with the
/// truth around it (what the wire really held there), for finding out why; with
/// `DUMP_WRONG_FIRST` too, the frames shown with two lengths the wrong one first, apart.
fn dump_false_valid(wire: &mbtap_sim::traffic::Wire, decided: &[mbtap_sim::traffic::Decided], model: Observation) {
    use mbtap_sim::traffic::TruthKind;
    let good: std::collections::HashSet<(usize, usize)> =
        wire.truth.iter().filter(|t| t.kind == TruthKind::Good).map(|t| (t.start, t.end)).collect();
    if std::env::var_os("DUMP_MISSED_VENDOR").is_some() {
        let valid: std::collections::HashSet<(usize, usize)> =
            decided.iter().filter(|d| d.frame && d.check_ok).map(|d| (d.range.start, d.range.end)).collect();
        for t in wire.truth.iter().filter(|t| t.kind == TruthKind::Good && wire.bytes.get(t.start + 1) == Some(&0x41)) {
            if !valid.contains(&(t.start, t.end)) {
                let shown: Vec<String> = decided
                    .iter()
                    .filter(|d| d.range.end > t.start && d.range.start < t.end + 2)
                    .map(|d| {
                        format!(
                            "{}..{} frame {} ok {} glitch {}",
                            d.range.start, d.range.end, d.frame, d.check_ok, d.glitch
                        )
                    })
                    .collect();
                println!(
                    "MISSED {model:?} {}..{} req {} [{}]\n    decided: {}",
                    t.start,
                    t.end,
                    t.is_request,
                    wire.hex(t.start..t.end + 3),
                    shown.join("; ")
                );
            }
        }
    }
    for d in decided.iter().filter(|d| d.frame && d.check_ok) {
        if std::env::var_os("DUMP_AMBIGUOUS").is_some() && d.alt_len.is_some() {
            println!("AMBIGUOUS {model:?} {}..{} alt {:?}", d.range.start, d.range.end, d.alt_len);
        }
        if good.contains(&(d.range.start, d.range.end)) {
            continue;
        }
        if std::env::var_os("DUMP_WRONG_FIRST").is_some()
            && d.alt_len.is_some_and(|n| good.contains(&(d.range.start, d.range.start + n)))
        {
            let around = wire.truth_around(&(d.range.start.saturating_sub(40)..d.range.end + 60), 0);
            println!(
                "WRONG FIRST {model:?} {}..{} [{}] alt {:?}\n    truth: {}",
                d.range.start,
                d.range.end,
                wire.hex(d.range.clone()),
                d.alt_len,
                around.join("\n           ")
            );
            continue;
        }
        let around = wire.truth_around(&d.range, 2);
        println!(
            "FALSE VALID {model:?} {}..{} [{}] alt {:?}\n    truth: {}",
            d.range.start,
            d.range.end,
            wire.hex(d.range.clone()),
            d.alt_len,
            around.join("\n           ")
        );
    }
}
