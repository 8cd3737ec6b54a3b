//! The output sink every analyzing command writes through: events as text, JSON lines or only
//! counted (the terminal UI takes them instead when it runs), the register image, the health
//! report at the end or every so often; and a capture replayed into it. Beside it, the files
//! mbtap keeps as it runs: the audit of writes ([`audit`]), `learn`'s drafts, whole files
//! written safely.
//!
//! Modules: [`audit`], [`learn_draft`] (drafts written while listening), [`progress`] (reading a
//! capture file, on a terminal), [`whole_file`] (the one writer of whole files).

pub mod audit;
pub mod learn_draft;
pub mod progress;
pub mod whole_file;

use std::io::{self, Read, Write};

use anyhow::Context;

use mbtap_analysis::analyzer::Event;
use mbtap_analysis::line_args::LineOverrides;
use mbtap_analysis::report::events::{Stats, json, text_line};

/// Output of `replay` and `sniff`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventFormat {
    Text,
    Jsonl,
    /// Only the summary at the end (fastest: the statistics sink).
    Summary,
}

/// Why a source feeding the output ended with an error, and so whether a summary is due
/// (`cli::runner` decides by it; the source says which).
#[derive(Debug)]
pub enum SourceError {
    /// The source never began (a port that did not open, a file that is no capture): nothing
    /// was heard, so only the error is said (no empty summary on stdout beside it).
    NotStarted(anyhow::Error),
    /// It began and then failed: the summary of what was heard is still written, then the error.
    Stopped(anyhow::Error),
}

impl SourceError {
    #[must_use]
    pub fn into_error(self) -> anyhow::Error {
        match self {
            Self::NotStarted(e) | Self::Stopped(e) => e,
        }
    }
}

impl From<anyhow::Error> for SourceError {
    fn from(e: anyhow::Error) -> Self {
        Self::Stopped(e)
    }
}

/// Writes events in a format and counts them.
#[derive(Debug)]
pub struct EventWriter<W: Write> {
    pub out: W,
    pub format: EventFormat,
    pub stats: Stats,
    pub error: Option<io::Error>,
    /// Profiles by unit: transactions of these units get their values annotated.
    pub profiles: mbtap_device::profile::Profiles,
    /// The register image, when asked for.
    pub image: Option<mbtap_device::profile::image::RegisterImage>,
    /// Language of names in text annotations.
    pub lang: mbtap_device::profile::annotate::Lang,
    /// The terminal UI's model: events go there instead of `out`.
    pub tui: Option<std::sync::Arc<dyn UiFeed>>,
    /// Others that take every event beside the output (the spy server, MQTT).
    pub taps: Vec<std::sync::Arc<dyn Tap>>,
    /// Recorded input shown in the UI: each event held until its time at the UI's speed.
    pub paced: bool,
    /// The bus health report, written by [`Self::finish`] when set.
    pub health: Option<mbtap_analysis::health::Health>,
    /// Also write the report so far each time this much bus time has passed.
    pub report_every_ns: Option<u64>,
    next_report_ns: Option<u64>,
    /// Draft profiles learned from what is heard, kept up to date (`--learn DRAFT.toml`).
    pub learn: Option<learn_draft::LiveDraft>,
}

impl<W: Write> EventWriter<W> {
    pub fn new(out: W, format: EventFormat) -> Self {
        Self {
            out,
            format,
            stats: Stats::default(),
            error: None,
            profiles: mbtap_device::profile::Profiles::new(),
            image: None,
            lang: mbtap_device::profile::annotate::Lang::En,
            tui: None,
            taps: Vec::new(),
            paced: false,
            health: None,
            report_every_ns: None,
            next_report_ns: None,
            learn: None,
        }
    }

