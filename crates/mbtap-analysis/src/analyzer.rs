//! The analyzer: chunks in, frames, noise and transactions out — the one code path shared by
//! live capture, replay and tests. Pure: time comes in with the chunks.

use crate::chunk::{Chunk, PortId, Timestamp};
use crate::framer::{AsciiFramer, Frame, FrameEvent, FramerConfig, Noise, RtuFramer};
use crate::pairing::{Pairing, PairingConfig, Role, Transaction};

pub use mbtap_proto::serial_line::SerialMode;

/// Analyzer settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnalyzerConfig {
    pub mode: SerialMode,
    pub framer: FramerConfig,
    pub pairing: PairingConfig,
}

impl Default for AnalyzerConfig {
    fn default() -> Self {
        Self { mode: SerialMode::Rtu, framer: FramerConfig::default(), pairing: PairingConfig::default() }
    }
}

/// What the analyzer reports.
#[derive(Debug, Clone, Copy)]
pub enum Event<'a> {
    /// A frame (good or failed check) and the role pairing gave it.
    Frame {
        frame: &'a Frame<'a>,
        role: Role,
        unit: Option<u8>,
        pdu: Option<&'a [u8]>,
    },
    Noise(&'a Noise<'a>),
    /// A turnaround glitch byte after a frame ([`FrameEvent::Glitch`]).
    Glitch(&'a Noise<'a>),
    Transaction(&'a Transaction<'a>),
}

/// A vendor function's frame length a profile declares: unit, code, request (else answer), bytes.
pub type DeclaredLength = (u8, u8, bool, u16);

/// The declared lengths of `profiles` (unit → profile).
#[must_use]
pub fn declared_lengths<'a>(
    profiles: impl IntoIterator<Item = (&'a u8, &'a mbtap_device::profile::Profile)>,
) -> Vec<DeclaredLength> {
    let mut out = Vec::new();
    for (&unit, p) in profiles {
        for &(code, request, response) in &p.vendor_lengths {
            out.extend(request.map(|n| (unit, code, true, n)));
            out.extend(response.map(|n| (unit, code, false, n)));
        }
    }
    out
}

/// Receives analyzer events.
pub trait Sink {
    fn event(&mut self, event: &Event<'_>);

    /// Something was wrong with the input (a corrupt capture block, say); the analysis goes on.
    fn warning(&mut self, message: &str) {
        let _ = message;
    }

    /// The line settings the analysis runs with, once known (a capture says them in its
    /// header, after the sink was made).
    fn settings(&mut self, line: crate::framer::LineSettings) {
        let _ = line;
    }

    /// Frame lengths the sink's device profiles declare for vendor functions:
    /// `(unit, code, request, length)`, given to every framer (see
    /// [`mbtap_device::profile::Profile::vendor_lengths`]).
    fn declared_lengths(&self) -> Vec<DeclaredLength> {
        Vec::new()
    }

    /// At the end: what a port's framer learned about its observer's reads.
    fn observer(&mut self, port: PortId, estimate: &crate::framer::ObserverEstimate) {
        let _ = (port, estimate);
    }
}

impl<F: FnMut(&Event<'_>)> Sink for F {
    fn event(&mut self, event: &Event<'_>) {
        self(event);
    }
}

#[derive(Debug)]
// One per port, a handful per analyzer: boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
enum PortFramer {
    Rtu(RtuFramer),
    Ascii(AsciiFramer),
}

/// Framers per port and one pairing over the bus.
#[derive(Debug)]
pub struct Analyzer {
    config: AnalyzerConfig,
    /// Lengths device profiles declare, given to each RTU framer as it is made.
    declared: Vec<DeclaredLength>,
    ports: Vec<(PortId, PortFramer)>,
    pairing: Pairing,
    /// Decoded ASCII frame bytes (address, PDU, LRC), reused.
    scratch: Vec<u8>,
}

impl Analyzer {
    #[must_use]
    pub fn new(config: AnalyzerConfig) -> Self {
        Self {
            config,
            declared: Vec::new(),
            ports: Vec::new(),
            pairing: Pairing::new(config.pairing),
            scratch: Vec::new(),
        }
    }

    #[must_use]
    pub const fn config(&self) -> &AnalyzerConfig {
        &self.config
    }

    #[inline]
    fn port_index(&mut self, port: PortId) -> usize {
        match self.ports.iter().position(|(p, _)| *p == port) {
            Some(i) => i,
            None => self.add_port(port),
        }
    }

    /// A port heard for the first time gets its framer. Apart from [`Self::port_index`], which
    /// every chunk asks: a framer is built on the stack (kilobytes of tables), and the frame
    /// that takes cost every call its set-up while it was inline (33 instructions a chunk).
    #[cold]
    #[inline(never)]
    fn add_port(&mut self, port: PortId) -> usize {
        let framer = match self.config.mode {
            SerialMode::Rtu => {
                let mut f = RtuFramer::new(port, self.config.framer);
                for &(unit, fc, request, len) in &self.declared {
                    f.declare_length(unit, fc, request, len);
                }
                PortFramer::Rtu(f)
            }
            SerialMode::Ascii => PortFramer::Ascii(AsciiFramer::new(port, self.config.framer.line)),
        };
        self.ports.push((port, framer));
        self.ports.len() - 1
    }

