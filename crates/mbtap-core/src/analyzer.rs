//! The analyzer: chunks in, frames, noise and transactions out — the one code path shared by
//! live capture, replay and tests. Pure: time comes in with the chunks.

use crate::chunk::{Chunk, PortId, Timestamp};
use crate::framer::{AsciiFramer, Frame, FrameEvent, FramerConfig, Noise, RtuFramer};
use crate::pairing::{Pairing, PairingConfig, Role, Transaction};

/// Serial transmission mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SerialMode {
    Rtu,
    Ascii,
}

impl SerialMode {
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Rtu => "rtu",
            Self::Ascii => "ascii",
        }
    }
}

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
    ports: Vec<(PortId, PortFramer)>,
    pairing: Pairing,
    /// Decoded ASCII frame bytes (address, PDU, LRC), reused.
    scratch: Vec<u8>,
}

impl Analyzer {
    #[must_use]
    pub fn new(config: AnalyzerConfig) -> Self {
        Self { config, ports: Vec::new(), pairing: Pairing::new(config.pairing), scratch: Vec::new() }
    }

    #[must_use]
    pub const fn config(&self) -> &AnalyzerConfig {
        &self.config
    }

    fn port_index(&mut self, port: PortId) -> usize {
        if let Some(i) = self.ports.iter().position(|(p, _)| *p == port) {
            return i;
        }
        let framer = match self.config.mode {
            SerialMode::Rtu => PortFramer::Rtu(RtuFramer::new(port, self.config.framer)),
            SerialMode::Ascii => PortFramer::Ascii(AsciiFramer::new(port, self.config.framer.line)),
        };
        self.ports.push((port, framer));
        self.ports.len() - 1
    }

    /// Feeds one chunk.
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
        self.pairing.tick(now, &mut |t: Transaction<'_>| sink.event(&Event::Transaction(&t)));
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
