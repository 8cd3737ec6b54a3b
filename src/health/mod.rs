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

mod findings;
pub mod html;
mod report;

use std::collections::BTreeMap;

pub use report::{BINS, Bin, Finding, LATENCY_POINTS, LatencyPoint, Report, UnitHealth, clock};

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
}

/// a / b for percentages (counts stay far below 2^52).
#[allow(clippy::cast_precision_loss)]
pub(crate) fn ratio(a: u64, b: u64) -> f64 {
    if b == 0 { 0.0 } else { a as f64 / b as f64 }
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