    /// Feeds one chunk.
    #[inline]
    pub fn push<S: Sink>(&mut self, chunk: &Chunk<'_>, sink: &mut S) {
        let i = self.port_index(chunk.port);
        let (pairing, scratch) = (&mut self.pairing, &mut self.scratch);
        let mut emit = |e: FrameEvent<'_>| route(pairing, scratch, e, sink);
        match &mut self.ports[i].1 {
            PortFramer::Rtu(f) => f.push(chunk, &mut emit),
            PortFramer::Ascii(f) => f.push(chunk, &mut emit),
        }
    }

    /// Feeds a chunk known to be exactly one frame (bytes this program wrote itself): it is
    /// framed at once, so it is shown — and paired — before anything that comes after it.
    pub fn push_frame<S: Sink>(&mut self, chunk: &Chunk<'_>, sink: &mut S) {
        let i = self.port_index(chunk.port);
        // On a half-duplex line what this program wrote follows everything heard before it (a
        // request goes out after the last answer ended; an answer after its whole request):
        // the other ports' pending bytes are complete now.
        for (j, (_, framer)) in self.ports.iter_mut().enumerate() {
            if j != i {
                let (pairing, scratch) = (&mut self.pairing, &mut self.scratch);
                let mut emit = |e: FrameEvent<'_>| route(pairing, scratch, e, sink);
                match framer {
                    PortFramer::Rtu(f) => f.finish(&mut emit),
                    PortFramer::Ascii(f) => f.finish(&mut emit),
                }
            }
        }
        let (pairing, scratch) = (&mut self.pairing, &mut self.scratch);
        let mut emit = |e: FrameEvent<'_>| route(pairing, scratch, e, sink);
        match &mut self.ports[i].1 {
            PortFramer::Rtu(f) => f.push_whole(chunk, &mut emit),
            PortFramer::Ascii(f) => f.push(chunk, &mut emit),
        }
    }

