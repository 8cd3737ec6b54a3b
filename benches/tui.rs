//! The terminal UI under load: the time to render one frame of each view with 100 000
//! transactions loaded, the cost of taking in one transaction, and of re-filtering the whole
//! scroll-back, plus the memory the loaded model holds (printed once before the benchmarks).
//! Run: `cargo bench --bench tui`. Figures go to BENCHMARKS.md with the machine.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // benchmarks may fail loudly

use std::sync::{Arc, OnceLock};

use divan::counter::ItemsCount;
use divan::{Bencher, black_box};
use mbtap::tui::{App, Model};
use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings};
use mbtap_sim::Slave;
use mbtap_sim::bus::{Fault, VirtualBus};
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

const TRANSACTIONS: usize = 100_000;

fn main() {
    let before = rss_kib();
    let model = loaded();
    let after = rss_kib();
    println!(
        "model with {} rows ({} transactions seen): resident memory +{:.1} MiB ({} KiB before, {} KiB after)",
        model.rows.len(),
        model.total_rows(),
        f64::from(u32::try_from(after.saturating_sub(before)).unwrap_or(u32::MAX)) / 1024.0,
        before,
        after
    );
    divan::main();
}

/// Resident set size of this process (Linux /proc), KiB.
fn rss_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

/// The demo bus with every fault, through the real analyzer, `n` transactions.
fn feed(n: usize, mut sink: impl FnMut(&Event<'_>)) {
    let profiles = mbtap_sim::demo_profiles().unwrap();
    let slaves = profiles.iter().map(|(&a, p)| Slave::new(Arc::new(p.clone()), a)).collect();
    let line = LineSettings::default();
    let mut bus = VirtualBus::new(slaves, line);
    bus.faults = Fault::ALL.to_vec();
    bus.fault_every = 20;
    let mut analyzer =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(line, 0), ..AnalyzerConfig::default() });
    for _ in 0..n {
        for frame in bus.next_transaction() {
            let t = Timestamp(frame.end_ns);
            analyzer.push(&Chunk { port: PortId(0), t, bytes: &frame.bytes }, &mut sink);
            analyzer.tick(Timestamp(t.0 + 2_000_000), &mut sink);
        }
    }
    analyzer.finish(&mut sink);
}

fn new_model(capacity: usize) -> Model {
    let profiles = mbtap_sim::demo_profiles().unwrap();
    Model::new(profiles, mbtap_device::profile::annotate::Lang::En, LineSettings::default(), capacity)
}

fn loaded() -> &'static Model {
    static MODEL: OnceLock<Model> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mut m = new_model(TRANSACTIONS);
        feed(TRANSACTIONS, |e| m.event(e));
        m
    })
}

fn render(bencher: Bencher, keys: &[KeyCode], width: u16, height: u16) {
    let model = loaded();
    let mut app = App::new(true);
    for &k in keys {
        app.refresh(model);
        app.key(KeyEvent::new(k, KeyModifiers::NONE), model);
    }
    let mut terminal = Terminal::new(TestBackend::new(width, height)).unwrap();
    // The first draw brings the filter up to date over the whole scroll-back; measure the
    // steady state a running UI is in.
    terminal.draw(|f| mbtap::tui::render::draw(f, &mut app, model, "bench")).unwrap();
    bencher.bench_local(|| {
        terminal.draw(|f| mbtap::tui::render::draw(f, &mut app, model, "bench")).unwrap();
    });
}

#[divan::bench]
fn render_traffic_120x40(bencher: Bencher) {
    render(bencher, &[], 120, 40);
}

#[divan::bench]
fn render_traffic_80x24(bencher: Bencher) {
    render(bencher, &[], 80, 24);
}

#[divan::bench]
fn render_detail_120x40(bencher: Bencher) {
    render(bencher, &[KeyCode::Up, KeyCode::Enter], 120, 40);
}

#[divan::bench]
fn render_devices_120x40(bencher: Bencher) {
    render(bencher, &[KeyCode::Char('2')], 120, 40);
}

#[divan::bench]
fn render_registers_120x40(bencher: Bencher) {
    render(bencher, &[KeyCode::Char('3')], 120, 40);
}

/// A new filter (errors only) applied to all 100 000 rows, then drawn.
#[divan::bench]
fn refilter_100k_rows_errors_only(bencher: Bencher) {
    let model = loaded();
    let mut terminal = Terminal::new(TestBackend::new(120, 40)).unwrap();
    bencher.bench_local(|| {
        let mut app = App::new(true);
        app.filter.errors_only = true;
        terminal.draw(|f| mbtap::tui::render::draw(f, &mut app, model, "bench")).unwrap();
        black_box(app.visible().len())
    });
}

/// Analyzer events of 1 000 transactions into the model (annotation, statistics, registers).
#[divan::bench]
fn ingest_1000_transactions(bencher: Bencher) {
    let mut events = Vec::new();
    feed(1000, |e| {
        if let Event::Transaction(t) = e {
            events.push((
                t.outcome,
                t.unit,
                t.function,
                t.request.map(<[u8]>::to_vec),
                t.response.map(<[u8]>::to_vec),
                t.t_start,
                t.latency_ns,
                t.request_pdu.map(<[u8]>::to_vec),
                t.response_pdu.map(<[u8]>::to_vec),
            ));
        }
    });
    bencher.counter(ItemsCount::new(events.len())).bench_local(|| {
        let mut m = new_model(TRANSACTIONS);
        for (outcome, unit, function, req, resp, t_start, latency_ns, req_pdu, resp_pdu) in &events {
            let t = mbtap_analysis::pairing::Transaction {
                outcome: *outcome,
                unit: *unit,
                function: *function,
                request: req.as_deref(),
                response: resp.as_deref(),
                request_pdu: req_pdu.as_deref(),
                response_pdu: resp_pdu.as_deref(),
                t_start: *t_start,
                latency_ns: *latency_ns,
                latency_resolution_ns: 0,
                input_ended: false,
            };
            m.event(&Event::Transaction(&t));
        }
        black_box(m.total_rows())
    });
}
