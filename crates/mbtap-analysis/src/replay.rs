//! A line capture through the analyzer into any [`Sink`]: the one path `replay`, `report`,
//! `export` and the capture fuzz target share, so each sees exactly what a live session saw.

use crate::analyzer::{Analyzer, AnalyzerConfig, Sink};
use crate::capture::{CaptureError, CaptureReader, Item};
use crate::chunk::{Chunk, PortId, Timestamp};
use crate::framer::FramerConfig;
use crate::line_args::LineOverrides;
use crate::pairing::PairingConfig;

/// A packet held for reordering: (time, arrival order, port, bytes).
type Held = (u64, u64, u8, Vec<u8>);

/// Packets held to put several ports' packets in time order.
const REORDER_PACKETS: usize = 4096;
/// ... or this much time between the oldest and newest held packet.
const REORDER_NS: u64 = 1_000_000_000;
/// ... or this many bytes held in all: memory must not follow the file.
const REORDER_BYTES: usize = 4 << 20;

/// Replays a capture into any sink.
///
/// A capture with one port goes straight through. With several ports (a tap with one port per
/// direction) packets are merged by time through a bounded reorder window, and a port whose
/// description says `role=requests` or `role=responses` tells pairing the direction.
///
/// # Errors
/// When the file cannot be read at all (not pcap/pcapng, I/O error).
pub fn replay_into<R: std::io::Read, S: Sink>(input: R, cli: LineOverrides, sink: &mut S) -> Result<(), CaptureError> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let sink = &mut Watch { inner: sink, valid: 0 };
    // Whether the bytes read like Modbus ASCII, to hint at the mode if nothing frames as RTU.
    let mut ascii_look = AsciiLook::default();
    let mut reader = CaptureReader::new(input).with_link_type(cli.link_type);
    let mut analyzer: Option<Analyzer> = None;
    let mut file_settings = LineOverrides::default();
    let mut pairing = PairingConfig::default();
    let mut ports = 0usize;
    let mut held: BinaryHeap<Reverse<Held>> = BinaryHeap::new();
    let mut seq = 0u64;
    let mut held_bytes = 0usize;
    let make = |file: LineOverrides, pairing: PairingConfig, sink: &mut Watch<'_, S>| {
        let (mode, line, latency_ns) = cli.or(file).resolve();
        if cli.baud.is_none() && file.baud.is_none() {
            sink.warning(&format!(
                "the capture stores no line settings: read as {line} {}, the serial-line defaults (give --baud, --parity and --mode if the line was otherwise)",
                mode.name()
            ));
        }
        sink.settings(line);
        // A latency given on the command line is kept; one the capture stores (or none) is
        // what the recorder knew, and valid frames may show the reads were later still.
        // Neither said: the reads are taken as exact until valid frames show otherwise.
        let framer = FramerConfig {
            learn_latency: cli.latency_ns.is_none(),
            ..FramerConfig::new(line, latency_ns.unwrap_or(0))
        };
        let mut analyzer = Analyzer::new(AnalyzerConfig { mode, framer, pairing });
        analyzer.declare_lengths(&sink.declared_lengths());
        analyzer
    };
    loop {
        let item = reader.next_item()?;
        let Some(item) = item else { break };
        match item {
            Item::Interface { port, interface } => {
                ports += 1;
                let description = interface.description.unwrap_or_default();
                if ports == 1 {
                    file_settings = LineOverrides::from_description(&description);
                }
                if description.split_whitespace().any(|w| w == "role=requests") {
                    pairing.request_port = Some(port);
                } else if description.split_whitespace().any(|w| w == "role=responses") {
                    pairing.response_port = Some(port);
                }
            }
            Item::Warning(w) => sink.warning(&w),
            Item::Packet { port, t, data } => {
                ascii_look.feed(data);
                if analyzer.is_none() {
                    analyzer = Some(make(file_settings, pairing, sink));
                }
                let Some(a) = analyzer.as_mut() else { continue };
                if ports <= 1 {
                    a.push(&Chunk { port, t, bytes: data }, sink);
                    continue;
                }
                seq += 1;
                held_bytes += data.len();
                held.push(Reverse((t.0, seq, port.0, data.to_vec())));
                while let Some(Reverse((oldest, ..))) = held.peek() {
                    if held.len() <= REORDER_PACKETS
                        && t.0.saturating_sub(*oldest) <= REORDER_NS
                        && held_bytes <= REORDER_BYTES
                    {
                        break;
                    }
                    if let Some(Reverse((t, _, p, bytes))) = held.pop() {
                        held_bytes -= bytes.len();
                        a.push(&Chunk { port: PortId(p), t: Timestamp(t), bytes: &bytes }, sink);
                    }
                }
            }
        }
    }
    // Nothing read because no interface was raw serial bytes: an error, not an empty success.
    if reader.packets == 0
        && let Some(linktype) = reader.skipped_linktype
    {
        return Err(CaptureError::UnknownLinkType { linktype });
    }
    if let Some(a) = analyzer.as_mut() {
        while let Some(Reverse((t, _, p, bytes))) = held.pop() {
            a.push(&Chunk { port: PortId(p), t: Timestamp(t), bytes: &bytes }, sink);
        }
        for &(iface, ns) in &reader.recorded_latency {
            if let Ok(p) = u8::try_from(iface) {
                a.set_recorded_latency(PortId(p), ns);
            }
        }
        a.finish(sink);
        // Nothing framed: say what the bytes look like, rather than leave "noise" unexplained.
        if sink.valid == 0 {
            let rtu = a.config().mode == crate::analyzer::SerialMode::Rtu;
            if rtu && ascii_look.likely() {
                sink.warning(
                    "no valid RTU frame, and the bytes look like Modbus ASCII (':' … CR LF): try --mode ascii (mbtap scan FILE tells the mode and character size)",
                );
            } else {
                sink.warning(
                    "no valid frame in the capture: mbtap scan FILE tells which mode and character size the bytes fit",
                );
            }
        }
    }
    Ok(())
}

