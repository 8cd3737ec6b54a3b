//! Cost of the bus health report: taking in a transaction (what `sniff --report` adds to a
//! live session) and building the report at the end (`mbtap report`, the UI's devices view).
//! Run: `cargo bench --bench health`. Figures go to BENCHMARKS.md with the machine.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // benchmarks may fail loudly

use std::sync::Arc;

use divan::counter::ItemsCount;
use divan::{Bencher, black_box};
use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::health::Health;
use mbtap_sim::Slave;
use mbtap_sim::bus::{Fault, VirtualBus};

fn main() {
    divan::main();
}

/// The analyzer's events for `n` transactions of the demo bus with every fault taking turns,
/// as owned values the benchmark can replay.
fn events(n: usize) -> Vec<(u64, Vec<u8>)> {
    let profiles = mbtap_sim::demo_profiles().unwrap();
    let slaves = profiles.iter().map(|(&a, p)| Slave::new(Arc::new(p.clone()), a)).collect();
    let mut bus = VirtualBus::new(slaves, mbtap_analysis::framer::LineSettings::default());
    bus.faults = Fault::ALL.to_vec();
    (0..n).flat_map(|_| bus.next_transaction()).map(|f| (f.end_ns, f.bytes)).collect()
}

/// Frames through the analyzer into the health collector (the analyzer's share is in the
/// `throughput` benchmarks; subtract it to see the report's).
#[divan::bench(args = [false, true])]
fn analyze_with_health(bencher: Bencher, with_health: bool) {
    const N: usize = 10_000;
    let frames = events(N);
    let profiles = mbtap_sim::demo_profiles().unwrap();
    bencher.counter(ItemsCount::new(N)).bench_local(|| {
        let mut analyzer = Analyzer::new(AnalyzerConfig::default());
        let mut health = Health::new(profiles.clone());
        let mut sink = |e: &Event<'_>| {
            if with_health {
                health.event(e);
            }
        };
        for (t, bytes) in &frames {
            analyzer.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes }, &mut sink);
        }
        analyzer.finish(&mut sink);
        black_box(health.report().findings.len())
    });
}

/// Building the report of a long capture: 100 000 transactions (about 3 h of this bus).
#[divan::bench(sample_count = 10)]
fn report_of_100k_transactions(bencher: Bencher) {
    let frames = events(100_000);
    let mut analyzer = Analyzer::new(AnalyzerConfig::default());
    let mut health = Health::new(mbtap_sim::demo_profiles().unwrap());
    for (t, bytes) in &frames {
        analyzer.push(&Chunk { port: PortId(0), t: Timestamp(*t), bytes }, &mut |e: &Event<'_>| health.event(e));
    }
    analyzer.finish(&mut |e: &Event<'_>| health.event(e));
    bencher.bench_local(|| black_box(health.report().findings.len()));
}
