//! Building devices from a recording (`mbtap simulate --from CAPTURE`): an analyzer sink fed by
//! the one replay every command uses, keeping per unit what [`super::recorded::RecordedDevice`]
//! answers from — the register image, the refusals, verbatim answers, latencies, and the values'
//! time course for `--replay-values`. Every store is bounded: a recording of ever-new requests
//! cannot grow memory without end.

use std::collections::BTreeMap;

use super::recorded::{Latency, RecordedDevice, carries_registers, refusal_key};
use crate::analyzer::{Event, Sink};
use crate::pairing::{Outcome, ShownLatency};
use crate::profile::format::Table;
use crate::profile::image::RegisterImage;

/// Answers kept verbatim per device (requests of functions without registers, by their PDU).
const MAX_VERBATIM: usize = 1024;
/// Refusals kept per device, by (function, start address, quantity).
const MAX_REFUSALS: usize = 65_536;
/// Latencies kept per device for its median and spread (the most recent).
const MAX_LATENCIES: usize = 4096;
/// Values of the time course kept in all (16 bytes each: 16 MiB).
const MAX_COURSE: usize = 1 << 20;

/// What one unit showed in the recording.
#[derive(Debug, Clone, Default)]
struct UnitLog {
    /// `(function, address, quantity)` → exception code, for requests the device refused.
    refusals: BTreeMap<(u8, u16, u16), u8>,
    /// Request PDU → response PDU, for functions that carry no registers.
    verbatim: BTreeMap<Vec<u8>, Vec<u8>>,
    latencies: Vec<u64>,
    /// Where the next latency goes once `latencies` is full (a ring of the most recent).
    latency_at: usize,
    answered: u64,
    unanswered: u64,
}

/// Builds devices from a recording's transactions (an [`Sink`] for [`crate::replay::replay_into`]).
#[derive(Debug, Default)]
pub struct Recorder {
    image: RegisterImage,
    units: BTreeMap<u8, UnitLog>,
    /// Every value set, when: (ns from the first transaction, unit, table, address, value).
    course: Vec<(u64, u8, Table, u16, u16)>,
    first_ns: Option<u64>,
    /// What the replay warned about (a damaged block), said to the user by the caller.
    pub warnings: Vec<String>,
}

impl Sink for Recorder {
    fn event(&mut self, event: &Event<'_>) {
        if let Event::Transaction(t) = event {
            self.transaction(t);
        }
    }

    fn warning(&mut self, message: &str) {
        if self.warnings.len() < 16 {
            self.warnings.push(message.to_owned());
        }
    }
}

impl Recorder {
    /// Takes in one transaction as the pairing gave it.
    pub fn transaction(&mut self, t: &crate::pairing::Transaction<'_>) {
        let Some(request) = t.request_pdu else { return };
        if t.unit == 0 || t.unit > 247 {
            return;
        }
        let log = self.units.entry(t.unit).or_default();
        match (t.outcome, t.response_pdu) {
            (Outcome::Ok, Some(response)) => {
                log.answered += 1;
                let function = request.first().copied().unwrap_or(0);
                if !carries_registers(function) && log.verbatim.len() < MAX_VERBATIM {
                    log.verbatim.insert(request.to_vec(), response.to_vec());
                }
                self.image.update(t.unit, t.t_start.0, request, Some(response));
                let since = t.t_start.0.saturating_sub(*self.first_ns.get_or_insert(t.t_start.0));
                for &(unit, table, address) in self.image.touched() {
                    if self.course.len() < MAX_COURSE
                        && let Some(k) = self.image.values.get(&(unit, table, address))
                    {
                        self.course.push((since, unit, table, address, k.raw));
                    }
                }
            }
            (Outcome::Exception(code), _) => {
                log.answered += 1;
                let key = refusal_key(request);
                if log.refusals.len() < MAX_REFUSALS || log.refusals.contains_key(&key) {
                    log.refusals.insert(key, code);
                }
            }
            _ => {
                log.unanswered += 1;
                return;
            }
        }
        if let ShownLatency::Measured(ns) = t.shown_latency() {
            if log.latencies.len() < MAX_LATENCIES {
                log.latencies.push(ns);
            } else if let Some(slot) = log.latencies.get_mut(log.latency_at) {
                *slot = ns;
                log.latency_at = (log.latency_at + 1) % MAX_LATENCIES;
            }
        }
    }

    /// Unit `unit`'s values in their recorded time course (ns from the recording's first
    /// transaction), for [`RecordedDevice::replay_values`].
    #[must_use]
    pub fn course(&self, unit: u8) -> Vec<(u64, Table, u16, u16)> {
        self.course.iter().filter(|c| c.1 == unit).map(|&(t, _, table, a, v)| (t, table, a, v)).collect()
    }

    /// Units asked in the recording that never answered (nothing to emulate them from).
    #[must_use]
    pub fn silent_units(&self) -> Vec<u8> {
        self.units.iter().filter(|(_, l)| l.answered == 0).map(|(&u, _)| u).collect()
    }

    /// One device per unit that answered at least once, in address order.
    #[must_use]
    pub fn devices(&self) -> Vec<RecordedDevice> {
        self.units
            .iter()
            .filter(|(_, l)| l.answered > 0)
            .map(|(&unit, log)| {
                // Coils sort first and input registers last (the order of `Table`'s variants).
                let values = self
                    .image
                    .values
                    .range((unit, Table::Coils, 0)..=(unit, Table::InputRegisters, u16::MAX))
                    .map(|(&(_, table, a), k)| ((table, a), k.raw))
                    .collect();
                let mut sorted = log.latencies.clone();
                sorted.sort_unstable();
                let at = |q: usize| sorted.get(sorted.len().saturating_sub(1) * q / 100).copied();
                RecordedDevice {
                    address: unit,
                    values,
                    refusals: log.refusals.clone(),
                    verbatim: log.verbatim.clone(),
                    course: Vec::new(),
                    course_at: 0,
                    course_last_ns: 0,
                    latency: at(50).map(|median| Latency {
                        median_ns: median,
                        p10_ns: at(10).unwrap_or(median),
                        p90_ns: at(90).unwrap_or(median),
                        samples: sorted.len(),
                    }),
                    answered: log.answered,
                    unanswered: log.unanswered,
                }
            })
            .collect()
    }
}
