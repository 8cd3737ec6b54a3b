//! The bus health report: what is wrong with a bus, each finding with its evidence (which
//! transactions, when), per unit and for the whole bus. Pure: analyzer events in, a report out;
//! `mbtap report FILE` feeds it a capture.
//!
//! Findings (stable `kind` names): `check_errors` (failed CRC/LRC, per unit or, when every unit
//! suffers, the bus), `noise`, `wrong_line_settings` (mostly garbage, few valid frames),
//! `gap_inside_frame` (t1.5 violations, Serial Line v1.02 §2.5.1.1), `fast_master` (requests
//! after less than t3.5), `no_response` (always or intermittently), `duplicate_address`
//! (answers that come twice), `implausible_jump` (a reading moving over half its documented
//! range between two reads), `exception_storm`,
//! `value_out_of_range` (outside the profile's range).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::analyzer::Event;
use crate::decode_cmd::Profiles;
use crate::pairing::{Outcome, Role};
use crate::profile::annotate::Note;

/// Evidence kept per finding: the first few times, enough to show a customer.
const EVIDENCE: usize = 10;
/// Exceptions above this share of a unit's transactions (and at least [`STORM_MIN`]) are a storm.
const STORM_SHARE: f64 = 0.2;
const STORM_MIN: u64 = 5;
/// Samples kept for plots and percentiles; past this they are thinned (every other one
/// dropped), so an endless live bus (`sniff --report`) stays in bounded memory.
const MAX_SAMPLES: usize = 1 << 20;

/// Halves `v` by keeping every other element once it is full.
fn thin<T>(v: &mut Vec<T>) {
    if v.len() >= MAX_SAMPLES {
        let mut i = 0;
        v.retain(|_| {
            i += 1;
            i % 2 == 0
        });
    }
}

/// An orphan answer this soon after an answered request from the same unit is a doubled answer.
const DOUBLED_WITHIN_NS: u64 = 500_000_000;
/// Below this share of bytes in valid frames, the line settings are suspect.
const GARBAGE_SHARE: f64 = 0.5;

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
    pub bad_frames: u64,
    pub noise_bytes: u64,
    pub frame_bytes: u64,
    pub transactions: u64,
    pub units: Vec<UnitHealth>,
    pub findings: Vec<Finding>,
    /// The capture cut into [`BINS`] slices of time.
    pub timeline: Vec<Bin>,
    /// Latencies over time (every one up to [`LATENCY_POINTS`], then evenly thinned).
    pub latencies: Vec<LatencyPoint>,
}

/// Slices of time in the timeline.
pub const BINS: usize = 120;
/// Latency points kept for the plot.
pub const LATENCY_POINTS: usize = 4000;

#[derive(Debug, Default)]
struct Tally {
    count: u64,
    first: u64,
    last: u64,
    evidence: Vec<u64>,
}

impl Tally {
    fn add(&mut self, t: u64) {
        if self.count == 0 {
            self.first = t;
        }
        self.count += 1;
        self.last = self.last.max(t);
        if self.evidence.len() < EVIDENCE {
            self.evidence.push(t);
        }
    }
}

#[derive(Debug, Default)]
struct UnitState {
    transactions: u64,
    ok: u64,
    exceptions: BTreeMap<u8, u64>,
    exception_tally: Tally,
    no_response: Tally,
    bad_response: Tally,
    gaps: Tally,
    out_of_range: Tally,
    /// Answers that came twice: two devices on one address.
    doubled: Tally,
    /// Readings that moved more than half their documented range from one read to the next.
    jumps: Tally,
    /// The last raw reading of each documented value with a range.
    last_values: BTreeMap<(crate::profile::Table, u16), i64>,
    latencies: Vec<u64>,
}

/// Collects events into a report.
#[derive(Debug, Default)]
pub struct Health {
    units: BTreeMap<u8, UnitState>,
    noise: Tally,
    noise_bytes: u64,
    frame_bytes: u64,
    frames: u64,
    bad_frames: u64,
    fast_master: Tally,
    transactions: u64,
    first: Option<u64>,
    last: Option<u64>,
    profiles: Profiles,
    /// (time, unit, latency, error) of every transaction, and the noise times, for the plots.
    samples: Vec<(u64, u8, Option<u64>, bool)>,
    noise_times: Vec<u64>,
    /// A request is waiting for its answer: a frame that fails its check now is that answer
    /// (pairing reports it); one that fails while nothing waits is noise that looked like a frame.
    awaiting: bool,
    /// The last transaction, when it was answered (unit, function, time) and nothing failed
    /// its check since: an orphan answer matching it is the same request answered twice.
    last_ok: Option<(u8, u8, u64)>,
}

