//! The bus health report: what is wrong with a bus, each finding with its evidence (which
//! transactions, when), per unit and for the whole bus. Pure: analyzer events in, a report out;
//! `mbtap report FILE` feeds it a capture.
//!
//! Findings (stable `kind` names): `check_errors` (failed CRC/LRC, per unit or, when every unit
//! suffers, the bus), `noise`, `wrong_line_settings` (mostly garbage, few valid frames),
//! `gap_inside_frame` (t1.5 violations, Serial Line v1.02 §2.5.1.1), `fast_master` (requests
//! after less than t3.5), `second_master` (requests sent while another request's answer was
//! due, which then came), `no_response` (always or intermittently), `late_answer` (answers
//! after the master moved on), `duplicate_address` (answers that come twice, or garbled the
//! way two answers on top of each other garble), `implausible_jump` (a reading moving over half
//! its documented range between two reads), `exception_storm`, `value_out_of_range` (outside
//! the profile's range), `turnaround_glitch` (a garbage byte right after the frames of one
//! sender: the line is not biased), `fast_answer` (a unit answering less than t3.5 after the
//! request), `no_valid_frames` (nothing heard, or nothing that frames: never "healthy").
//! Check errors say whether they come in bursts or steadily; a damaged answer counts against a
//! unit only when its address byte is the unit's.
//!
//! Modules: `margins` (timing evidence with its margin), `findings` (from the figures to the
//! findings and per-unit figures), `html` (the report as one self-contained page).

mod findings;
pub mod html;
mod margins;
mod report;
mod transactions;

use std::collections::BTreeMap;

pub use report::{BINS, Bin, Finding, LATENCY_POINTS, LatencyPoint, Report, UnitHealth, clock, severity};

use crate::analyzer::Event;
use crate::pairing::Role;
use mbtap_device::profile::Profiles;
use mbtap_device::profile::annotate::Annotation;

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

#[derive(Debug, Default, Clone)]
struct Tally {
    count: u64,
    first: u64,
    last: u64,
    evidence: Vec<u64>,
}

impl Tally {
    /// Both tallies as one: counts added, the earliest evidence kept.
    fn merged(&self, other: &Self) -> Self {
        let mut evidence: Vec<u64> = self.evidence.iter().chain(&other.evidence).copied().collect();
        evidence.sort_unstable();
        evidence.truncate(EVIDENCE);
        let first = match (self.count, other.count) {
            (0, _) => other.first,
            (_, 0) => self.first,
            _ => self.first.min(other.first),
        };
        Self { count: self.count + other.count, first, last: self.last.max(other.last), evidence }
    }

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
    gaps: margins::Margins,
    out_of_range: Tally,
    /// The first few registers and values outside their range, for the finding's sentence.
    out_of_range_examples: Vec<String>,
    /// Answers that came twice: two devices on one address.
    doubled: Tally,
    /// Answers garbled the way two devices answering together garble them.
    collided: Tally,
    /// Answers that came after the master had moved on to another request.
    late: Tally,
    /// The longest such answer's latency, and the shortest time the master waited.
    late_latency_max: u64,
    master_wait_min: Option<u64>,
    /// Readings that moved more than half their documented range from one read to the next.
    jumps: Tally,
    /// Valid frames this unit sent, and the turnaround glitches right after them.
    sent: u64,
    glitches: Tally,
    /// Answers that began less than t3.5 after the request (Serial Line v1.02 §2.5.1.1).
    fast_answers: margins::Margins,
    /// Requests answered only by a damaged frame whose address is not this unit's.
    unclear: u64,
    /// The last raw reading of each documented value with a range.
    last_values: BTreeMap<(mbtap_device::profile::Table, u16), i64>,
    latencies: Vec<u64>,
    /// A smoothed latency of answers on time (1/8 of each new one).
    typical_latency: Option<u64>,
    /// Per distinct request (up to [`MAX_POLLS`]): when it was last asked and its last good answer.
    polls: BTreeMap<Vec<u8>, Poll>,
    /// Time between one request and the next identical one: the polling period.
    periods: Vec<u64>,
}

#[derive(Debug, Default)]
struct Poll {
    last_t: u64,
    answer: Option<Vec<u8>>,
}

/// Distinct requests remembered per unit (a master polls a handful; a scanner sweeping
/// addresses must not grow memory without bound).
const MAX_POLLS: usize = 64;
/// Below this, no master has given up on its request: a new request this soon after one that
/// is then answered comes from another master. (Above the unit's typical latency too.)
const SECOND_MASTER_GAP_NS: u64 = 10_000_000;

