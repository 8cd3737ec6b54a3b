//! The terminal UI's views rendered on ratatui's `TestBackend` and kept as insta snapshots:
//! traffic (following, filtered), detail, devices, registers, the help overlay — at 80×24 (the
//! smallest terminal we support) and 120×30. The model is fed by the virtual bus through the
//! real analyzer, at fixed times, so the screens are the same on every machine.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::sync::Arc;

use mbtap::tui::{App, Model};
use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings};
use mbtap_sim::Slave;
use mbtap_sim::bus::{Fault, VirtualBus};
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

/// 10:00:00 UTC on the first day of the epoch: times on screen read 10:00:…
const START_NS: u64 = 10 * 3600 * 1_000_000_000;

/// The demo's three devices after `transactions` polls, with `faults` injected.
fn model(transactions: usize, faults: &[Fault]) -> Model {
    let profiles = mbtap_sim::demo_profiles().unwrap();
    let slaves = profiles.iter().map(|(&a, p)| Slave::new(Arc::new(p.clone()), a)).collect();
    let line = LineSettings::default();
    let mut bus = VirtualBus::new(slaves, line);
    bus.faults = faults.to_vec();
    let mut model = Model::new(profiles, mbtap_device::profile::annotate::Lang::En, line, 1000);
    let mut analyzer =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(line, 0), ..AnalyzerConfig::default() });
    for _ in 0..transactions {
        for frame in bus.next_transaction() {
            let t = Timestamp(START_NS + frame.end_ns);
            analyzer.push(&Chunk { port: PortId(0), t, bytes: &frame.bytes }, &mut |e: &Event<'_>| model.event(e));
            analyzer.tick(Timestamp(t.0 + 2_000_000), &mut |e: &Event<'_>| model.event(e));
        }
    }
    analyzer.finish(&mut |e: &Event<'_>| model.event(e));
    model
}

fn key(app: &mut App, model: &Model, code: KeyCode) {
    app.refresh(model);
    app.key(KeyEvent::new(code, KeyModifiers::NONE), model);
}

fn screen(app: &mut App, model: &Model, width: u16, height: u16) -> String {
    let mut terminal = Terminal::new(TestBackend::new(width, height)).unwrap();
    terminal.draw(|f| mbtap::tui::render::draw(f, app, model, "demo")).unwrap();
    terminal.backend().to_string()
}

#[test]
fn traffic_follows_the_newest_transaction() {
    let m = model(30, &[]);
    let mut app = App::new(true);
    insta::assert_snapshot!("traffic_80x24", screen(&mut app, &m, 80, 24));
    insta::assert_snapshot!("traffic_120x30", screen(&mut app, &m, 120, 30));
}

#[test]
fn traffic_filtered_to_errors_shows_every_fault_as_what_it_is() {
    let m = model(60, &[Fault::Corrupt, Fault::Noise, Fault::SilentSlave, Fault::SlowSlave, Fault::FastMaster]);
    let mut app = App::new(true);
    key(&mut app, &m, KeyCode::Char('e'));
    let s = screen(&mut app, &m, 120, 30);
    for status in ["bad check", "noise", "timeout", "gap", "<t3.5"] {
        assert!(s.contains(status), "{status} missing:\n{s}");
    }
    assert!(s.contains("filter: errors only"));
    insta::assert_snapshot!("traffic_errors_only", s);
}

#[test]
fn a_unit_filter_and_a_search() {
    let m = model(30, &[]);
    let mut app = App::new(true);
    // First unit on the bus: 1 (mk4).
    key(&mut app, &m, KeyCode::Char('u'));
    let s = screen(&mut app, &m, 100, 24);
    assert!(s.contains("filter: unit 1"));
    assert!(s.contains("mk4") && !s.contains("mkzp") && !s.contains("display"), "{s}");
    key(&mut app, &m, KeyCode::Char('c'));
    key(&mut app, &m, KeyCode::Char('/'));
    for c in "current".chars() {
        key(&mut app, &m, KeyCode::Char(c));
    }
    assert!(screen(&mut app, &m, 100, 24).contains("search: current"));
    key(&mut app, &m, KeyCode::Enter);
    let s = screen(&mut app, &m, 100, 24);
    assert!(s.contains("filter: \"current\""), "{s}");
    // MKZP phase currents and MK4 motor currents match; the Display's fuel rows do not.
    assert!(s.contains("mkzp") && !s.contains("display"), "{s}");
}

#[test]
fn detail_of_a_transaction_with_the_selected_field_highlighted() {
    let m = model(30, &[]);
    let mut app = App::new(true);
    // Up from the newest row to an MK4 voltage read, then open it.
    let voltages = (0..m.rows.len()).rev().find(|&i| m.rows[i].summary.contains("Phase A (L1) voltage")).unwrap();
    for _ in voltages..m.rows.len() - 1 {
        key(&mut app, &m, KeyCode::Up);
    }
    key(&mut app, &m, KeyCode::Enter);
    key(&mut app, &m, KeyCode::Down);
    key(&mut app, &m, KeyCode::Down);
    key(&mut app, &m, KeyCode::Down);
    let s = screen(&mut app, &m, 100, 30);
    assert!(s.contains("Phase A (L1) voltage"), "{s}");
    insta::assert_snapshot!("detail_mk4_voltages", s);
    // The highlight is on register 0's two bytes of the response (bytes 3 and 4).
    let mut terminal = Terminal::new(TestBackend::new(100, 30)).unwrap();
    terminal.draw(|f| mbtap::tui::render::draw(f, &mut app, &m, "demo")).unwrap();
    let buffer = terminal.backend().buffer();
    let highlighted: String = (0..30)
        .flat_map(|y| (0..100).map(move |x| (x, y)))
        .filter(|&(x, y)| buffer[(x, y)].bg == ratatui::style::Color::Yellow)
        .map(|(x, y)| buffer[(x, y)].symbol().to_owned())
        .collect();
    assert_eq!(highlighted.split_whitespace().count(), 2, "two bytes highlighted: {highlighted:?}");
    // r shows the request instead.
    key(&mut app, &m, KeyCode::Char('r'));
    assert!(screen(&mut app, &m, 100, 30).contains("request fields"));
}

#[test]
fn devices_view() {
    let m = model(60, &[Fault::SilentSlave]);
    let mut app = App::new(true);
    key(&mut app, &m, KeyCode::Char('2'));
    insta::assert_snapshot!("devices_80x24", screen(&mut app, &m, 80, 24));
    let s = screen(&mut app, &m, 120, 30);
    for name in ["mk4", "display", "mkzp"] {
        assert!(s.contains(name), "{name}");
    }
    // The silent slave shows up as a live finding, as `mbtap report` would name it.
    assert!(s.contains("findings (") && s.contains("no_response"), "{s}");
    let healthy = model(30, &[]);
    let mut app = App::new(true);
    key(&mut app, &healthy, KeyCode::Char('2'));
    assert!(screen(&mut app, &healthy, 120, 30).contains("none — the bus looks healthy"));
}

#[test]
fn registers_view_and_other_units() {
    let m = model(30, &[]);
    let mut app = App::new(true);
    key(&mut app, &m, KeyCode::Char('3'));
    let first = screen(&mut app, &m, 100, 30);
    insta::assert_snapshot!("registers_100x30", first);
    key(&mut app, &m, KeyCode::Right);
    let second = screen(&mut app, &m, 100, 30);
    assert_ne!(first, second, "→ shows another unit");
}

#[test]
fn help_overlay_lists_every_key() {
    let m = model(5, &[]);
    let mut app = App::new(true);
    key(&mut app, &m, KeyCode::Char('?'));
    let s = screen(&mut app, &m, 80, 24);
    insta::assert_snapshot!("help_80x24", s);
    for (k, _) in mbtap::tui::render::KEYS {
        assert!(s.contains(k), "{k} missing from the help");
    }
    key(&mut app, &m, KeyCode::Char('x'));
    assert!(!screen(&mut app, &m, 80, 24).contains("any key closes"), "any key closes the help");
}

#[test]
fn scroll_back_is_bounded_and_says_so() {
    let profiles = mbtap_sim::demo_profiles().unwrap();
    let line = LineSettings::default();
    let mut small = Model::new(profiles, mbtap_device::profile::annotate::Lang::En, line, 10);
    let slaves = mbtap_sim::demo_profiles().unwrap().iter().map(|(&a, p)| Slave::new(Arc::new(p.clone()), a)).collect();
    let mut bus = VirtualBus::new(slaves, line);
    let mut analyzer =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(line, 0), ..AnalyzerConfig::default() });
    for _ in 0..40 {
        for frame in bus.next_transaction() {
            let t = Timestamp(START_NS + frame.end_ns);
            analyzer.push(&Chunk { port: PortId(0), t, bytes: &frame.bytes }, &mut |e: &Event<'_>| small.event(e));
            analyzer.tick(Timestamp(t.0 + 2_000_000), &mut |e: &Event<'_>| small.event(e));
        }
    }
    assert_eq!(small.rows.len(), 10);
    assert_eq!(small.total_rows(), 40);
    assert_eq!(small.dropped, 30);
    let mut app = App::new(false);
    assert!(screen(&mut app, &small, 100, 24).contains("30 oldest dropped (scroll-back 10)"));
    // Statistics cover everything seen, not only what is kept.
    assert_eq!(small.devices.values().map(|d| d.requests).sum::<u64>(), 40);
}

/// A replay shown in the UI gives the devices view the line settings the capture was recorded with,
/// not the command line's defaults.
#[test]
fn a_replay_shows_the_line_settings_the_capture_was_recorded_with() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/mk4-doc-examples-ascii.pcapng");
    let model = mbtap::tui::model::Model::new(
        mbtap_analysis::decode::Profiles::new(),
        mbtap_device::profile::annotate::Lang::En,
        LineSettings::default(),
        1000,
    );
    let shared = mbtap::tui::terminal::Shared::new(model);
    let mut writer = mbtap::output::EventWriter::new(std::io::sink(), mbtap::output::EventFormat::Text);
    writer.tui = Some(shared.clone());
    let input = std::fs::File::open(capture).unwrap();
    mbtap::output::replay(
        input,
        mbtap_analysis::line_args::LineOverrides::default(),
        &mut writer,
        &mut std::io::sink(),
    )
    .unwrap();
    assert_eq!(shared.model().line, "19200 7E1".parse::<LineSettings>().unwrap());
    assert!(shared.model().total_rows() > 0);
}

/// A frame that checks at another length too (a vendor request ending in `00` on a line whose
/// master leaves a `00` glitch after some frames) marks its row `len?`.
#[test]
fn a_frame_with_two_possible_lengths_is_marked_in_the_traffic_view() {
    let line = LineSettings { baud: 9600, ..LineSettings::default() };
    let c = line.char_ns();
    let mut model =
        Model::new(std::collections::BTreeMap::new(), mbtap_device::profile::annotate::Lang::En, line, 1000);
    let mut analyzer =
        Analyzer::new(AnalyzerConfig { framer: FramerConfig::new(line, 0), ..AnalyzerConfig::default() });
    let rtu = |pdu: &[u8]| {
        let mut f = Vec::new();
        mbtap_proto::encode_rtu(1, pdu, &mut f);
        f
    };
    // A vendor request (user-defined 0x41) whose last byte makes its CRC end in 00.
    let request = (0..=255u8).map(|v| rtu(&[0x41, 0x10, 0x20, v])).find(|f| f.last() == Some(&0)).unwrap();
    let mut t = START_NS;
    let mut send = |gap: u64, bytes: &[u8], model: &mut Model| {
        t += gap * c;
        for &b in bytes {
            t += c;
            analyzer.push(&Chunk { port: PortId(0), t: Timestamp(t), bytes: &[b] }, &mut |e: &Event<'_>| {
                model.event(e);
            });
        }
    };
    for i in 0..60 {
        send(10, &rtu(&[0x03, 0x00, 0x10, 0x00, 0x01]), &mut model);
        if i % 3 == 0 {
            send(0, &[0x00], &mut model);
        }
        send(5, &rtu(&[0x03, 0x02, 0x12, 0x34]), &mut model);
    }
    send(10, &request, &mut model);
    send(5, &rtu(&[0x41, 0x55]), &mut model);
    send(40, &rtu(&[0x03, 0x00, 0x10, 0x00, 0x01]), &mut model);
    analyzer.finish(&mut |e: &Event<'_>| model.event(e));
    let mut app = App::new(true);
    app.refresh(&model);
    let s = screen(&mut app, &model, 120, 30);
    assert_eq!(s.matches("len?").count(), 1, "{s}");
}