/// Whether a capture's bytes read like Modbus ASCII: ':' opens a frame, CR LF ends it, and
/// everything between is hex digits (Modbus over Serial Line v1.02, 2.5.2.1). Binary garbage
/// holds ':' and LF too, so most sampled bytes must be of that alphabet. Only the first
/// [`AsciiLook::SAMPLE`] bytes are looked at: the cost does not follow the file.
#[derive(Default)]
struct AsciiLook {
    sampled: usize,
    alphabet: usize,
    colon: bool,
    line_end: bool,
}

impl AsciiLook {
    const SAMPLE: usize = 64 * 1024;

    /// Once per packet: nothing but a comparison after the sample is full.
    #[inline]
    fn feed(&mut self, data: &[u8]) {
        if self.sampled < Self::SAMPLE {
            self.sample(data);
        }
    }

    #[inline(never)]
    fn sample(&mut self, data: &[u8]) {
        let room = Self::SAMPLE.saturating_sub(self.sampled);
        let data = &data[..data.len().min(room)];
        for &b in data {
            self.colon |= b == b':';
            self.line_end |= b == b'\n';
            if b.is_ascii_hexdigit() || matches!(b, b':' | b'\r' | b'\n') {
                self.alphabet += 1;
            }
        }
        self.sampled += data.len();
    }

    /// Both delimiters seen and at least 90 % of the sampled bytes of the ASCII-frame alphabet.
    fn likely(&self) -> bool {
        self.colon && self.line_end && self.alphabet.saturating_mul(10) >= self.sampled.saturating_mul(9)
    }
}

/// A sink that counts the valid frames passing through (for the hint at the end).
struct Watch<'s, S> {
    inner: &'s mut S,
    valid: u64,
}

impl<S: Sink> Sink for Watch<'_, S> {
    fn event(&mut self, event: &crate::analyzer::Event<'_>) {
        if let crate::analyzer::Event::Frame { frame, .. } = event
            && frame.check_ok
        {
            self.valid += 1;
        }
        self.inner.event(event);
    }

    fn warning(&mut self, message: &str) {
        self.inner.warning(message);
    }

    fn settings(&mut self, line: crate::framer::LineSettings) {
        self.inner.settings(line);
    }

    fn observer(&mut self, port: PortId, estimate: &crate::framer::ObserverEstimate) {
        self.inner.observer(port, estimate);
    }

    fn declared_lengths(&self) -> Vec<crate::analyzer::DeclaredLength> {
        self.inner.declared_lengths()
    }
}
