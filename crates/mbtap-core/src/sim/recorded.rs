//! A device as a recording showed it (`mbtap simulate --from CAPTURE`): the register image the
//! capture carried (the last value heard at each address, what was written included), the
//! exceptions it gave and for which requests, answers to functions that carry no registers
//! (FC 11 Report Server ID, FC 2B/0E identity, FC 08) as they were, and how long it took to
//! answer. Built by [`Recorder`], an analyzer sink fed by the one replay every command uses;
//! pure like the rest of the core.
//!
//! What the recording never showed is not invented: a read of an address never heard is
//! refused with exception 02 (MAP v1.1b3 §7), a function never heard with 01, unless the
//! recording showed the device refusing it otherwise.

use std::collections::BTreeMap;

use super::answers::{self, COIL_OFF, COIL_ON};
use crate::analyzer::{Event, Sink};
use crate::pairing::{Outcome, ShownLatency};
use crate::profile::format::Table;
use crate::profile::image::RegisterImage;
use crate::proto::{EXCEPTION_FLAG, ExceptionCode, Request, parse_request};

/// Answers kept verbatim per device (requests of functions without registers, by their PDU):
/// a recording of ever-new diagnostics requests must not grow without bound.
const MAX_VERBATIM: usize = 1024;
/// Refusals kept per device, by (function, start address, quantity).
const MAX_REFUSALS: usize = 65_536;
/// Latencies kept per device for its median and spread (the most recent).
const MAX_LATENCIES: usize = 4096;

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

/// Functions whose answers the register image holds (MAP v1.1b3 §6.1–§6.6, §6.11, §6.12, §6.17):
/// served from values, not replayed verbatim.
const fn carries_registers(function: u8) -> bool {
    matches!(function, 0x01..=0x06 | 0x0F | 0x10 | 0x17)
}

/// A refused request's key: its function, and for the register functions its start address
/// and quantity (1 for single writes), else 0.
fn refusal_key(request: &[u8]) -> (u8, u16, u16) {
    let function = request.first().copied().unwrap_or(0);
    let word = |i: usize| match (request.get(i), request.get(i + 1)) {
        (Some(&hi), Some(&lo)) => u16::from_be_bytes([hi, lo]),
        _ => 0,
    };
    match function {
        0x01..=0x04 | 0x0F | 0x10 | 0x17 => (function, word(1), word(3)),
        0x05 | 0x06 => (function, word(1), 1),
        _ => (function, 0, 0),
    }
}

/// How long the device took to answer: end of request to start of answer, as the recording's
/// reads could measure it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Latency {
    pub median_ns: u64,
    pub p10_ns: u64,
    pub p90_ns: u64,
    pub samples: usize,
}

/// One unit of a recording, answering as it did.
#[derive(Debug, Clone)]
pub struct RecordedDevice {
    address: u8,
    values: BTreeMap<(Table, u16), u16>,
    refusals: BTreeMap<(u8, u16, u16), u8>,
    verbatim: BTreeMap<Vec<u8>, Vec<u8>>,
    /// `None` when no answer's start could be measured (one read held request and answer).
    pub latency: Option<Latency>,
    pub answered: u64,
    pub unanswered: u64,
}

impl RecordedDevice {
    /// A device from a register image alone (`replay --image`, a probe dump): every value as
    /// the image holds it, no refusals, no latency.
    #[must_use]
    pub fn from_image(address: u8, values: BTreeMap<(Table, u16), u16>) -> Self {
        Self {
            address,
            values,
            refusals: BTreeMap::new(),
            verbatim: BTreeMap::new(),
            latency: None,
            answered: 0,
            unanswered: 0,
        }
    }

    /// The unit's address.
    #[must_use]
    pub const fn address(&self) -> u8 {
        self.address
    }

