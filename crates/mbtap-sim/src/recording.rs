//! Building devices from a recording (`mbtap simulate --from CAPTURE`): an analyzer sink fed by
//! the one replay every command uses, keeping per unit what [`super::recorded::RecordedDevice`]
//! answers from — the register image, the refusals, verbatim answers, latencies, and the values'
//! time course for `--replay-values`. Every store is bounded — per unit, and in all by what it
//! takes in memory — so a recording of ever-new requests cannot grow memory without end, and
//! every unit a recording shows keeps its values: 247 units read over their whole holding and
//! input tables take 2 × 256 pages each (69 MB) under [`MAX_VALUE_BYTES`]. What a bound drops is
//! counted per unit and said ([`RecordedDevicesBuilder::bounds_said`]).

use std::collections::BTreeMap;

use super::recorded::{Latency, RecordedDevice, carries_registers, refusal_key};
use mbtap_analysis::analyzer::{Event, Sink};
use mbtap_analysis::pairing::{Outcome, ShownLatency};
use mbtap_device::profile::format::Table;
use mbtap_device::profile::image::RegisterImage;

use crate::store::{PAGE_BYTES, Values};

/// Answers kept verbatim per device (requests of functions without registers, by their PDU).
const MAX_VERBATIM: usize = 1024;
/// Refusals kept per device, by (function, start address, quantity).
const MAX_REFUSALS: usize = 65_536;
/// Latencies kept per device for its median and spread (the most recent).
const MAX_LATENCIES: usize = 4096;
/// Refusals kept in all units together (about 40 bytes each: 10 MiB).
const MAX_REFUSALS_ALL: usize = 1 << 18;
/// Values of the time course kept in all (16 bytes each: 16 MiB).
pub const MAX_COURSE: usize = 1 << 20;
/// Memory the units' values may take in all, in pages of [`PAGE_BYTES`]: every unit of a line
/// (247) over whole holding and input tables fits, with room to spare.
pub const MAX_VALUE_BYTES: usize = 96 << 20;

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
    /// The values it showed, as last heard.
    values: Values,
    /// Values and refusals it showed that the bounds in all dropped.
    values_dropped: u64,
    refusals_dropped: u64,
}

/// Builds devices from a recording's transactions (an [`Sink`] for [`mbtap_analysis::replay::replay_into`]).
#[derive(Debug, Default)]
pub struct RecordedDevicesBuilder {
    /// Decodes each transaction's values; emptied after each into the units' stores.
    image: RegisterImage,
    units: BTreeMap<u8, UnitLog>,
    /// Value pages held by all units, and refusals kept by all units.
    pages: usize,
    refusals: usize,
    /// Time course values past [`MAX_COURSE`], not kept.
    course_dropped: u64,
    /// Every value set, when: (ns from the first transaction, unit, table, address, value).
    course: Vec<(u64, u8, Table, u16, u16)>,
    first_ns: Option<u64>,
    /// What the replay warned about (a damaged block), said to the user by the caller.
    pub warnings: Vec<String>,
}

impl Sink for RecordedDevicesBuilder {
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

impl RecordedDevicesBuilder {
    /// Takes in one transaction as the pairing gave it.
    pub fn transaction(&mut self, t: &mbtap_analysis::pairing::Transaction<'_>) {
        let Some(request) = t.request_pdu else { return };
        if t.unit == 0 || t.unit > 247 {
            return;
        }
        let log = self.units.entry(t.unit).or_default();
        let answer = match (t.outcome, t.response_pdu) {
            (Outcome::Ok, Some(response)) => {
                log.answered += 1;
                let function = request.first().copied().unwrap_or(0);
                if !carries_registers(function) && log.verbatim.len() < MAX_VERBATIM {
                    log.verbatim.insert(request.to_vec(), response.to_vec());
                }
                Some(response)
            }
            (Outcome::Exception(code), _) => {
                log.answered += 1;
                let key = refusal_key(request);
                if log.refusals.contains_key(&key) {
                    log.refusals.insert(key, code);
                } else if log.refusals.len() < MAX_REFUSALS && self.refusals < MAX_REFUSALS_ALL {
                    log.refusals.insert(key, code);
                    self.refusals += 1;
                } else {
                    log.refusals_dropped += 1;
                }
                None
            }
            _ => {
                log.unanswered += 1;
                return;
            }
        };
        if let ShownLatency::Measured(ns) = t.shown_latency() {
            if log.latencies.len() < MAX_LATENCIES {
                log.latencies.push(ns);
            } else if let Some(slot) = log.latencies.get_mut(log.latency_at) {
                *slot = ns;
                log.latency_at = (log.latency_at + 1) % MAX_LATENCIES;
            }
        }
        if let Some(response) = answer {
            self.keep_values(t.unit, t.t_start.0, request, response);
        }
    }