impl Health {
    #[must_use]
    pub fn new(profiles: Profiles) -> Self {
        Self { profiles, ..Self::default() }
    }

    fn seen(&mut self, t: u64) {
        self.first = Some(self.first.map_or(t, |f| f.min(t)));
        self.last = Some(self.last.map_or(t, |l| l.max(t)));
    }

    /// Takes in one analyzer event.
    pub fn event(&mut self, e: &Event<'_>) {
        match *e {
            Event::Frame { frame, role, unit, .. } => {
                self.seen(frame.t_end.0);
                self.frames += 1;
                self.frame_bytes += frame.bytes.len() as u64;
                if !frame.check_ok {
                    self.bad_frames += 1;
                    self.last_ok = None;
                    if !self.awaiting {
                        thin(&mut self.noise_times);
                        self.noise_times.push(frame.t_start.0);
                        self.noise.add(frame.t_start.0);
                        self.noise_bytes += frame.bytes.len() as u64;
                        self.frame_bytes -= frame.bytes.len() as u64;
                    }
                }
                if frame.check_ok && role == Role::Request && unit != Some(0) {
                    self.awaiting = true;
                }
                if frame.gap_violation_ns.is_some()
                    && let Some(u) = unit
                {
                    self.units.entry(u).or_default().gaps.add(frame.t_start.0);
                }
                if frame.short_gap_before_ns.is_some() && role == Role::Request {
                    self.fast_master.add(frame.t_start.0);
                }
            }
            Event::Noise(n) => {
                self.seen(n.t_end.0);
                thin(&mut self.noise_times);
                self.noise_times.push(n.t_start.0);
                self.noise.add(n.t_start.0);
                self.noise_bytes += n.bytes.len() as u64;
            }
            Event::Transaction(t) => {
                self.awaiting = false;
                let at = t.t_start.0;
                self.seen(at);
                self.transactions += 1;
                if t.outcome == Outcome::Broadcast {
                    // Addressed to everyone, answered by no one: not a unit's figures.
                    return;
                }
                let u = self.units.entry(t.unit).or_default();
                u.transactions += 1;
                let previous = self.last_ok.take();
                match t.outcome {
                    Outcome::Ok => {
                        u.ok += 1;
                        self.last_ok = Some((t.unit, t.function, at));
                    }
                    // A second answer to the same request, nothing garbled in between: another
                    // device at this address.
                    Outcome::Orphan
                        if previous.is_some_and(|(unit, function, ok)| {
                            unit == t.unit && function == t.function && at.saturating_sub(ok) < DOUBLED_WITHIN_NS
                        }) =>
                    {
                        u.doubled.add(at);
                    }
                    Outcome::Exception(code) => {
                        *u.exceptions.entry(code).or_default() += 1;
                        u.exception_tally.add(at);
                    }
                    Outcome::NoResponse => u.no_response.add(at),
                    Outcome::BadResponse => u.bad_response.add(at),
                    Outcome::Broadcast | Outcome::Orphan | Outcome::WrongUnit(_) => {}
                }
                if let Some(l) = t.latency_ns {
                    thin(&mut u.latencies);
                    u.latencies.push(l);
                }
                let failed = matches!(t.outcome, Outcome::NoResponse | Outcome::BadResponse);
                thin(&mut self.samples);
                self.samples.push((at, t.unit, t.latency_ns, failed));
                if t.outcome == Outcome::Ok
                    && let (Some(p), Some(req)) = (self.profiles.get(&t.unit), t.request)
                {
                    let annotations = crate::profile::transaction::annotate_wire(p, req, t.response);
                    if annotations.iter().any(|a| a.notes.iter().any(|n| matches!(n, Note::OutOfRange { .. }))) {
                        u.out_of_range.add(at);
                    }
                    let mut jumped = false;
                    for a in &annotations {
                        let Some((min, max)) = p.slot(a.table, a.address).and_then(|(_, def)| def.range) else {
                            continue;
                        };
                        let is_number = matches!(a.shown, crate::profile::annotate::Shown::Number { .. });
                        if let (true, Some(prev)) = (is_number, u.last_values.insert((a.table, a.address), a.raw)) {
                            // More than half the documented span between two reads.
                            jumped |= (a.raw - prev).unsigned_abs().saturating_mul(2) > (max - min).unsigned_abs();
                        }
                    }
                    if jumped {
                        u.jumps.add(at);
                    }
                }
            }
        }
    }

