//! The RTU framer against generated traffic with ground truth, per observation model
//! (per-byte timestamps, 16550 FIFO, USB latency timer 1 ms and 16 ms). Deterministic seeds:
//! these are regression tests of the framer's decisions, not statistics.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_analysis::framer::{FramerConfig, LineSettings, Parity};
use mbtap_sim::traffic::{Observation, TrafficConfig, generate, observe, run_framer, run_gap_cutter, score};

fn check(line: LineSettings, model: Observation, seed: u64, min_good: f64, min_corrupted: f64, max_false: usize) {
    let wire = generate(&TrafficConfig { seed, line, transactions: 3000, ..TrafficConfig::default() });
    let chunks = observe(&wire, model, line.char_ns());
    let s = score(&wire, &run_framer(&wire, &chunks, FramerConfig::new(line, model.latency_ns(line.char_ns()))));
    assert!(s.good_ratio() >= min_good, "{line} {}: good {s:?}", model.name());
    assert!(s.corrupted_ratio() >= min_corrupted, "{line} {}: corrupted {s:?}", model.name());
    assert!(s.false_valid <= max_false, "{line} {}: false valid {s:?}", model.name());
}

const L9600: LineSettings = LineSettings { baud: 9600, data_bits: 8, parity: Parity::Even, stop_bits: 1 };
const L19200: LineSettings = LineSettings { baud: 19_200, data_bits: 8, parity: Parity::Even, stop_bits: 1 };
const L115200: LineSettings = LineSettings { baud: 115_200, data_bits: 8, parity: Parity::None, stop_bits: 1 };

#[test]
fn per_byte_timestamps() {
    for (line, seed) in [(L9600, 1), (L19200, 2), (L115200, 3)] {
        check(line, Observation::PerByte, seed, 0.999, 0.95, 0);
    }
}

#[test]
fn fifo_16550() {
    for (line, seed) in [(L9600, 4), (L19200, 5), (L115200, 6)] {
        check(line, Observation::FIFO_16550, seed, 0.999, 0.93, 0);
    }
}

#[test]
fn usb_latency_1ms() {
    for (line, seed) in [(L9600, 7), (L19200, 8), (L115200, 9)] {
        check(line, Observation::USB_1MS, seed, 0.999, 0.95, 0);
    }
}

/// The hardest model: reads come every 16 ms, so timing says almost nothing.
#[test]
fn usb_latency_16ms() {
    for (line, seed) in [(L9600, 10), (L19200, 11), (L115200, 12)] {
        check(line, Observation::USB_16MS, seed, 0.999, 0.88, 0);
    }
}

/// The reason for all this: on the same bytes, cutting on silence alone loses most frames
/// once an adapter batches its reads.
#[test]
fn gap_cutting_alone_fails_on_usb_batching() {
    let wire = generate(&TrafficConfig { seed: 13, line: L19200, transactions: 1000, ..TrafficConfig::default() });
    let model = Observation::USB_16MS;
    let chunks = observe(&wire, model, L19200.char_ns());
    let cfg = FramerConfig::new(L19200, model.latency_ns(L19200.char_ns()));
    let ours = score(&wire, &run_framer(&wire, &chunks, cfg));
    let gap = score(&wire, &run_gap_cutter(&wire, &chunks, cfg));
    assert!(gap.good_ratio() < 0.5, "{gap:?}");
    assert!(ours.good_ratio() > 0.999, "{ours:?}");
}

/// Every byte ends up in exactly one event, in order: nothing is lost or duplicated.
#[test]
fn events_cover_every_byte_once() {
    for model in [Observation::PerByte, Observation::FIFO_16550, Observation::USB_16MS] {
        let wire = generate(&TrafficConfig {
            seed: 14,
            line: L9600,
            transactions: 500,
            noise: 0.2,
            ..TrafficConfig::default()
        });
        let chunks = observe(&wire, model, L9600.char_ns());
        let decided = run_framer(&wire, &chunks, FramerConfig::new(L9600, model.latency_ns(L9600.char_ns())));
        let mut at = 0;
        for d in &decided {
            assert_eq!(d.range.start, at);
            at = d.range.end;
        }
        assert_eq!(at, wire.bytes.len());
    }
}

