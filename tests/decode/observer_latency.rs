//! Self-calibrating timing trust: a capture that does not say how late its reads delivered
//! bytes (another tool's, or a port whose latency timer nobody knew) is read with what its own
//! valid frames show — they were sent back to back, so an apparent silence inside one is the
//! observer's delay. Given `--latency-ms`, the given figure is kept, and the summary says both.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_analysis::analyzer::{Event, Sink};
use mbtap_analysis::capture::PcapNgWriter;
use mbtap_analysis::chunk::{PortId, Timestamp};
use mbtap_analysis::framer::{LineSettings, ObserverEstimate, Parity};
use mbtap_analysis::line_args::LineOverrides;
use mbtap_analysis::replay::replay_into;
use mbtap_sim::traffic::{Observation, TrafficConfig, generate, observe};

const L9600: LineSettings = LineSettings { baud: 9600, data_bits: 8, parity: Parity::Even, stop_bits: 1 };

/// Traffic (`transactions` of it, from `seed`) read through `model`, written as a capture whose
/// interface says the line settings but no latency (`latency_ns=` absent, as a recorder that
/// did not know it writes).
fn capture_without_latency_of(seed: u64, transactions: usize, model: Observation) -> Vec<u8> {
    let wire = generate(&TrafficConfig { seed, line: L9600, transactions, ..TrafficConfig::default() });
    let chunks = observe(&wire, model, L9600.char_ns());
    let mut w = PcapNgWriter::new(Vec::new()).unwrap();
    let i = w.add_serial_interface("/dev/ttyUSB0", "mbtap rtu 9600 8E1").unwrap();
    for (t, r) in &chunks {
        w.write_packet(i, Timestamp(*t), &wire.bytes[r.clone()]).unwrap();
    }
    w.into_inner()
}

/// Through a USB adapter at its 16 ms latency timer.
fn capture_without_latency() -> Vec<u8> {
    capture_without_latency_of(77, 3000, Observation::USB_16MS)
}

#[derive(Default)]
struct Seen {
    frames: u64,
    gaps_inside: u64,
    observers: Vec<(PortId, ObserverEstimate)>,
}

impl Sink for Seen {
    fn event(&mut self, e: &Event<'_>) {
        if let Event::Frame { frame, .. } = e {
            self.frames += 1;
            self.gaps_inside += u64::from(frame.gap_violation_ns.is_some());
        }
    }

    fn observer(&mut self, port: PortId, estimate: &ObserverEstimate) {
        self.observers.push((port, *estimate));
    }
}

fn replay(file: &[u8], cli: LineOverrides) -> Seen {
    let mut seen = Seen::default();
    replay_into(file, cli, &mut seen).unwrap();
    seen
}

#[test]
fn a_capture_that_stores_no_latency_learns_it_from_its_valid_frames() {
    let file = capture_without_latency();
    let learned = replay(&file, LineOverrides::default());
    let [(port, e)] = learned.observers[..] else { panic!("{:?}", learned.observers) };
    assert_eq!(port, PortId(0));
    assert_eq!(e.configured_latency_ns, 0);
    assert!(e.learning);
    // The timer delivers up to 16 ms late; what frames show is a lower bound near it.
    let l = e.learned_latency_ns.expect("learned");
    assert!((8_000_000..=16_000_000).contains(&l), "{e:?}");
    assert_eq!(e.effective_latency_ns(), l);

    // Told 0 ms on the command line, the framer keeps 0 and takes the timer's delays for
    // silences: frames "with gaps inside" that were sent whole. (What this costs in frame
    // boundaries is measured in BENCHMARKS.md, `framer_accuracy … unknown` against `… fixed`.)
    let told = replay(&file, LineOverrides { latency_ns: Some(0), ..LineOverrides::default() });
    assert!(!told.observers[0].1.learning);
    assert_eq!(told.observers[0].1.effective_latency_ns(), 0);
    assert!(
        told.gaps_inside > 10 * learned.gaps_inside.max(1),
        "told {} learned {}",
        told.gaps_inside,
        learned.gaps_inside
    );
}

#[test]
fn per_byte_timestamps_learn_no_latency() {
    let seen = replay(&capture_without_latency_of(78, 1000, Observation::PerByte), LineOverrides::default());
    let e = seen.observers[0].1;
    assert_eq!(e.learned_latency_ns, Some(0), "{e:?}");
    assert_eq!(e.shape(), "1.0 bytes per read on average, at most 1");
}

/// What a recording session learned is stored at the end of its file (an interface statistics
/// block's comment, which Wireshark shows among the file's properties) and read back by replay,
/// which shows it beside what it learns itself.
#[test]
fn the_latency_a_recording_session_learned_is_stored_and_read_back() {
    let mut file = capture_without_latency();
    let mut w = PcapNgWriter::new(Vec::new()).unwrap();
    w.write_statistics_comment(0, Timestamp(1), "mbtap observer latency_ns=12345678 split_frames=900").unwrap();
    // The writer's own section header first: only the statistics block is appended.
    let block = w.into_inner();
    let shb_len = u32::from_le_bytes(block[4..8].try_into().unwrap()) as usize;
    file.extend_from_slice(&block[shb_len..]);
    let seen = replay(&file, LineOverrides::default());
    let e = seen.observers[0].1;
    assert_eq!(e.recorded_latency_ns, Some(12_345_678), "{e:?}");
    let mut stats = mbtap_analysis::report::events::Stats::default();
    stats.observe(0, &e);
    assert!(stats.text().contains("the session that recorded it learned 12.3 ms"), "{}", stats.text());
    assert_eq!(stats.json()["observers"][0]["recorded_latency_ns"], 12_345_678);
}