    /// The time is `now` and nothing arrived: framers flush what silence decides, pairing
    /// times out what waited too long.
    pub fn tick<S: Sink>(&mut self, now: Timestamp, sink: &mut S) {
        for (_, framer) in &mut self.ports {
            let (pairing, scratch) = (&mut self.pairing, &mut self.scratch);
            let mut emit = |e: FrameEvent<'_>| route(pairing, scratch, e, sink);
            match framer {
                PortFramer::Rtu(f) => f.tick(now, &mut emit),
                PortFramer::Ascii(f) => f.tick(now, &mut emit),
            }
        }
        // A request's answer may be held behind an undecided twin: pairing gives up
        // on nothing later than what is held, or a live session would call a request
        // unanswered whose answer a replay of the same bytes pairs with it.
        let held = self.ports.iter().filter_map(|(_, f)| match f {
            PortFramer::Rtu(f) => f.held_since(),
            PortFramer::Ascii(_) => None,
        });
        let upto = held.fold(now, std::cmp::Ord::min);
        self.pairing.tick(upto, &mut |t: Transaction<'_>| sink.event(&Event::Transaction(&t)));
    }

    /// End of input. The sink is told what each RTU port's framer learned about its reads.
    pub fn finish<S: Sink>(&mut self, sink: &mut S) {
        for (_, framer) in &mut self.ports {
            let (pairing, scratch) = (&mut self.pairing, &mut self.scratch);
            let mut emit = |e: FrameEvent<'_>| route(pairing, scratch, e, sink);
            match framer {
                PortFramer::Rtu(f) => f.finish(&mut emit),
                PortFramer::Ascii(f) => f.finish(&mut emit),
            }
        }
        self.pairing.finish_all(&mut |t: Transaction<'_>| sink.event(&Event::Transaction(&t)));
        for (port, estimate) in self.observers() {
            sink.observer(port, &estimate);
        }
    }

    /// Vendor functions' frame lengths device profiles declare, for every port's framer.
    pub fn declare_lengths(&mut self, declared: &[DeclaredLength]) {
        self.declared.extend_from_slice(declared);
        for (_, framer) in &mut self.ports {
            if let PortFramer::Rtu(f) = framer {
                for &(unit, fc, request, len) in declared {
                    f.declare_length(unit, fc, request, len);
                }
            }
        }
    }

    /// What the session that recorded `port` learned about its reads (see
    /// [`RtuFramer::set_recorded_latency`]).
    pub fn set_recorded_latency(&mut self, port: PortId, ns: u64) {
        if let Some((_, PortFramer::Rtu(f))) = self.ports.iter_mut().find(|(p, _)| *p == port) {
            f.set_recorded_latency(ns);
        }
    }

    /// What each RTU port's framer learned about its observer's reads so far.
    #[must_use]
    pub fn observers(&self) -> Vec<(PortId, crate::framer::ObserverEstimate)> {
        self.ports
            .iter()
            .filter_map(|(p, f)| match f {
                PortFramer::Rtu(f) => Some((*p, f.observer())),
                PortFramer::Ascii(_) => None,
            })
            .collect()
    }
}

fn route<S: Sink>(pairing: &mut Pairing, scratch: &mut Vec<u8>, e: FrameEvent<'_>, sink: &mut S) {
    match e {
        FrameEvent::Noise(n) => sink.event(&Event::Noise(&n)),
        FrameEvent::Glitch(n) => sink.event(&Event::Glitch(&n)),
        FrameEvent::Frame(f) => {
            let decoded = f.unit_pdu(scratch);
            // The frame's event goes out before the transaction it completes; a sink is needed
            // by both callbacks, so it is shared through a cell for the duration of the call.
            let cell = std::cell::RefCell::new(sink);
            pairing.frame_then(
                &f,
                decoded,
                |role: Role| {
                    cell.borrow_mut().event(&Event::Frame {
                        frame: &f,
                        role,
                        unit: decoded.map(|d| d.0),
                        pdu: decoded.map(|d| d.1),
                    });
                },
                &mut |t: Transaction<'_>| cell.borrow_mut().event(&Event::Transaction(&t)),
            );
        }
    }
}

#[cfg(test)]
mod declared_length_tests {
    use super::*;

    /// Unit 1, vendor function 0x41: a request (unit, code, 3 data, CRC `9B FC`).
    const REQUEST: [u8; 7] = [0x01, 0x41, 0x09, 0x08, 0x07, 0x9B, 0xFC];
    /// Its 14-byte answer (unit, code, 10 data, CRC `38 00`: the high byte `00`), then a `00`
    /// turnaround glitch glued to it: 13, 14 and 15 bytes all check.
    const ANSWER_AND_GLITCH: [u8; 15] = [
        0x01, 0x41, // unit 1, vendor code
        0xA3, 0x00, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, // data
        0x38, 0x00, // CRC, high byte 00
        0x00, // glitch
    ];

    fn frames(declared: &[DeclaredLength]) -> Vec<(usize, bool)> {
        let mut a = Analyzer::new(AnalyzerConfig::default());
        a.declare_lengths(declared);
        let mut out = Vec::new();
        let mut sink = |e: &Event<'_>| {
            if let Event::Frame { frame, .. } = e {
                out.push((frame.bytes.len(), frame.check_ok));
            }
        };
        let ms = 1_000_000;
        a.push(&Chunk { port: PortId(0), t: Timestamp(10 * ms), bytes: &REQUEST }, &mut sink);
        a.push(&Chunk { port: PortId(0), t: Timestamp(30 * ms), bytes: &ANSWER_AND_GLITCH }, &mut sink);
        a.tick(Timestamp(200 * ms), &mut sink);
        a.finish(&mut sink);
        out
    }

    /// A profile may declare a vendor function's lengths; the first answer of the
    /// day, whose CRC ends in `00` and which its glitch follows, is then read at its length —
    /// before any has been learned from the line.
    #[test]
    fn a_profiles_vendor_length_decides_the_first_twin() {
        let declared = [(1, 0x41, true, 7), (1, 0x41, false, 14)];
        assert_eq!(frames(&declared), [(7, true), (14, true)]);
        // Nothing declared, nothing learned yet: the odds of a line never seen to glitch take
        // the longest reading, the glitch inside the frame.
        assert_eq!(frames(&[]), [(7, true), (15, true)]);
    }

    /// The answer, a twin nothing decides, is held (see `framer::rtu::hold`); a live session's
    /// ticks go on meanwhile. They never call the request unanswered at its timeout, nor the held
    /// answer an orphan when it comes out: live as in a replay of the same bytes, which ticks only
    /// as frames come, the two pair.
    #[test]
    fn a_request_is_not_given_up_while_its_answer_is_held() {
        use crate::pairing::Outcome;
        let mut a = Analyzer::new(AnalyzerConfig::default());
        let outcomes = std::cell::RefCell::new(Vec::new());
        let mut sink = |e: &Event<'_>| {
            if let Event::Transaction(t) = e {
                outcomes.borrow_mut().push(t.outcome);
            }
        };
        let ms = 1_000_000;
        a.push(&Chunk { port: PortId(0), t: Timestamp(10 * ms), bytes: &REQUEST }, &mut sink);
        a.push(&Chunk { port: PortId(0), t: Timestamp(30 * ms), bytes: &ANSWER_AND_GLITCH }, &mut sink);
        for s in 1..=5 {
            a.tick(Timestamp(30 * ms + s * 1000 * ms), &mut sink);
        }
        assert!(outcomes.borrow().is_empty(), "{:?}", outcomes.borrow());
        a.finish(&mut sink);
        assert_eq!(*outcomes.borrow(), [Outcome::Ok]);
    }
}
