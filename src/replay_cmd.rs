//! `mbtap replay FILE`: a line capture through the analyzer, exactly as a live session would
//! have seen it.

use std::io::{self, Read, Write};

use anyhow::Context;

use crate::analyzer::{Analyzer, AnalyzerConfig, Event};
use crate::capture::{CaptureReader, Item};
use crate::chunk::{Chunk, PortId, Timestamp};
use crate::framer::FramerConfig;
use crate::line_args::LineOverrides;
use crate::pairing::PairingConfig;
use crate::report::events::{Stats, json, text_line};

/// Output of `replay` and `sniff`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventFormat {
    Text,
    Jsonl,
    /// Only the summary at the end (fastest: the statistics sink).
    Summary,
}

/// Writes events in a format and counts them.
#[derive(Debug)]
pub struct EventWriter<W: Write> {
    pub out: W,
    pub format: EventFormat,
    pub stats: Stats,
    pub error: Option<io::Error>,
    /// Profiles by unit: transactions of these units get their values annotated.
    pub profiles: crate::decode_cmd::Profiles,
    /// The register image, when asked for.
    pub image: Option<crate::profile::image::RegisterImage>,
    /// Language of names in text annotations.
    pub lang: crate::profile::annotate::Lang,
    /// The terminal UI's model: events go there instead of `out`.
    pub tui: Option<std::sync::Arc<crate::tui::terminal::Shared>>,
    /// Recorded input shown in the UI: hold each event until its time at the UI's speed.
    pub pacer: Option<crate::tui::terminal::Pacer>,
    /// The bus health report, written by [`Self::finish`] when set.
    pub health: Option<crate::health::Health>,
    /// Also write the report so far each time this much bus time has passed.
    pub report_every_ns: Option<u64>,
    next_report_ns: Option<u64>,
}

impl<W: Write> EventWriter<W> {
    pub fn new(out: W, format: EventFormat) -> Self {
        Self {
            out,
            format,
            stats: Stats::default(),
            error: None,
            profiles: crate::decode_cmd::Profiles::new(),
            image: None,
            lang: crate::profile::annotate::Lang::En,
            tui: None,
            pacer: None,
            health: None,
            report_every_ns: None,
            next_report_ns: None,
        }
    }

    /// Writes one event (errors are kept for the caller; a closed pipe stops output).
    pub fn write(&mut self, e: &Event<'_>) {
        self.stats.add(e);
        // Annotated once, for the health report and the output alike (the UI makes its own).
        let shown = self.tui.is_none() && self.error.is_none() && self.format != EventFormat::Summary;
        let annotations = match e {
            Event::Transaction(t) if t.outcome == crate::pairing::Outcome::Ok && (shown || self.health.is_some()) => {
                match (self.profiles.get(&t.unit), t.request) {
                    (Some(p), Some(req)) => Some(crate::profile::transaction::annotate_wire(p, req, t.response)),
                    _ => None,
                }
            }
            _ => None,
        };
        if let Some(h) = self.health.as_mut() {
            h.event_annotated(e, annotations.as_deref());
        }
        if let Some(every) = self.report_every_ns {
            // Bus time, not the clock: a replay gives the same interim reports as the live run.
            let t = event_time(e);
            let due = *self.next_report_ns.get_or_insert(t.saturating_add(every));
            if t >= due && self.tui.is_none() && self.error.is_none() {
                self.next_report_ns = Some(t.saturating_add(every));
                if let Err(err) = self.write_report(false) {
                    self.error = Some(err);
                }
            }
        }
        if let (Some(image), Event::Transaction(t)) = (self.image.as_mut(), e)
            && let Some(req) = t.request
        {
            let resp = if t.outcome == crate::pairing::Outcome::Ok { t.response } else { None };
            image.update(t.unit, t.t_start.0, req, resp);
        }
        if let Some(shared) = &self.tui {
            if let Some(pacer) = self.pacer.as_mut() {
                pace(pacer, shared, e);
            }
            shared.model().event(e);
            return;
        }
        if self.error.is_some() {
            return;
        }
        if self.format == EventFormat::Summary {
            return;
        }
        let annotations = annotations.unwrap_or_default();
        let r = match self.format {
            EventFormat::Text => {
                let mut text = text_line(e);
                for a in &annotations {
                    text.push_str("\n      ");
                    text.push_str(&a.line(self.lang));
                }
                writeln!(self.out, "{text}")
            }
            EventFormat::Jsonl => {
                let mut line = json(e).to_string();
                if !annotations.is_empty() && line.ends_with('}') {
                    line.pop();
                    line.push_str(",\"annotations\":[");
                    for (i, a) in annotations.iter().enumerate() {
                        if i > 0 {
                            line.push(',');
                        }
                        crate::report::annotations::write_json(&mut line, a);
                    }
                    line.push_str("]}");
                }
                writeln!(self.out, "{line}")
            }
            EventFormat::Summary => Ok(()),
        };
        if let Err(err) = r {
            self.error = Some(err);
        }
    }

