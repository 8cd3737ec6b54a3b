//! The counts of what went by — the statistics sink and the summary printed at the end — and
//! what the observer's latency was learned to be.

use crate::analyzer::Event;
use crate::framer::ObserverEstimate;
use crate::pairing::Outcome;
use serde_json::{Value as J, json};

/// Counts of what went by: the statistics sink, and the summary printed after a replay.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    pub frames: u64,
    pub frame_bytes: u64,
    pub bad_frames: u64,
    pub noise_events: u64,
    pub noise_bytes: u64,
    /// Turnaround glitch bytes.
    pub glitches: u64,
    pub gap_violations: u64,
    /// Frames that followed the previous one after less than t3.5 of silence.
    pub short_gaps: u64,
    pub transactions: u64,
    pub ok: u64,
    pub exceptions: u64,
    pub no_response: u64,
    pub broadcasts: u64,
    pub bad_responses: u64,
    pub orphans: u64,
    pub wrong_unit: u64,
    /// What the framers learned about the reads of the first two ports (a tap has two).
    pub observers: [Option<(u8, ObserverEstimate)>; 2],
}

impl Stats {
    /// Counts one event.
    pub fn add(&mut self, e: &Event<'_>) {
        match *e {
            Event::Frame { frame, .. } => {
                self.frames += 1;
                self.frame_bytes += frame.bytes.len() as u64;
                self.bad_frames += u64::from(!frame.check_ok);
                self.gap_violations += u64::from(frame.gap_violation_ns.is_some());
                self.short_gaps += u64::from(frame.short_gap_before_ns.is_some());
            }
            Event::Noise(n) => {
                self.noise_events += 1;
                self.noise_bytes += n.bytes.len() as u64;
            }
            Event::Glitch(_) => self.glitches += 1,
            Event::Transaction(t) => {
                self.transactions += 1;
                match t.outcome {
                    Outcome::Ok => self.ok += 1,
                    Outcome::Exception(_) => self.exceptions += 1,
                    Outcome::NoResponse => self.no_response += 1,
                    Outcome::Broadcast => self.broadcasts += 1,
                    Outcome::BadResponse => self.bad_responses += 1,
                    Outcome::Orphan => self.orphans += 1,
                    Outcome::WrongUnit(_) => self.wrong_unit += 1,
                }
            }
        }
    }

    /// Keeps what a port's framer learned about its reads (the first two ports).
    pub fn observe(&mut self, port: u8, estimate: &ObserverEstimate) {
        if let Some(slot) = self.observers.iter_mut().find(|o| o.is_none_or(|(p, _)| p == port)) {
            *slot = Some((port, *estimate));
        }
    }

    /// The observers that learned something (a batch of frames split across reads).
    pub(super) fn learned(&self) -> impl Iterator<Item = &(u8, ObserverEstimate)> {
        self.observers
            .iter()
            .flatten()
            .filter(|(_, e)| e.learned_latency_ns.is_some() || e.recorded_latency_ns.is_some())
    }

    /// The summary as JSON.
    #[must_use]
    pub fn json(&self) -> J {
        let mut j = self.counts_json();
        let observers: Vec<J> = self
            .learned()
            .map(|(port, e)| {
                let mut o = json!({
                    "port": port, "reads": e.reads, "read_bytes": e.read_bytes, "longest_read": e.longest_read,
                    "shape": e.shape(), "split_frames": e.split_frames,
                    "learned_latency_ns": e.learned_latency_ns, "configured_latency_ns": e.configured_latency_ns,
                    "learning": e.learning, "latency_ns": e.effective_latency_ns(),
                });
                // Only a replay of a recording that stored it has one.
                if let (Some(r), Some(m)) = (e.recorded_latency_ns, o.as_object_mut()) {
                    m.insert("recorded_latency_ns".into(), json!(r));
                }
                o
            })
            .collect();
        if !observers.is_empty()
            && let Some(m) = j.as_object_mut()
        {
            m.insert("observers".into(), J::Array(observers));
        }
        j
    }

    pub(super) fn counts_json(&self) -> J {
        json!({
            "event": "summary",
            "frames": self.frames, "frame_bytes": self.frame_bytes, "bad_frames": self.bad_frames,
            "noise_events": self.noise_events, "noise_bytes": self.noise_bytes, "glitches": self.glitches,
            "gap_violations": self.gap_violations,
            "short_gaps": self.short_gaps, "transactions": self.transactions, "ok": self.ok, "exceptions": self.exceptions,
            "no_response": self.no_response, "broadcasts": self.broadcasts, "bad_responses": self.bad_responses,
            "orphan_responses": self.orphans, "wrong_unit": self.wrong_unit,
        })
    }

    /// The summary as text.
    #[must_use]
    pub fn text(&self) -> String {
        // Glitches are named only where there are some: a well-biased line's summary is as it was.
        let glitches =
            if self.glitches > 0 { format!(", {} turnaround glitches", self.glitches) } else { String::new() };
        format!(
            "summary: {} frames ({} bytes, {} failed check, {} with gaps inside, {} after less than t3.5), {} noise bursts ({} bytes){glitches}; {} transactions: {} ok, {} exceptions, {} no response, {} broadcasts, {} bad responses, {} orphan responses, {} from the wrong unit",
            self.frames,
            self.frame_bytes,
            self.bad_frames,
            self.gap_violations,
            self.short_gaps,
            self.noise_events,
            self.noise_bytes,
            self.transactions,
            self.ok,
            self.exceptions,
            self.no_response,
            self.broadcasts,
            self.bad_responses,
            self.orphans,
            self.wrong_unit
        ) + &self.learned().map(|(port, e)| observer_text(*port, e)).collect::<String>()
    }
}

/// What a port's framer learned about its reads, as a line of the summary (and the health
/// report's).
#[must_use]
pub fn observer_text(port: u8, e: &ObserverEstimate) -> String {
    let ms = |ns: u64| {
        #[allow(clippy::cast_precision_loss)]
        let v = ns as f64 / 1e6;
        v
    };
    let learned = e.learned_latency_ns.unwrap_or(0);
    let given = e.configured_latency_ns;
    let verdict = if !e.learning {
        format!("the latency given, {:.1} ms, kept", ms(given))
    } else if learned > given {
        format!("given {:.1} ms, timing now trusted only beyond {:.1} ms", ms(given), ms(learned))
    } else {
        format!("within the {:.1} ms given", ms(given))
    };
    let recorded = e
        .recorded_latency_ns
        .map(|r| format!("; the session that recorded it learned {:.1} ms", ms(r)))
        .unwrap_or_default();
    format!(
        "\nreads on port {port}: {}; valid frames split across reads show bytes delivered up to {:.1} ms late (learned from {} frames; {verdict}){recorded}",
        e.shape(),
        ms(learned),
        e.split_frames
    )
}