/// Vendor-function frames whose CRC ends in `00`, on a line with `00` turnaround
/// glitches: each unit sends its vendor function with the same lengths all day, and the frames
/// that are unambiguous about their length decide the twins — far fewer shown with two lengths,
/// and far fewer with the wrong one first, than a framer that does not learn them.
#[test]
fn vendor_lengths_learned_per_unit_decide_crc_00_twins() {
    let cfg = TrafficConfig {
        seed: 2525,
        line: L19200,
        transactions: 20_000,
        glitch: 0.3,
        vendor_fixed: true,
        vendor_lookalike: 0.25,
        ..TrafficConfig::default()
    };
    let wire = generate(&cfg);
    let chunks = observe(&wire, Observation::PerByte, L19200.char_ns());
    let mut fc = FramerConfig::new(L19200, 0);
    let learned = score(&wire, &run_framer(&wire, &chunks, fc));
    fc.learn_lengths = false;
    let blind = score(&wire, &run_framer(&wire, &chunks, fc));
    assert!(learned.ambiguous_wrong * 10 < blind.ambiguous_wrong, "learned {learned:?}\nblind {blind:?}");
    assert!(learned.ambiguous * 10 < blind.ambiguous, "learned {learned:?}\nblind {blind:?}");
    assert!(learned.good_ratio() > blind.good_ratio(), "learned {learned:?}\nblind {blind:?}");
    assert!(learned.false_valid <= blind.false_valid, "learned {learned:?}\nblind {blind:?}");
}

/// The wire of `transactions` vendor-heavy transactions (5 % vendor functions, fixed lengths
/// per unit, a quarter of their CRCs ending in `00`) through `model`, the framer told nothing
/// of the latency: its score.
fn vendor_line(line: LineSettings, seed: u64, glitch: f64, model: Observation) -> mbtap_sim::traffic::Score {
    vendor_line_with(line, seed, glitch, model, FramerConfig::new(line, 0))
}

fn vendor_line_with(
    line: LineSettings,
    seed: u64,
    glitch: f64,
    model: Observation,
    framer: FramerConfig,
) -> mbtap_sim::traffic::Score {
    let cfg = TrafficConfig {
        seed,
        line,
        transactions: 30_000,
        glitch,
        vendor_fixed: true,
        vendor_lookalike: 0.25,
        ..TrafficConfig::default()
    };
    let wire = generate(&cfg);
    let chunks = observe(&wire, model, line.char_ns());
    score(&wire, &run_framer(&wire, &chunks, framer))
}

/// No false valid frames through a 16 ms USB timer on this line: a vendor answer whose CRC ends in
/// `00`, glued to noise (no silence the timer lets through), takes its learned length, not one byte
/// short; and a corrupted vendor request glued to the next frame never checks as one long "frame"
/// of a length its function never has.
#[test]
fn vendor_twins_glued_to_noise_take_their_learned_length() {
    let s = vendor_line(L9600, 42, 0.0, Observation::USB_16MS);
    assert_eq!(s.false_valid, 0, "{s:?}");
    assert!(s.good_ratio() > 0.999, "{s:?}");
}

/// A vendor request whose CRC ends in `00`, followed by the master's `00` glitch,
/// makes three readings that check (7, 8 and 9 bytes): the frame is the second — a sender
/// leaves one glitch byte — where the first used to be taken through a FIFO.
#[test]
fn a_frame_ending_in_00_and_its_00_glitch_is_the_longer_reading() {
    let s = vendor_line(L19200, 43, 1.0, Observation::FIFO_16550);
    assert_eq!(s.false_valid, 0, "{s:?}");
}