    /// A warning about the input.
    pub fn warning(&mut self, err: &mut dyn Write, message: &str) {
        match self.format {
            EventFormat::Jsonl => {
                let _ = writeln!(self.out, "{}", serde_json::json!({"event": "warning", "message": message}));
            }
            _ => {
                let _ = writeln!(err, "mbtap: warning: {message}");
            }
        }
    }

    /// Writes the summary (text and summary formats) and flushes.
    ///
    /// # Errors
    /// The first output error.
    pub fn finish(mut self) -> io::Result<Stats> {
        let mut r = match self.format {
            EventFormat::Text | EventFormat::Summary => writeln!(self.out, "{}", self.stats.text()),
            EventFormat::Jsonl => writeln!(self.out, "{}", self.stats.json()),
        };
        if self.health.is_some() {
            r = r.and_then(|()| self.write_report(true));
        }
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        r?;
        self.out.flush()?;
        Ok(self.stats)
    }
}

impl<W: Write> EventWriter<W> {
    /// The health report so far (text: headed with its time unless `last`; JSON lines: a
    /// `report` event with `final` true or false).
    fn write_report(&mut self, last: bool) -> io::Result<()> {
        let Some(h) = self.health.as_ref() else { return Ok(()) };
        let report = h.report();
        match self.format {
            EventFormat::Text | EventFormat::Summary => {
                if !last {
                    let until = report.last_t_ns.map_or_else(String::new, crate::health::clock);
                    writeln!(self.out, "--- bus health so far (until {until}) ---")?;
                }
                write!(self.out, "{}", report.text())?;
                if !last {
                    writeln!(self.out, "---")?;
                }
                Ok(())
            }
            EventFormat::Jsonl => {
                let mut j = report.json();
                if let Some(o) = j.as_object_mut() {
                    o.insert("event".into(), "report".into());
                    o.insert("final".into(), last.into());
                }
                writeln!(self.out, "{j}")
            }
        }
    }
}

/// The time an event happened (its end for frames and noise, its start for transactions).
fn event_time(e: &Event<'_>) -> u64 {
    match e {
        Event::Frame { frame, .. } => frame.t_end.0,
        Event::Noise(n) => n.t_end.0,
        Event::Transaction(t) => t.t_start.0,
    }
}

/// Waits (this thread) until `e` is due at the UI's speed; a stop request ends all waiting.
fn pace(pacer: &mut crate::tui::terminal::Pacer, shared: &crate::tui::terminal::Shared, e: &Event<'_>) {
    let t = event_time(e);
    while !crate::sniff_cmd::stop_requested() {
        match pacer.delay(t, shared.speed(), std::time::Instant::now()) {
            None => break,
            Some(d) => std::thread::sleep(d),
        }
    }
}