    /// The report.
    #[must_use]
    pub fn report(&self) -> Report {
        let mut findings = Vec::new();
        let mut push = |kind, unit, t: &Tally, summary: String| {
            if t.count > 0 {
                findings.push(Finding {
                    kind,
                    unit,
                    count: t.count,
                    first_t_ns: t.first,
                    last_t_ns: t.last,
                    summary,
                    evidence: t.evidence.clone(),
                });
            }
        };
        let total_bytes = self.noise_bytes + self.frame_bytes;
        let garbage = total_bytes > 64 && ratio(self.noise_bytes, total_bytes) > GARBAGE_SHARE;
        if garbage {
            let share = ratio(self.noise_bytes, total_bytes) * 100.0;
            push(
                "wrong_line_settings",
                None,
                &self.noise,
                format!(
                    "{share:.0} % of the bytes belong to no valid frame: the baud rate, parity or mode is probably not the line's (try mbtap scan)"
                ),
            );
        } else {
            let n = self.noise.count;
            push(
                "noise",
                None,
                &self.noise,
                format!("{n} burst(s) of bytes that belong to no frame: interference, termination or biasing"),
            );
        }
        // Check errors on every unit that answers at all point at the bus, not a device.
        let answering: Vec<u8> = self.units.iter().filter(|(_, u)| u.ok > 0).map(|(&k, _)| k).collect();
        let failing: Vec<u8> = self.units.iter().filter(|(_, u)| u.bad_response.count > 0).map(|(&k, _)| k).collect();
        let bus_wide = answering.len() > 1 && answering.iter().all(|u| failing.contains(u));
        if bus_wide && !garbage {
            let mut all = Tally::default();
            let mut times: Vec<u64> =
                self.units.values().flat_map(|u| u.bad_response.evidence.iter().copied()).collect();
            times.sort_unstable();
            for u in self.units.values() {
                all.count += u.bad_response.count;
                all.first = if all.first == 0 { u.bad_response.first } else { all.first.min(u.bad_response.first) };
                all.last = all.last.max(u.bad_response.last);
            }
            all.evidence = times.into_iter().take(EVIDENCE).collect();
            push(
                "check_errors",
                None,
                &all,
                "answers with failed checks from every unit: the cabling, termination or grounding of the bus".into(),
            );
        }
        push(
            "fast_master",
            None,
            &self.fast_master,
            "requests sent less than t3.5 after the previous frame (Serial Line v1.02 §2.5.1.1): slaves may merge or drop them".into(),
        );
        let mut units = Vec::new();
        for (&unit, u) in &self.units {
            if !bus_wide && !garbage {
                let n = u.bad_response.count;
                push(
                    "check_errors",
                    Some(unit),
                    &u.bad_response,
                    format!("{n} answer(s) from unit {unit} failed their check"),
                );
            }
            push(
                "implausible_jump",
                Some(unit),
                &u.jumps,
                format!(
                    "unit {unit} reports readings that move more than half their documented range between two reads"
                ),
            );
            push(
                "duplicate_address",
                Some(unit),
                &u.doubled,
                format!("unit {unit} answers twice to one request: two devices are set to address {unit}"),
            );
            push(
                "gap_inside_frame",
                Some(unit),
                &u.gaps,
                format!(
                    "unit {unit} pauses inside its frames longer than t1.5: a slow device or a gateway that splits frames"
                ),
            );
            let nr = u.no_response.count;
            let pattern = if u.ok == 0 { "never answers" } else { "answers only intermittently" };
            push(
                "no_response",
                Some(unit),
                &u.no_response,
                format!("unit {unit} {pattern}: {nr} of {} request(s) unanswered", u.transactions),
            );
            let exceptions: u64 = u.exceptions.values().sum();
            if exceptions >= STORM_MIN && ratio(exceptions, u.transactions) > STORM_SHARE {
                let codes: Vec<String> = u.exceptions.iter().map(|(c, n)| format!("0x{c:02X}×{n}")).collect();
                push(
                    "exception_storm",
                    Some(unit),
                    &u.exception_tally,
                    format!(
                        "unit {unit} answers {exceptions} of {} requests with exceptions ({}): polling what the device does not have?",
                        u.transactions,
                        codes.join(", ")
                    ),
                );
            }
            push(
                "value_out_of_range",
                Some(unit),
                &u.out_of_range,
                format!("unit {unit} reports values outside its profile's range"),
            );
            let mut latencies = u.latencies.clone();
            latencies.sort_unstable();
            let pct = |p: usize| latencies.get((latencies.len().saturating_sub(1)) * p / 100).copied();
            units.push(UnitHealth {
                unit,
                transactions: u.transactions,
                ok: u.ok,
                exceptions: u.exceptions.clone(),
                no_response: u.no_response.count,
                bad_responses: u.bad_response.count,
                // Answered (normally or with an exception) out of asked.
                availability_percent: if u.transactions == 0 {
                    0.0
                } else {
                    100.0 - ratio(u.no_response.count + u.bad_response.count, u.transactions) * 100.0
                },
                latency_p50_ns: pct(50),
                latency_p99_ns: pct(99),
                latency_max_ns: latencies.last().copied(),
            });
        }
        findings.sort_by_key(|f| (f.first_t_ns, f.kind));
        let (timeline, latencies) = self.plots();
        Report {
            first_t_ns: self.first,
            last_t_ns: self.last,
            frames: self.frames,
            bad_frames: self.bad_frames,
            noise_bytes: self.noise_bytes,
            frame_bytes: self.frame_bytes,
            transactions: self.transactions,
            units,
            findings,
            timeline,
            latencies,
        }
    }