/// A request waiting for its answer, as the health collector follows pairing.
#[derive(Debug, Clone, Copy)]
struct Asked {
    unit: u8,
    t_start: u64,
    t_end: u64,
    /// When the next request came, if one overtook this one.
    overtaken_at: Option<u64>,
}

/// Collects events into a report.
#[derive(Debug, Default)]
pub struct Health {
    units: BTreeMap<u8, UnitState>,
    /// Noise bursts: bytes the framer could read as no frame (the same count `replay` gives).
    noise: Tally,
    noise_bytes: u64,
    /// Frames that failed their check while no answer was awaited: garbage that only looked
    /// like a frame, counted apart from noise so every output means the same by "noise"
    /// (the report counted them as noise bursts, replay as failed frames).
    stray: Tally,
    stray_bytes: u64,
    frame_bytes: u64,
    frames: u64,
    bad_frames: u64,
    fast_master: margins::Margins,
    second_master: Tally,
    /// Failed frames taking a request's place whose address is not the asked unit's: damage
    /// the bus suffered, not evidence against a unit.
    bus_bad: Tally,
    /// Valid requests the master sent, and the turnaround glitches right after them.
    master_sent: u64,
    master_glitches: Tally,
    /// Who sent the last valid frame (a glitch right after it is that sender's driver
    /// switching off): the master, or a unit answering.
    last_sender: Option<Sender>,
    transactions: u64,
    first: Option<u64>,
    last: Option<u64>,
    profiles: Profiles,
    /// (time, unit, latency, class) of every transaction, and the noise times, for the plots.
    samples: Vec<Sample>,
    noise_times: Vec<u64>,
    /// The request waiting for its answer (a frame that fails its check now is that answer —
    /// pairing reports it; one that fails while nothing waits is noise that looked like a
    /// frame), and one it overtook, as pairing keeps them.
    pending: Option<Asked>,
    overtaken: Option<Asked>,
    /// The last transaction, when it was answered (unit, function, time) and nothing failed
    /// its check since: an orphan answer matching it is the same request answered twice.
    last_ok: Option<(u8, u8, u64)>,
    /// Per port: the resolution of its reads (ns) as its frames said, and as its framer finally
    /// learned it (told by [`Health::observer`]; that one wins).
    resolution_streamed: BTreeMap<u8, u64>,
    resolution_final: BTreeMap<u8, u64>,
    /// A frame has passed its check: the listener is in step with the line.
    in_step: bool,
    /// Garbage before that, up to one longest frame: the listener started in the middle of a
    /// frame, which says nothing about the bus.
    cut_at_start: u64,
}

/// The longest frame on the wire (an ASCII frame: 513 characters, Modbus over Serial Line
/// v1.02 §2.5.2.1): garbage up to this much before the first good frame is a frame the
/// listener joined halfway.
const JOINED_MID_FRAME: u64 = 513;

/// The sender of a frame on a half-duplex bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sender {
    Master,
    Unit(u8),
}

/// How a transaction ended, for the plots and the clustering of errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    Answered,
    Unanswered,
    FailedCheck,
}

