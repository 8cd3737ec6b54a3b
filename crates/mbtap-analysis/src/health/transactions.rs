//! What a paired transaction tells the health report: late, missing and exception answers, the
//! poll a unit answers, a second master, and values outside what the unit's profile allows.

use super::{Class, DOUBLED_WITHIN_NS, Health, MAX_POLLS, SECOND_MASTER_GAP_NS, Sample, UnitState, thin};
use crate::pairing::Outcome;
use mbtap_device::profile::annotate::{Annotation, Note};

impl Health {
    pub(super) fn transaction(&mut self, t: &crate::pairing::Transaction<'_>, annotations: Option<&[Annotation]>) {
        let at = t.t_start.0;
        if self.pending.is_some_and(|p| p.t_start == at) {
            self.pending = None;
        }
        let overtaken = self.overtaken.filter(|p| p.t_start == at && p.unit == t.unit);
        if overtaken.is_some() {
            self.overtaken = None;
        }
        self.seen(at);
        if t.input_ended {
            // Cut off by the end of the capture, not evidence of a silent unit.
            return;
        }
        self.transactions += 1;
        if t.outcome == Outcome::Broadcast {
            // Addressed to everyone, answered by no one: not a unit's figures.
            return;
        }
        // A damaged answer counts against the unit only when its address byte says it is the
        // unit's: otherwise the bus damaged something nobody can name.
        let unclear = t.outcome == Outcome::BadResponse && t.response.and_then(<[u8]>::first) != Some(&t.unit);
        if unclear {
            self.bus_bad.add(at);
        }
        let u = self.units.entry(t.unit).or_default();
        u.transactions += 1;
        u.unclear += u64::from(unclear);
        let previous = self.last_ok.take();
        let answered = matches!(t.outcome, Outcome::Ok | Outcome::Exception(_));
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
            Outcome::BadResponse if t.response.and_then(<[u8]>::first) == Some(&t.unit) => u.bad_response.add(at),
            Outcome::BadResponse | Outcome::Broadcast | Outcome::Orphan | Outcome::WrongUnit(_) => {}
        }
        if let (Some(l), Some(p), true) = (t.latency_ns, overtaken, answered) {
            // Answered after another request went out: which master sent that one?
            let waited = p.overtaken_at.unwrap_or(p.t_end).saturating_sub(p.t_end);
            if waited < u.typical_latency.unwrap_or(0).max(SECOND_MASTER_GAP_NS) {
                self.second_master.add(p.overtaken_at.unwrap_or(at));
            } else {
                u.late.add(at);
                u.late_latency_max = u.late_latency_max.max(l);
                u.master_wait_min = Some(u.master_wait_min.map_or(waited, |m| m.min(waited)));
            }
        } else if let (Some(l), true) = (t.latency_ns, answered) {
            u.typical_latency = Some(u.typical_latency.map_or(l, |m| (m * 7 + l) / 8));
        }
        if let Some(l) = t.latency_ns {
            thin(&mut u.latencies);
            u.latencies.push(l);
        }
        if let Some(req) = t.request {
            Self::remember_poll(u, at, req, t);
        }
        let class = match t.outcome {
            Outcome::NoResponse => Class::Unanswered,
            Outcome::BadResponse => Class::FailedCheck,
            _ => Class::Answered,
        };
        thin(&mut self.samples);
        self.samples.push(Sample { t: at, unit: t.unit, latency: t.latency_ns, class });
        if t.outcome == Outcome::Ok {
            self.check_values(t, annotations);
        }
    }

    /// The polling period, and garbled answers that look like two devices answering at once:
    /// compared with the last good answer to the same request, a wired-AND collision only
    /// clears bits (a dominant 0 wins on RS-485), where noise flips them both ways.
    pub(super) fn remember_poll(u: &mut UnitState, at: u64, request: &[u8], t: &crate::pairing::Transaction<'_>) {
        if u.polls.len() >= MAX_POLLS && !u.polls.contains_key(request) {
            return;
        }
        let poll = u.polls.entry(request.to_vec()).or_default();
        if poll.last_t != 0 && at > poll.last_t {
            thin(&mut u.periods);
            u.periods.push(at - poll.last_t);
        }
        poll.last_t = at;
        match (t.outcome, t.response, &poll.answer) {
            (Outcome::Ok, Some(r), _) => poll.answer = Some(r.to_vec()),
            (Outcome::BadResponse, Some(bad), Some(good)) if looks_collided(good, bad) => u.collided.add(at),
            _ => {}
        }
    }

    /// Values outside the profile's range, and readings that jump.
    pub(super) fn check_values(&mut self, t: &crate::pairing::Transaction<'_>, given: Option<&[Annotation]>) {
        let (Some(p), Some(req)) = (self.profiles.get(&t.unit), t.request_pdu) else { return };
        let Some(u) = self.units.get_mut(&t.unit) else { return };
        let at = t.t_start.0;
        let made;
        let annotations = if let Some(a) = given {
            a
        } else {
            made = mbtap_device::profile::transaction::annotate_pdus(p, req, t.response_pdu);
            &made
        };
        if annotations.iter().any(|a| a.notes.iter().any(|n| matches!(n, Note::OutOfRange { .. }))) {
            u.out_of_range.add(at);
            // Which register and value (the finding named neither).
            for a in annotations {
                for n in &a.notes {
                    if let Note::OutOfRange { min, max } = n {
                        let example = format!(
                            "{} {}{} = raw {} (documented {min}..={max})",
                            mbtap_device::query::rows::short_table(a.table),
                            a.address,
                            a.name.as_deref().map(|n| format!(" {n}")).unwrap_or_default(),
                            a.raw
                        );
                        let key = format!("{} {}", mbtap_device::query::rows::short_table(a.table), a.address);
                        if u.out_of_range_examples.len() < 3
                            && !u.out_of_range_examples.iter().any(|e| e.starts_with(&key))
                        {
                            u.out_of_range_examples.push(example);
                        }
                    }
                }
            }
        }
        let mut jumped = false;
        for a in annotations {
            let Some((min, max)) = p.slot(a.table, a.address).and_then(|(_, def)| def.range) else {
                continue;
            };
            let is_number = matches!(a.shown, mbtap_device::profile::annotate::Shown::Number { .. });
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

/// A failed answer of the same length and header as a good one, whose payload and CRC differ
/// only by cleared bits — several of them — is two answers on top of each other.
fn looks_collided(good: &[u8], bad: &[u8]) -> bool {
    // Unit, function, byte count (Modbus over Serial Line v1.02 §2.5.1: RTU frame layout):
    // identical in both devices' answers, so the fight starts after them.
    const HEADER: usize = 3;
    if good.len() != bad.len() || good.len() <= HEADER || good.get(..HEADER) != bad.get(..HEADER) {
        return false;
    }
    let (mut cleared, mut set) = (0u32, 0u32);
    for (g, b) in good.iter().zip(bad).skip(HEADER) {
        cleared += (g & !b).count_ones();
        set += (b & !g).count_ones();
    }
    // Values move a little between two reads (and the CRC with them): allow a few set bits
    // against many cleared. A flipped bit or two of noise is not enough.
    cleared >= 3 && set * 4 <= cleared
}