    /// Writes one event (errors are kept for the caller; a closed pipe stops output).
    pub fn write(&mut self, e: &Event<'_>) {
        self.stats.add(e);
        // Annotated once, for the health report and the output alike (the UI makes its own).
        let shown = self.tui.is_none() && self.error.is_none() && self.format != EventFormat::Summary;
        let annotations = match e {
            Event::Transaction(t)
                if t.outcome == mbtap_analysis::pairing::Outcome::Ok && (shown || self.health.is_some()) =>
            {
                match (self.profiles.get(&t.unit), t.request_pdu) {
                    (Some(p), Some(req)) => {
                        Some(mbtap_device::profile::transaction::annotate_pdus(p, req, t.response_pdu))
                    }
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
        if let Some(image) = self.image.as_mut() {
            update_image(image, e);
        }
        if let Some(l) = self.learn.as_mut()
            && let Err(err) = l.event(e, event_time(e))
            && self.error.is_none()
        {
            self.error = Some(io::Error::other(format!("{err:#}")));
        }
        for tap in &self.taps {
            tap.event(e);
        }
        if let Some(feed) = &self.tui {
            feed.event(e, self.paced);
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
                // Names, decoded strings and ASCII frames come from files and the bus: a terminal
                // must never get their control characters.
                writeln!(self.out, "{}", mbtap_analysis::report::format::printable(&text))
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
                        mbtap_analysis::report::annotations::write_json(&mut line, a);
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
        if self.format == EventFormat::Jsonl {
            let _ = writeln!(self.out, "{}", serde_json::json!({"event": "warning", "message": message}));
        } else {
            crate::output::progress::clear_line();
            let _ = writeln!(err, "mbtap: warning: {message}");
        }
    }

    /// Keeps what a port's framer learned about its reads, for the summary.
    pub fn observer(
        &mut self,
        port: mbtap_analysis::chunk::PortId,
        estimate: &mbtap_analysis::framer::ObserverEstimate,
    ) {
        self.stats.observe(port.0, estimate);
        if let Some(h) = &mut self.health {
            h.observer(port, estimate);
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
        if let Some(l) = self.learn.as_mut() {
            match l.finish() {
                Ok(files) => {
                    for (unit, file) in files {
                        eprintln!("mbtap: draft profile of unit {unit} written to {}", file.display());
                    }
                    if let Some(note) = l.left_out_note() {
                        eprintln!("mbtap: {note}");
                    }
                }
                Err(err) => r = r.and(Err(io::Error::other(format!("{err:#}")))),
            }
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
                    let until = report.last_t_ns.map_or_else(String::new, mbtap_analysis::health::clock);
                    writeln!(self.out, "--- bus health so far (until {until}) ---")?;
                }
                write!(self.out, "{}", mbtap_analysis::report::format::printable(&report.text()))?;
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
#[must_use]
pub fn event_time(e: &Event<'_>) -> u64 {
    match e {
        Event::Frame { frame, .. } => frame.t_end.0,
        Event::Noise(n) | Event::Glitch(n) => n.t_end.0,
        Event::Transaction(t) => t.t_start.0,
    }
}

/// Takes a completed transaction into a register image (other events change nothing).
pub fn update_image(image: &mut mbtap_device::profile::image::RegisterImage, e: &Event<'_>) {
    if let Event::Transaction(t) = e
        && let Some(req) = t.request_pdu
    {
        // A failed answer carries no values; its request alone still counts as a transaction.
        let resp = if t.outcome == mbtap_analysis::pairing::Outcome::Ok { t.response_pdu } else { None };
        image.update(t.unit, t.t_start.0, req, resp);
    }
}

/// Something that takes every event beside the output, from the thread that analyses: it must
/// not block (the spy server's image takes a short lock; MQTT queues and drops when full).
pub trait Tap: Send + Sync + std::fmt::Debug {
    fn event(&self, e: &Event<'_>);
}

/// Where events go instead of the text output while the terminal UI runs. The UI implements
/// it; the sink knows nothing of terminals (and the UI depends on the sink, never the reverse).
pub trait UiFeed: Send + Sync + std::fmt::Debug {
    /// Takes one event; with `paced` (recorded input) first waits until it is due at the
    /// UI's speed.
    fn event(&self, e: &Event<'_>, paced: bool);

    /// The line settings the events come from (a capture says them after the UI started).
    fn settings(&self, line: mbtap_analysis::framer::LineSettings);

    /// How long until line time `t_ns` is due at the UI's speed (`None`: now) — for a producer
    /// that paces itself (the simulated line of `demo`).
    fn due_in(&self, t_ns: u64) -> Option<std::time::Duration>;
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
    mbtap_analysis::replay::replay_into(input, cli, &mut WriterSink { writer, err }).context("reading the capture")
}

/// An [`EventWriter`] as an analyzer sink, warnings included.
struct WriterSink<'a, W: Write> {
    writer: &'a mut EventWriter<W>,
    err: &'a mut dyn Write,
}

impl<W: Write> mbtap_analysis::analyzer::Sink for WriterSink<'_, W> {
    fn event(&mut self, event: &Event<'_>) {
        self.writer.write(event);
    }

    fn warning(&mut self, message: &str) {
        self.writer.warning(self.err, message);
    }

    fn settings(&mut self, line: mbtap_analysis::framer::LineSettings) {
        // The UI shows the line the capture was recorded on, not the command line's default.
        if let Some(feed) = &self.writer.tui {
            feed.settings(line);
        }
    }

    fn observer(&mut self, port: mbtap_analysis::chunk::PortId, estimate: &mbtap_analysis::framer::ObserverEstimate) {
        self.writer.observer(port, estimate);
    }

    fn declared_lengths(&self) -> Vec<mbtap_analysis::analyzer::DeclaredLength> {
        mbtap_analysis::analyzer::declared_lengths(&self.writer.profiles)
    }
}