    /// The values an answered request set (a read's answer, a write's request), into each
    /// unit's store and the time course, as far as the bounds allow.
    fn keep_values(&mut self, unit: u8, t_ns: u64, request: &[u8], response: &[u8]) {
        self.image.update(unit, t_ns, request, Some(response));
        let since = t_ns.saturating_sub(*self.first_ns.get_or_insert(t_ns));
        let touched: Vec<(u8, Table, u16)> = self.image.touched().to_vec();
        for (unit, table, address) in touched {
            let Some(raw) = self.image.values.remove(&(unit, table, address)).map(|k| k.raw) else { continue };
            if self.course.len() < MAX_COURSE {
                self.course.push((since, unit, table, address, raw));
            } else {
                self.course_dropped += 1;
            }
            let log = self.units.entry(unit).or_default();
            if log.values.needs_page(table, address) {
                if (self.pages + 1) * PAGE_BYTES > MAX_VALUE_BYTES {
                    log.values_dropped += 1;
                    continue;
                }
                self.pages += 1;
            }
            log.values.insert(table, address, raw);
        }
        // The image only decodes: the units' stores hold the values.
        self.image.values.clear();
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

    /// What the bounds dropped, one line each, with what to do: values and refusals per unit.
    /// Empty when everything was kept.
    #[must_use]
    pub fn bounds_said(&self) -> Vec<String> {
        let mut said = Vec::new();
        let per_unit = |what: fn(&UnitLog) -> u64| {
            self.units
                .iter()
                .filter(|(_, l)| what(l) > 0)
                .map(|(u, l)| format!("unit {u}: {}", what(l)))
                .collect::<Vec<_>>()
        };
        let values = per_unit(|l| l.values_dropped);
        if !values.is_empty() {
            said.push(format!(
                "values past the {} MiB the emulated units may hold in all were not kept ({}); those addresses answer exception 02; give fewer units with CAPTURE@UNITS",
                MAX_VALUE_BYTES >> 20,
                values.join(", ")
            ));
        }
        let refusals = per_unit(|l| l.refusals_dropped);
        if !refusals.is_empty() {
            said.push(format!(
                "refusals past {MAX_REFUSALS} per unit or {MAX_REFUSALS_ALL} in all were not kept ({}); those requests get the unit's usual answer for addresses it never showed",
                refusals.join(", ")
            ));
        }
        said
    }

    /// With `--replay-values`: what the time course's bound dropped, if anything.
    #[must_use]
    pub fn course_said(&self) -> Option<String> {
        (self.course_dropped > 0).then(|| {
            format!(
                "--replay-values: the recording's time course holds {} values more than the {MAX_COURSE} kept; the values replay up to the last kept change, then loop",
                self.course_dropped
            )
        })
    }

    /// One device per unit that answered at least once, in address order; each takes its values
    /// from the recorder (they are not held twice).
    #[must_use]
    pub fn take_devices(&mut self) -> Vec<RecordedDevice> {
        self.units
            .iter_mut()
            .filter(|(_, l)| l.answered > 0)
            .map(|(&unit, log)| {
                let values = std::mem::take(&mut log.values);
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

#[cfg(test)]
mod tests {
    use super::super::recorded::RecordedDevice;
    use super::*;
    use mbtap_analysis::chunk::Timestamp;
    use mbtap_analysis::pairing::{Outcome, Transaction};

    /// FC 03 at 100, 2 registers (MAP v1.1b3 §6.3).
    const READ_100_2: [u8; 5] = [/* fc */ 0x03, /* address */ 0x00, 0x64, /* quantity */ 0x00, 0x02];
    /// Its answer: 4 bytes, 0x1234 and 0x5678.
    const ANSWER_100_2: [u8; 6] = [/* fc */ 0x03, /* bytes */ 4, 0x12, 0x34, 0x56, 0x78];
    /// FC 04 at 7, 1 register, and the device's exception 02 to it (MAP v1.1b3 §7).
    const READ_INPUT_7: [u8; 5] = [/* fc */ 0x04, /* address */ 0x00, 0x07, /* quantity */ 0x00, 0x01];
    const REFUSED_02: [u8; 2] = [/* fc | 0x80 */ 0x84, /* code */ 0x02];
    /// FC 04 at 8, 1 register, answered 0x0102: input registers sort after holding ones.
    const READ_INPUT_8: [u8; 5] = [/* fc */ 0x04, /* address */ 0x00, 0x08, /* quantity */ 0x00, 0x01];
    const ANSWER_INPUT_8: [u8; 4] = [/* fc */ 0x04, /* bytes */ 2, 0x01, 0x02];
    /// FC 11 Report Server ID and an answer (MAP v1.1b3 §6.13): byte count 3, id 0x42, run 0xFF, "A".
    const REPORT_ID: [u8; 1] = [/* fc */ 0x11];
    const REPORT_ID_ANSWER: [u8; 5] =
        [/* fc */ 0x11, /* bytes */ 3, /* id */ 0x42, /* run */ 0xFF, b'A'];
    /// FC 05 coil 3 ON (MAP v1.1b3 §6.5): never heard, so refused as the device never showed it.
    const COIL_3_ON: [u8; 5] = [/* fc */ 0x05, /* address */ 0x00, 0x03, /* value */ 0xFF, 0x00];

    fn transaction<'a>(
        unit: u8,
        request: &'a [u8],
        response: Option<&'a [u8]>,
        outcome: Outcome,
        latency_ns: u64,
    ) -> Transaction<'a> {
        Transaction {
            outcome,
            unit,
            function: request[0],
            request: Some(request),
            response,
            request_pdu: Some(request),
            response_pdu: response,
            t_start: Timestamp(1),
            latency_ns: Some(latency_ns),
            latency_resolution_ns: 0,
            input_ended: false,
        }
    }

    fn recorded() -> RecordedDevice {
        let mut r = RecordedDevicesBuilder::default();
        r.transaction(&transaction(9, &READ_100_2, Some(&ANSWER_100_2), Outcome::Ok, 4_000_000));
        r.transaction(&transaction(9, &READ_INPUT_7, Some(&REFUSED_02), Outcome::Exception(2), 6_000_000));
        r.transaction(&transaction(9, &REPORT_ID, Some(&REPORT_ID_ANSWER), Outcome::Ok, 5_000_000));
        r.transaction(&transaction(9, &READ_INPUT_8, Some(&ANSWER_INPUT_8), Outcome::Ok, 5_000_000));
        // Unit 10's value at input register 8 stays unit 10's.
        r.transaction(&transaction(10, &READ_INPUT_8, Some(&[0x04, 2, 0xFF, 0xFF]), Outcome::Ok, 1));
        r.transaction(&transaction(3, &READ_100_2, None, Outcome::NoResponse, 0));
        assert_eq!(r.silent_units(), [3], "unit 3 was asked, never answered");
        let mut devices = r.take_devices();
        assert_eq!(devices.iter().map(RecordedDevice::address).collect::<Vec<_>>(), [9, 10]);
        devices.remove(0)
    }

    /// 247 units, each read over 4 500 holding and 4 500 input registers in blocks of 125 (the most
    /// FC 03/04 carries, MAP v1.1b3 §6.3) — 2.2 M values, twice what one store shared by all units
    /// could hold: every unit keeps every value, none loses its values to the units before it. (247
    /// units over their whole tables: `BENCHMARKS.md`, the release binary's peak RSS; their pages
    /// fit the bound, `a_full_line_over_whole_tables_fits_the_bound`.)
    #[test]
    fn every_unit_of_a_full_line_keeps_its_values() {
        const SPAN: u16 = 4_500;
        let mut r = RecordedDevicesBuilder::default();
        let mut answer = Vec::with_capacity(2 + 250);
        for unit in 1..=247u8 {
            for function in [0x03u8, 0x04] {
                for start in (0..SPAN).step_by(125) {
                    let quantity: u16 = 125;
                    let [ah, al] = start.to_be_bytes();
                    let [qh, ql] = quantity.to_be_bytes();
                    let request = [function, ah, al, qh, ql];
                    answer.clear();
                    answer.extend([function, u8::try_from(quantity * 2).unwrap()]);
                    for a in (0..quantity).map(|i| start + i) {
                        answer.extend((a ^ u16::from(unit)).to_be_bytes());
                    }
                    r.transaction(&transaction(unit, &request, Some(&answer), Outcome::Ok, 1_000_000));
                }
            }
        }
        assert!(r.bounds_said().is_empty(), "{:?}", r.bounds_said());
        let devices = r.take_devices();
        assert_eq!(devices.len(), 247);
        for d in &devices {
            let u = u16::from(d.address());
            assert_eq!(d.counts()[3], (Table::HoldingRegisters, usize::from(SPAN)), "unit {u}");
            for a in [0, 1, 2_222, SPAN - 1] {
                assert_eq!(d.get(Table::HoldingRegisters, a), Some(a ^ u), "unit {u} holding {a}");
                assert_eq!(d.get(Table::InputRegisters, a), Some(a ^ u), "unit {u} input {a}");
            }
        }
    }

    #[test]
    fn a_full_line_over_whole_tables_fits_the_bound() {
        // 247 units × 2 tables × 256 pages of 256 addresses.
        let pages = 247 * 2 * (65_536 / 256);
        assert!(pages * PAGE_BYTES <= MAX_VALUE_BYTES, "{} MB", (pages * PAGE_BYTES) >> 20);
    }

    /// Past the bound in bytes, what is dropped is counted for the unit it belonged to and said.
    #[test]
    fn values_past_the_bound_are_said_per_unit() {
        let mut r = RecordedDevicesBuilder { pages: MAX_VALUE_BYTES / PAGE_BYTES, ..RecordedDevicesBuilder::default() };
        r.transaction(&transaction(12, &READ_100_2, Some(&ANSWER_100_2), Outcome::Ok, 1));
        let said = r.bounds_said();
        assert!(said.len() == 1 && said[0].contains("unit 12: 2") && said[0].contains("CAPTURE@UNITS"), "{said:?}");
    }

    #[test]
    fn answers_what_the_recording_showed() {
        let mut d = recorded();
        assert_eq!(d.handle(9, &READ_100_2).unwrap(), ANSWER_100_2);
        assert_eq!(d.handle(9, &READ_INPUT_7).unwrap(), REFUSED_02, "the recorded exception");
        assert_eq!(d.handle(9, &REPORT_ID).unwrap(), REPORT_ID_ANSWER, "FC 11 as recorded");
        assert_eq!(d.handle(9, &READ_INPUT_8).unwrap(), ANSWER_INPUT_8, "input registers too");
        assert_eq!(d.handle(8, &READ_100_2), None, "another unit's request");
        let latency = d.latency.unwrap();
        assert_eq!((latency.median_ns, latency.samples), (5_000_000, 4));
    }

    #[test]
    fn what_was_never_heard_is_refused_not_invented() {
        let mut d = recorded();
        // 100–102: 102 was never heard.
        assert_eq!(d.handle(9, &[0x03, 0x00, 0x64, 0x00, 0x03]).unwrap(), [0x83, 0x02]);
        // A function never heard at all.
        assert_eq!(d.handle(9, &COIL_3_ON).unwrap(), [0x85, 0x02], "a coil never heard: 02");
        assert_eq!(d.handle(9, &[0x2B, 0x0E, 0x01, 0x00]).unwrap(), [0xAB, 0x01], "identity never asked: 01");
        // A read overlapping the recorded refusal is not that request: 02, as anything unheard.
        assert_eq!(d.handle(9, &[0x04, 0x00, 0x06, 0x00, 0x02]).unwrap(), [0x84, 0x02]);
    }

    #[test]
    fn writes_to_heard_registers_are_kept() {
        let mut d = recorded();
        let write = [/* fc */ 0x06, /* address */ 0x00, 0x65, /* value */ 0xAB, 0xCD];
        assert_eq!(d.handle(9, &write).unwrap(), write, "the echo is the request (MAP v1.1b3 §6.6)");
        assert_eq!(d.get(Table::HoldingRegisters, 101), Some(0xABCD));
        assert_eq!(d.handle(0, &[0x06, 0x00, 0x64, 0x00, 0x01]), None, "broadcast: acted on, silent");
        assert_eq!(d.get(Table::HoldingRegisters, 100), Some(1));
    }

    #[test]
    fn any_bytes_never_panic() {
        let mut d = recorded();
        for f in 0..=255u8 {
            for len in 0..8usize {
                let pdu: Vec<u8> =
                    std::iter::once(f).chain((0..len).map(|i| u8::try_from(i * 91 % 256).unwrap())).collect();
                let _ = d.handle(9, &pdu);
                let _ = d.handle(0, &pdu);
            }
        }
    }
}