/// Replays a capture from `input` into `writer`; `cli` overrides the settings stored in the file.
///
/// # Errors
/// When the file cannot be read at all (not pcap/pcapng, I/O error).
pub fn replay<R: Read, W: Write>(
    input: R,
    cli: LineOverrides,
    writer: &mut EventWriter<W>,
    err: &mut dyn Write,
) -> anyhow::Result<()> {
    replay_into(input, cli, &mut WriterSink { writer, err })
}

/// An [`EventWriter`] as an analyzer sink, warnings included.
struct WriterSink<'a, W: Write> {
    writer: &'a mut EventWriter<W>,
    err: &'a mut dyn Write,
}

impl<W: Write> crate::analyzer::Sink for WriterSink<'_, W> {
    fn event(&mut self, event: &Event<'_>) {
        self.writer.write(event);
    }

    fn warning(&mut self, message: &str) {
        self.writer.warning(self.err, message);
    }

    fn settings(&mut self, line: crate::framer::LineSettings) {
        // The UI shows the line the capture was recorded on, not the command line's default.
        if let Some(shared) = &self.writer.tui {
            shared.model().line = line;
        }
    }
}

/// A packet held for reordering: (time, arrival order, port, bytes).
type Held = (u64, u64, u8, Vec<u8>);

/// Packets held to put several ports' packets in time order.
const REORDER_PACKETS: usize = 4096;
/// ... or this much time between the oldest and newest held packet.
const REORDER_NS: u64 = 1_000_000_000;

/// Replays a capture into any sink.
///
/// A capture with one port goes straight through. With several ports (a tap with one port per
/// direction) packets are merged by time through a bounded reorder window, and a port whose
/// description says `role=requests` or `role=responses` tells pairing the direction.
///
/// # Errors
/// When the file cannot be read at all (not pcap/pcapng, I/O error).
pub fn replay_into<R: Read, S: crate::analyzer::Sink>(
    input: R,
    cli: LineOverrides,
    sink: &mut S,
) -> anyhow::Result<()> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let mut reader = CaptureReader::new(input);
    let mut analyzer: Option<Analyzer> = None;
    let mut file_settings = LineOverrides::default();
    let mut pairing = PairingConfig::default();
    let mut ports = 0usize;
    let mut held: BinaryHeap<Reverse<Held>> = BinaryHeap::new();
    let mut seq = 0u64;
    let make = |file: LineOverrides, pairing: PairingConfig, sink: &mut S| {
        let (mode, line, latency_ns) = cli.or(file).resolve();
        sink.settings(line);
        Analyzer::new(AnalyzerConfig { mode, framer: FramerConfig::new(line, latency_ns), pairing })
    };
    loop {
        let item = reader.next_item().context("reading the capture")?;
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
                if analyzer.is_none() {
                    analyzer = Some(make(file_settings, pairing, sink));
                }
                let Some(a) = analyzer.as_mut() else { continue };
                if ports <= 1 {
                    a.push(&Chunk { port, t, bytes: data }, sink);
                    continue;
                }
                seq += 1;
                held.push(Reverse((t.0, seq, port.0, data.to_vec())));
                while let Some(Reverse((oldest, ..))) = held.peek() {
                    if held.len() <= REORDER_PACKETS && t.0.saturating_sub(*oldest) <= REORDER_NS {
                        break;
                    }
                    if let Some(Reverse((t, _, p, bytes))) = held.pop() {
                        a.push(&Chunk { port: PortId(p), t: Timestamp(t), bytes: &bytes }, sink);
                    }
                }
            }
        }
    }
    if let Some(a) = analyzer.as_mut() {
        while let Some(Reverse((t, _, p, bytes))) = held.pop() {
            a.push(&Chunk { port: PortId(p), t: Timestamp(t), bytes: &bytes }, sink);
        }
        a.finish(sink);
    }
    Ok(())
}
