//! A capture with one port per direction (a 4-wire tap, or `mbtap tap --record`): packets are
//! merged by time even when the file stores them out of order, and the interface roles tell
//! pairing which frames are requests — so echo-shaped frames (06) pair without guessing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_analysis::analyzer::{Event, Sink};
use mbtap_analysis::capture::PcapNgWriter;
use mbtap_analysis::chunk::Timestamp;
use mbtap_analysis::line_args::LineOverrides;
use mbtap_analysis::pairing::Outcome;
use mbtap_analysis::replay::replay_into;

/// MK4 §3.3 write of register 108 = 10; the response is the same 8 bytes.
const WRITE_108: &[u8] = &[0x01, 0x06, 0x00, 0x6C, 0x00, 0x0A, 0xC9, 0xD0];

#[derive(Default)]
struct Collect {
    frames: Vec<(u8, u64)>,
    outcomes: Vec<Outcome>,
}

impl Sink for Collect {
    fn event(&mut self, e: &Event<'_>) {
        match e {
            Event::Frame { frame, .. } => self.frames.push((frame.port.0, frame.t_end.0)),
            Event::Transaction(t) => self.outcomes.push(t.outcome),
            Event::Noise(_) | Event::Glitch(_) => {}
        }
    }
}

#[test]
fn two_ports_merge_by_time_and_know_direction() {
    let mut w = PcapNgWriter::new(Vec::new()).unwrap();
    w.add_serial_interface("master", "mbtap rtu 19200 8E1 latency_ns=0 role=requests").unwrap();
    w.add_serial_interface("slaves", "mbtap rtu 19200 8E1 latency_ns=0 role=responses").unwrap();
    let t0 = 1_700_000_000_000_000_000u64;
    // Stored out of order: the second response before the second request.
    w.write_packet(0, Timestamp(t0), WRITE_108).unwrap();
    w.write_packet(1, Timestamp(t0 + 10_000_000), WRITE_108).unwrap();
    w.write_packet(1, Timestamp(t0 + 110_000_000), WRITE_108).unwrap();
    w.write_packet(0, Timestamp(t0 + 100_000_000), WRITE_108).unwrap();
    let file = w.into_inner();
    let mut c = Collect::default();
    replay_into(&file[..], LineOverrides::default(), &mut c).unwrap();
    let ports: Vec<u8> = c.frames.iter().map(|f| f.0).collect();
    assert_eq!(ports, [0, 1, 0, 1], "merged by time");
    assert!(c.frames.windows(2).all(|w| w[0].1 <= w[1].1));
    assert_eq!(c.outcomes, [Outcome::Ok, Outcome::Ok]);
}