    /// How many addresses of each table the recording showed.
    #[must_use]
    pub fn counts(&self) -> [(Table, usize); 4] {
        [Table::Coils, Table::DiscreteInputs, Table::InputRegisters, Table::HoldingRegisters]
            .map(|t| (t, self.values.keys().filter(|(table, _)| *table == t).count()))
    }

    /// A value as the recording left it (or as written since).
    #[must_use]
    pub fn get(&self, table: Table, address: u16) -> Option<u16> {
        self.values.get(&(table, address)).copied()
    }

    /// Sets a value the recording showed (from outside: `simulate --values-from`); `false` at an
    /// address it never showed, which stays refused.
    pub fn set(&mut self, table: Table, address: u16, value: u16) -> bool {
        match self.values.get_mut(&(table, address)) {
            Some(v) => {
                *v = value;
                true
            }
            None => false,
        }
    }

    /// Requests the recording showed refused, and with which code.
    pub fn refusals(&self) -> impl Iterator<Item = ((u8, u16, u16), u8)> + '_ {
        self.refusals.iter().map(|(&k, &v)| (k, v))
    }

    /// Handles one request PDU addressed to `unit`: the response PDU, or `None` (another unit's,
    /// or a broadcast: acted on, never answered — Serial Line v1.02 §2.2).
    pub fn handle(&mut self, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        if unit != self.address && unit != super::slave::BROADCAST {
            return None;
        }
        let function = *pdu.first()?;
        let answer = self.answer(function, pdu);
        if unit == super::slave::BROADCAST {
            return None;
        }
        Some(answer.unwrap_or_else(|code| vec![function | EXCEPTION_FLAG, code]))
    }

    fn answer(&mut self, function: u8, pdu: &[u8]) -> Result<Vec<u8>, u8> {
        if let Some(&code) = self.refusals.get(&refusal_key(pdu)) {
            return Err(code);
        }
        if !carries_registers(function) {
            return match self.verbatim.get(pdu) {
                Some(answer) => Ok(answer.clone()),
                None => Err(self.refused_function(function).unwrap_or(ExceptionCode::IllegalFunction.value())),
            };
        }
        let Ok((_, request)) = parse_request(pdu) else { return Err(ExceptionCode::IllegalDataValue.value()) };
        let code = |e: ExceptionCode| e.value();
        match request {
            Request::ReadCoils { address, quantity } => self.read(Table::Coils, function, address, quantity),
            Request::ReadDiscreteInputs { address, quantity } => {
                self.read(Table::DiscreteInputs, function, address, quantity)
            }
            Request::ReadHoldingRegisters { address, quantity } => {
                self.read(Table::HoldingRegisters, function, address, quantity)
            }
            Request::ReadInputRegisters { address, quantity } => {
                self.read(Table::InputRegisters, function, address, quantity)
            }
            Request::WriteSingleCoil { address, value } => {
                if value != COIL_ON && value != COIL_OFF {
                    return Err(code(ExceptionCode::IllegalDataValue));
                }
                self.write(Table::Coils, function, address, &[u16::from(value == COIL_ON)])?;
                Ok(pdu.get(..5).unwrap_or(pdu).to_vec())
            }
            Request::WriteSingleRegister { address, value } => {
                self.write(Table::HoldingRegisters, function, address, &[value])?;
                Ok(pdu.get(..5).unwrap_or(pdu).to_vec())
            }
            Request::WriteMultipleCoils { address, quantity, values } => {
                if quantity == 0 || quantity > answers::MAX_WRITE_BITS {
                    return Err(code(ExceptionCode::IllegalDataValue));
                }
                let bits: Vec<u16> = values.iter(usize::from(quantity)).map(u16::from).collect();
                self.write(Table::Coils, function, address, &bits)?;
                Ok(answers::write_echo(function, address, quantity))
            }
            Request::WriteMultipleRegisters { address, quantity, values } => {
                if quantity == 0 || quantity > answers::MAX_WRITE_REGISTERS || values.len() != usize::from(quantity) {
                    return Err(code(ExceptionCode::IllegalDataValue));
                }
                let words: Vec<u16> = values.iter().collect();
                self.write(Table::HoldingRegisters, function, address, &words)?;
                Ok(answers::write_echo(function, address, quantity))
            }
            _ => Err(self.refused_function(function).unwrap_or(ExceptionCode::IllegalFunction.value())),
        }
    }

    /// The code the recording showed for `function` refused as a whole (01 for any request).
    fn refused_function(&self, function: u8) -> Option<u8> {
        self.refusals
            .range((function, 0, 0)..=(function, u16::MAX, u16::MAX))
            .find(|&(_, &code)| code == ExceptionCode::IllegalFunction.value())
            .map(|(_, &code)| code)
    }

    /// Every address of the range heard, else refused: 01 where the recording showed the whole
    /// function refused, else 02. (A refusal of another request overlapping this one is no
    /// evidence: a device's 03 for a block says nothing of a smaller read inside it.)
    fn covered(&self, table: Table, function: u8, address: u16, quantity: u16) -> Result<(), u8> {
        let last = answers::last_address(address, quantity).map_err(ExceptionCode::value)?;
        if (address..=last).all(|a| self.values.contains_key(&(table, a))) {
            return Ok(());
        }
        Err(self.refused_function(function).unwrap_or(ExceptionCode::IllegalDataAddress.value()))
    }

    fn read(&self, table: Table, function: u8, address: u16, quantity: u16) -> Result<Vec<u8>, u8> {
        let limit = if matches!(table, Table::Coils | Table::DiscreteInputs) {
            answers::MAX_READ_BITS
        } else {
            answers::MAX_READ_REGISTERS
        };
        if quantity == 0 || quantity > limit {
            return Err(ExceptionCode::IllegalDataValue.value());
        }
        self.covered(table, function, address, quantity)?;
        let value = |i: u16| self.get(table, address.wrapping_add(i)).unwrap_or(0);
        let answer = if limit == answers::MAX_READ_BITS {
            answers::read_bits(function, quantity, value)
        } else {
            answers::read_registers(function, quantity, value)
        };
        answer.map_err(ExceptionCode::value)
    }

    /// A write to addresses the recording showed: kept, as the device would; elsewhere refused
    /// as the recording refused it, else 02.
    fn write(&mut self, table: Table, function: u8, address: u16, values: &[u16]) -> Result<(), u8> {
        let quantity = u16::try_from(values.len()).map_err(|_| ExceptionCode::IllegalDataValue.value())?;
        self.covered(table, function, address, quantity)?;
        for (a, &v) in (address..).zip(values) {
            self.values.insert((table, a), v);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chunk::Timestamp;
    use crate::pairing::Transaction;

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
        let mut r = Recorder::default();
        r.transaction(&transaction(9, &READ_100_2, Some(&ANSWER_100_2), Outcome::Ok, 4_000_000));
        r.transaction(&transaction(9, &READ_INPUT_7, Some(&REFUSED_02), Outcome::Exception(2), 6_000_000));
        r.transaction(&transaction(9, &REPORT_ID, Some(&REPORT_ID_ANSWER), Outcome::Ok, 5_000_000));
        r.transaction(&transaction(9, &READ_INPUT_8, Some(&ANSWER_INPUT_8), Outcome::Ok, 5_000_000));
        // Unit 10's value at input register 8 stays unit 10's.
        r.transaction(&transaction(10, &READ_INPUT_8, Some(&[0x04, 2, 0xFF, 0xFF]), Outcome::Ok, 1));
        r.transaction(&transaction(3, &READ_100_2, None, Outcome::NoResponse, 0));
        assert_eq!(r.silent_units(), [3], "unit 3 was asked, never answered");
        let mut devices = r.devices();
        assert_eq!(devices.iter().map(RecordedDevice::address).collect::<Vec<_>>(), [9, 10]);
        devices.remove(0)
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