    fn plots(&self) -> (Vec<Bin>, Vec<LatencyPoint>) {
        let (Some(first), Some(last)) = (self.first, self.last) else { return (Vec::new(), Vec::new()) };
        let width = (last - first) / BINS as u64 + 1;
        let mut bins: Vec<Bin> =
            (0..BINS as u64).map(|i| Bin { t_start_ns: first + i * width, ..Bin::default() }).collect();
        let bin = |t: u64| usize::try_from((t.saturating_sub(first)) / width).unwrap_or(0).min(BINS - 1);
        for &(t, _, latency, failed) in &self.samples {
            let b = &mut bins[bin(t)];
            b.transactions += 1;
            b.errors += u64::from(failed);
            if let Some(l) = latency {
                b.latency_max_ns = Some(b.latency_max_ns.map_or(l, |m| m.max(l)));
            }
        }
        for &t in &self.noise_times {
            bins[bin(t)].errors += 1;
        }
        let with_latency: Vec<LatencyPoint> = self
            .samples
            .iter()
            .filter_map(|&(t_ns, unit, l, _)| l.map(|latency_ns| LatencyPoint { t_ns, unit, latency_ns }))
            .collect();
        let step = with_latency.len().div_ceil(LATENCY_POINTS).max(1);
        (bins, with_latency.into_iter().step_by(step).collect())
    }
}

/// a / b for percentages (counts stay far below 2^52).
#[allow(clippy::cast_precision_loss)]
fn ratio(a: u64, b: u64) -> f64 {
    if b == 0 { 0.0 } else { a as f64 / b as f64 }
}

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
        let _ = writeln!(
            s,
            "bus: {span} of traffic, {} frames ({} failed checks), {} transactions, {} bytes of noise",
            self.frames, self.bad_frames, self.transactions, self.noise_bytes
        );
        for u in &self.units {
            let ms = |v: Option<u64>| v.map_or_else(|| "–".into(), |v| format!("{:.1} ms", ratio(v, 1_000_000)));
            let _ = writeln!(
                s,
                "unit {:>3}: {} transactions, availability {:.1} %, {} unanswered, {} bad answers, {} exceptions, latency p50 {} p99 {} max {}",
                u.unit,
                u.transactions,
                u.availability_percent,
                u.no_response,
                u.bad_responses,
                u.exceptions.values().sum::<u64>(),
                ms(u.latency_p50_ns),
                ms(u.latency_p99_ns),
                ms(u.latency_max_ns)
            );
        }
        if self.findings.is_empty() {
            let _ = writeln!(s, "findings: none — the bus looks healthy");
        } else {
            let _ = writeln!(s, "findings:");
            for f in &self.findings {
                let who = f.unit.map_or_else(|| "bus".to_owned(), |u| format!("unit {u}"));
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

/// `HH:MM:SS.mmm` (UTC) of a time in ns since the epoch, as the findings show it.
#[must_use]
pub fn clock(t_ns: u64) -> String {
    let secs = t_ns / 1_000_000_000;
    let (h, m, s) = ((secs / 3600) % 24, (secs / 60) % 60, secs % 60);
    format!("{h:02}:{m:02}:{s:02}.{:03}", (t_ns % 1_000_000_000) / 1_000_000)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_memory_bounded_and_spread() {
        let mut v: Vec<usize> = (0..MAX_SAMPLES).collect();
        thin(&mut v);
        assert_eq!(v.len(), MAX_SAMPLES / 2);
        assert_eq!((v[0], v[1], *v.last().unwrap()), (1, 3, MAX_SAMPLES - 1), "every other one, end to end");
    }
}