/// Behind a 16 ms USB timer at 19200, on a bus that glitches after every frame and keeps only 1.05
/// × t3.5 between frames, no glitch byte alone between a frame's end and the next frame's start is
/// a noise burst (a `noise` finding on a healthy bus): the silence the reads seem to show before it
/// is judged with the timer's latency, a slave's first `FE` counts before its own glitch values are
/// known, and a `00` after a request nobody answers is followed by a silence, not a frame.
#[test]
fn glitches_between_frames_are_glitches_behind_a_usb_timer() {
    let t35 = L19200.t35_ns();
    let cfg = TrafficConfig {
        seed: 701,
        line: L19200,
        transactions: 3000,
        noise: 0.0,
        corrupt: 0.0,
        slow: 0.0,
        glitch: 1.0,
        min_idle_ns: Some(t35 + t35 / 20),
        ..TrafficConfig::default()
    };
    let wire = generate(&cfg);
    let chunks = observe(&wire, Observation::USB_16MS, L19200.char_ns());
    let s = score(&wire, &run_framer(&wire, &chunks, FramerConfig::new(L19200, 0)));
    assert!(s.glitch_total > 5000, "{s:?}");
    assert_eq!(s.glitch_reported, s.glitch_total, "{s:?}");
}

/// 1 215 bytes into a glitchy line behind a 16 ms USB timer, before the observer's latency is
/// learned, a read boundary falls right before a vendor answer's last byte, a CRC `00`: the answer
/// is taken whole, not one byte short without doubt, because its `00` is followed by the slave's
/// own `FF` glitch (a sender leaves one glitch byte). Where reads batch bytes, that silence is a
/// lower bound and the glitch after the longer frame outweighs it.
#[test]
fn a_vendor_answer_ending_in_00_and_its_ff_before_the_latency_is_learned() {
    let s = vendor_line(L19200, 43, 1.0, Observation::USB_16MS);
    assert_eq!(s.false_valid, 0, "{s:?}");
}

/// On a line of vendor functions with a quarter of their CRCs ending in `00` and 30 % turnaround
/// glitches, no frame is shown with two lengths, the wrong one first, in any observer model:
/// requests to a unit that never answers are learned from (a silence follows them, never a byte), a
/// unit's twins are read by its learned length once one frame of it is certain, and a unit's very
/// first vendor frames wait for that.
#[test]
fn vendor_twins_are_read_by_what_their_unit_was_heard_sending() {
    for model in [Observation::PerByte, Observation::FIFO_16550, Observation::USB_1MS, Observation::USB_16MS] {
        let s = vendor_line(L9600, 42, 0.3, model);
        assert_eq!(s.false_valid, 0, "{model:?} {s:?}");
        // Two commits back: 3 wrong first of 20 shown with two lengths in each model; then 1
        // of 8; now none.
        assert_eq!(s.ambiguous_wrong, 0, "{model:?} {s:?}");
        assert!(s.ambiguous <= 10, "{model:?} {s:?}");
    }
}

/// A unit's first vendor request whose CRC ends in `00` (here unit 1's, 7 bytes, at
/// byte 1 957 of the line) reads as well one byte shorter with the master's `00` glitch after
/// it, and the line's odds (30 % glitches) put the short reading first. What the line does next
/// tells: the unit's next requests of that function have 7 bytes. The framer now holds such a
/// twin, and what follows it, until then; without the hold the wrong length comes first.
#[test]
fn a_units_first_vendor_twin_waits_for_what_the_line_does_next() {
    let held = vendor_line(L9600, 42, 0.3, Observation::USB_16MS);
    let unheld = vendor_line_with(
        L9600,
        42,
        0.3,
        Observation::USB_16MS,
        FramerConfig { hold_twins_ns: 0, ..FramerConfig::new(L9600, 0) },
    );
    assert_eq!(unheld.ambiguous_wrong, 1, "{unheld:?}");
    assert_eq!(held.ambiguous_wrong, 0, "{held:?}");
    assert_eq!(held.good_recovered, unheld.good_recovered + 1, "held {held:?}\nunheld {unheld:?}");
    assert_eq!(held.ambiguous, unheld.ambiguous);
}