#[derive(Debug, Clone, Copy)]
struct Sample {
    t: u64,
    unit: u8,
    latency: Option<u64>,
    class: Class,
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
        self.event_annotated(e, None);
    }

    /// As [`Self::event`], with the annotations of an answered transaction when the caller has
    /// already made them from the same profiles (the UI and the transcript do), so they are
    /// not made twice.
    pub fn event_annotated(&mut self, e: &Event<'_>, annotations: Option<&[Annotation]>) {
        match *e {
            Event::Frame { frame, role, unit, .. } => self.frame(frame, role, unit),
            Event::Noise(n) => {
                self.seen(n.t_end.0);
                self.garbage(n.t_start.0, n.bytes.len());
            }
            Event::Glitch(n) => {
                self.seen(n.t_end.0);
                match self.last_sender {
                    Some(Sender::Unit(u)) => self.units.entry(u).or_default().glitches.add(n.t_start.0),
                    Some(Sender::Master) => self.master_glitches.add(n.t_start.0),
                    // The framer reports a glitch only right after a frame; without a valid one
                    // before it, it is a byte of noise.
                    None => self.garbage(n.t_start.0, n.bytes.len()),
                }
            }
            Event::Transaction(t) => self.transaction(t, annotations),
        }
    }

    /// Bytes that belong to no valid frame, `len` of them from `t`: whether they count (false
    /// when they come before the first good frame, within one frame's length in all — the frame
    /// the listener joined halfway, which says nothing about the bus); counted ones are put on
    /// the errors-over-time plot.
    fn counts_as_garbage(&mut self, t: u64, len: u64) -> bool {
        if !self.in_step && self.cut_at_start + len <= JOINED_MID_FRAME {
            self.cut_at_start += len;
            return false;
        }
        thin(&mut self.noise_times);
        self.noise_times.push(t);
        true
    }

    /// `len` bytes of noise from `t` (see [`Self::counts_as_garbage`]).
    fn garbage(&mut self, t: u64, len: usize) {
        let len = len as u64;
        if self.counts_as_garbage(t, len) {
            self.noise.add(t);
            self.noise_bytes += len;
        }
    }

    /// A failed frame nothing awaited, `len` bytes from `t`: a stray (see
    /// [`Self::counts_as_garbage`]).
    fn stray_frame(&mut self, t: u64, len: usize) {
        let len = len as u64;
        if self.counts_as_garbage(t, len) {
            self.stray.add(t);
            self.stray_bytes += len;
        }
    }

    fn frame(&mut self, frame: &crate::framer::Frame<'_>, role: Role, unit: Option<u8>) {
        self.seen(frame.t_end.0);
        self.frames += 1;
        self.frame_bytes += frame.bytes.len() as u64;
        self.in_step |= frame.check_ok;
        self.last_sender = match (frame.check_ok, role, unit) {
            (true, Role::Request, _) => {
                self.master_sent += 1;
                Some(Sender::Master)
            }
            (true, Role::Response | Role::Unknown, Some(u)) => {
                self.units.entry(u).or_default().sent += 1;
                Some(Sender::Unit(u))
            }
            _ => None,
        };
        if !frame.check_ok {
            self.bad_frames += 1;
            self.last_ok = None;
            if self.pending.is_none() {
                // Nothing awaited an answer: garbage that only looked like a frame.
                self.stray_frame(frame.t_start.0, frame.bytes.len());
            }
        }
        if frame.check_ok
            && role == Role::Request
            && let Some(u) = unit.filter(|&u| u != 0)
        {
            // Pairing keeps the request this one overtakes (and gives up an older one).
            self.overtaken = self.pending.take().map(|p| Asked { overtaken_at: Some(frame.t_start.0), ..p });
            self.pending = Some(Asked { unit: u, t_start: frame.t_start.0, t_end: frame.t_end.0, overtaken_at: None });
        }
        self.resolution_streamed.insert(frame.port.0, frame.resolution_ns);
        // Timing evidence is kept with its margin and judged at report time against the
        // observer's resolution (a 16 ms USB timer's delays were blamed on every unit).
        // A failed frame's address byte names its unit only where that unit was awaited: else
        // the byte may be the damage itself (a garbled answer's `A7` made a unit 167
        // row, availability 0.0 %, in the report of a bus that has no unit 167).
        let named = |u: u8| frame.check_ok || self.pending.as_ref().is_some_and(|p| p.unit == u);
        if let (Some(m), Some(u)) = (frame.gap_tolerance_ns, unit.filter(|&u| named(u))) {
            self.units.entry(u).or_default().gaps.add(m, frame.t_start.0);
        }
        if let Some(m) = frame.short_gap_tolerance_ns {
            match (role, unit) {
                (Role::Request, _) => self.fast_master.add(m, frame.t_start.0),
                (Role::Response, Some(u)) if frame.check_ok => {
                    self.units.entry(u).or_default().fast_answers.add(m, frame.t_start.0);
                }
                _ => {}
            }
        }
    }

    /// What a port's framer finally learned about its reads (at the end of the input): timing
    /// findings are judged with its resolution.
    pub fn observer(&mut self, port: crate::chunk::PortId, estimate: &crate::framer::ObserverEstimate) {
        self.resolution_final.insert(port.0, estimate.resolution_ns());
    }

    /// The resolution timing findings are judged with: the coarsest port's (ns).
    fn resolution_ns(&self) -> u64 {
        let streamed = self.resolution_streamed.iter().filter(|(p, _)| !self.resolution_final.contains_key(p));
        self.resolution_final.iter().chain(streamed).map(|(_, &r)| r).max().unwrap_or(0)
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
