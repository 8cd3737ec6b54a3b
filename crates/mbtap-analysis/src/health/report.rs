//! The report's shape — findings with their evidence, per-unit figures, the timeline for the
//! plots — and its text and JSON renderings.

use std::collections::BTreeMap;

use serde::Serialize;

use super::ratio;

/// One thing wrong, with its evidence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// A stable snake_case name.
    pub kind: &'static str,
    /// The unit, or `None` for the whole bus.
    pub unit: Option<u8>,
    pub count: u64,
    pub first_t_ns: u64,
    pub last_t_ns: u64,
    /// What it means, in a sentence.
    pub summary: String,
    /// Times (ns) of the first occurrences.
    pub evidence: Vec<u64>,
}

/// Per-unit figures.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct UnitHealth {
    pub unit: u8,
    pub transactions: u64,
    pub ok: u64,
    pub exceptions: BTreeMap<u8, u64>,
    pub no_response: u64,
    pub bad_responses: u64,
    /// Answered share of requests, percent.
    pub availability_percent: f64,
    pub latency_p50_ns: Option<u64>,
    pub latency_p99_ns: Option<u64>,
    pub latency_max_ns: Option<u64>,
    /// The median time between one request and the next identical one.
    pub poll_period_ns: Option<u64>,
}

impl UnitHealth {
    /// The figures as the text and HTML reports show them: (label, value), in table order.
    #[must_use]
    pub fn figures(&self) -> [(&'static str, String); 9] {
        let ms = |v: Option<u64>| v.map_or_else(|| "–".into(), |v| format!("{:.1} ms", ratio(v, 1_000_000)));
        [
            ("transactions", self.transactions.to_string()),
            ("availability", format!("{:.1} %", self.availability_percent)),
            ("unanswered", self.no_response.to_string()),
            ("failed checks", self.bad_responses.to_string()),
            ("exceptions", self.exceptions.values().sum::<u64>().to_string()),
            ("latency p50", ms(self.latency_p50_ns)),
            ("p99", ms(self.latency_p99_ns)),
            ("max", ms(self.latency_max_ns)),
            (
                "polled every",
                self.poll_period_ns.map_or_else(|| "–".into(), |p| format!("{:.2} s", ratio(p, 1_000_000_000))),
            ),
        ]
    }
}

/// One slice of the capture's time, for the plots.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Bin {
    pub t_start_ns: u64,
    pub transactions: u64,
    /// Transactions that did not end with an answer (timeouts, failed checks) plus noise bursts.
    pub errors: u64,
    pub latency_max_ns: Option<u64>,
}

/// One transaction's latency, for the latency plot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct LatencyPoint {
    pub t_ns: u64,
    pub unit: u8,
    pub latency_ns: u64,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub first_t_ns: Option<u64>,
    pub last_t_ns: Option<u64>,
    pub frames: u64,
    /// Frames that failed their check: the units' failed answers, and [`Self::stray_frames`].
    pub bad_frames: u64,
    /// Noise bursts and their bytes: what the framer read as no frame (as `replay` counts).
    pub noise_bytes: u64,
    pub noise_bursts: u64,
    /// Failed frames while no answer was awaited (no unit they can be laid on), and their bytes.
    pub stray_frames: u64,
    pub stray_bytes: u64,
    /// Garbage before the first good frame (the listener joined mid-frame), not counted as noise.
    pub cut_at_start_bytes: u64,
    pub frame_bytes: u64,
    pub transactions: u64,
    pub units: Vec<UnitHealth>,
    pub findings: Vec<Finding>,
    /// The capture cut into [`BINS`] slices of time.
    pub timeline: Vec<Bin>,
    /// Latencies over time (every one up to [`LATENCY_POINTS`], then evenly thinned).
    pub latencies: Vec<LatencyPoint>,
    /// The line settings the capture was read with (`19200 8E1 rtu`), when the caller knows.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<String>,
    /// What each port's framer learned about its observer's reads (the latency worked with and
    /// where it came from), one sentence each.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub observers: Vec<String>,
    /// What the observer's reads could not resolve (timing faults too short to prove through
    /// them), said once rather than as findings against units.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub limits: Vec<String>,
}

/// How much a finding should worry the reader, for the HTML page's colours: `alarm` (the bus
/// or a unit does not work), `warning` (it works, with faults), `info` (worth knowing).
#[must_use]
pub fn severity(f: &Finding) -> &'static str {
    match f.kind {
        "no_valid_frames" | "wrong_line_settings" | "second_master" | "duplicate_address" => "alarm",
        "no_response" if f.summary.contains("never answers") => "alarm",
        "turnaround_glitch" => "info",
        _ => "warning",
    }
}

/// Slices of time in the timeline.
pub const BINS: usize = 120;
/// Latency points kept for the plot.
pub const LATENCY_POINTS: usize = 4000;

impl Report {
    /// The report for people.
    #[must_use]
    pub fn text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let span = match (self.first_t_ns, self.last_t_ns) {
            (Some(a), Some(b)) => format!("{:.1} s", ratio(b - a, 1_000_000_000)),
            _ => "nothing".into(),
        };
        let strays = if self.stray_frames > 0 {
            format!(", {} of them with no answer awaited", self.stray_frames)
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "bus: {span} of traffic, {} frames ({} failed checks{strays}), {} transactions, {} noise bursts ({} bytes)",
            self.frames, self.bad_frames, self.transactions, self.noise_bursts, self.noise_bytes
        );
        if let Some(line) = &self.line {
            let _ = writeln!(s, "line: {line}");
        }
        for o in self.observers.iter().chain(&self.limits) {
            let _ = writeln!(s, "{o}");
        }
        if self.cut_at_start_bytes > 0 && self.frames > self.bad_frames {
            let _ = writeln!(
                s,
                "     ({} byte(s) before the first good frame: listening began mid-frame; not counted as noise)",
                self.cut_at_start_bytes
            );
        }
        for u in &self.units {
            let figures: Vec<String> = u.figures().iter().map(|(label, value)| format!("{label} {value}")).collect();
            let _ = writeln!(s, "unit {:>3}: {}", u.unit, figures.join(", "));
        }
        if self.findings.is_empty() {
            let _ = writeln!(s, "findings: none — the bus looks healthy");
        } else {
            let _ = writeln!(s, "findings:");
            for f in &self.findings {
                let who = f.unit.map_or_else(|| "bus".to_owned(), |u| format!("unit {u}"));
                if f.evidence.is_empty() {
                    // Nothing to point at in time (nothing was heard at all).
                    let _ = writeln!(s, "  [{}] {who}: {}", f.kind, f.summary);
                    continue;
                }
                let _ = writeln!(
                    s,
                    "  [{}] {who}: {} ({}×, from {} to {})",
                    f.kind,
                    f.summary,
                    f.count,
                    clock(f.first_t_ns),
                    clock(f.last_t_ns)
                );
                let times: Vec<String> = f.evidence.iter().map(|&t| clock(t)).collect();
                let _ = writeln!(s, "      at {}", times.join(", "));
            }
        }
        s
    }

    /// The report for programs: `findings` at the top level with `kind`, `unit`, `count`,
    /// `first_t_ns`, `last_t_ns`, `evidence`.
    #[must_use]
    pub fn json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }
}

pub use crate::report::format::clock_ms as clock;
