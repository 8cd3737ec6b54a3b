//! A device as a recording showed it (`mbtap simulate --from CAPTURE`): the register image the
//! capture carried (the last value heard at each address, what was written included), the
//! exceptions it gave and for which requests, answers to functions that carry no registers
//! (FC 11 Report Server ID, FC 2B/0E identity, FC 08) as they were, how long it took to
//! answer, and — with `--replay-values` — its values in their recorded time course, looping.
//! Built by [`super::recording::RecordedDevicesBuilder`]; pure like the rest of the core.
//!
//! What the recording never showed is not invented: a read of an address never heard is
//! refused with exception 02 (MAP v1.1b3 §7), a function never heard with 01, unless the
//! recording showed the device refusing it otherwise.

use std::collections::BTreeMap;

use super::answers::{self, COIL_OFF, COIL_ON};
use mbtap_device::profile::format::Table;
use mbtap_proto::{EXCEPTION_FLAG, ExceptionCode, Request, parse_request};

/// Functions whose answers the register image holds (MAP v1.1b3 §6.1–§6.6, §6.11, §6.12, §6.17):
/// served from values, not replayed verbatim.
pub(super) const fn carries_registers(function: u8) -> bool {
    matches!(function, 0x01..=0x06 | 0x0F | 0x10 | 0x17)
}

/// A refused request's key: its function, and for the register functions its start address
/// and quantity (1 for single writes), else 0.
pub(super) fn refusal_key(request: &[u8]) -> (u8, u16, u16) {
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
    pub(super) address: u8,
    pub(super) values: crate::store::Values,
    pub(super) refusals: BTreeMap<(u8, u16, u16), u8>,
    pub(super) verbatim: BTreeMap<Vec<u8>, Vec<u8>>,
    /// The values in their recorded time course (ns from the recording's first transaction),
    /// and where serving them has got to; empty unless replayed.
    pub(super) course: Vec<(u64, Table, u16, u16)>,
    pub(super) course_at: usize,
    pub(super) course_last_ns: u64,
    /// `None` when no answer's start could be measured (one read held request and answer).
    pub latency: Option<Latency>,
    pub answered: u64,
    pub unanswered: u64,
}

impl RecordedDevice {
    /// A device from a register image alone (`replay --image`, a probe dump): every value as
    /// the image holds it, no refusals, no latency.
    #[must_use]
    pub fn from_image(address: u8, values: crate::store::Values) -> Self {
        Self {
            address,
            values,
            refusals: BTreeMap::new(),
            verbatim: BTreeMap::new(),
            course: Vec::new(),
            course_at: 0,
            course_last_ns: 0,
            latency: None,
            answered: 0,
            unanswered: 0,
        }
    }

    /// Serves the recorded time course from now on: values start as first heard and change
    /// when the recording changed them, from the start again after the last change.
    pub fn replay_values(&mut self, course: Vec<(u64, Table, u16, u16)>) {
        // Only where the recording's values are kept: the course never grows the store past the
        // bound its values were kept under.
        for &(_, table, address, value) in course.iter().rev() {
            if self.values.contains(table, address) {
                self.values.insert(table, address, value);
            }
        }
        self.course = course;
        self.course_at = 0;
        self.course_last_ns = 0;
    }

    /// Moves the values on to `t` seconds since serving began (with a replayed time course).
    pub fn step(&mut self, t: f64) {
        let Some(&(span, ..)) = self.course.last() else { return };
        // One period past the last change, so the last values are served a while too.
        let period = span.saturating_add(span / self.course.len().max(1) as u64).max(1);
        // Seconds to ns, within u64 for any run shorter than 584 years.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let now = ((t.max(0.0) * 1e9) as u64) % period;
        if now < self.course_last_ns {
            self.course_at = 0;
        }
        while let Some(&(at, table, address, value)) = self.course.get(self.course_at) {
            if at > now {
                break;
            }
            if self.values.contains(table, address) {
                self.values.insert(table, address, value);
            }
            self.course_at += 1;
        }
        self.course_last_ns = now;
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
            .map(|t| (t, self.values.count(t)))
    }

    /// A value as the recording left it (or as written since).
    #[must_use]
    pub fn get(&self, table: Table, address: u16) -> Option<u16> {
        self.values.get(table, address)
    }

    /// Sets a value the recording showed (from outside: `simulate --values-from`); `false` at an
    /// address it never showed, which stays refused.
    pub fn set(&mut self, table: Table, address: u16, value: u16) -> bool {
        let known = self.values.contains(table, address);
        if known {
            self.values.insert(table, address, value);
        }
        known
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
    /// function refused or never showed its table read, else 02. (A refusal of another request overlapping this one is no
    /// evidence: a device's 03 for a block says nothing of a smaller read inside it.)
    fn covered(&self, table: Table, function: u8, address: u16, quantity: u16) -> Result<(), u8> {
        // A read of a table the recording never showed read, nor refused, is a function the
        // device never showed: 01, as the docs and the start line say (02 is for an address).
        let never_shown = self.values.count(table) == 0
            && self.refusals.range((function, 0, 0)..=(function, u16::MAX, u16::MAX)).next().is_none();
        if never_shown && matches!(function, 0x01..=0x04) {
            return Err(ExceptionCode::IllegalFunction.value());
        }
        let last = answers::last_address(address, quantity).map_err(ExceptionCode::value)?;
        if (address..=last).all(|a| self.values.contains(table, a)) {
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
            self.values.insert(table, a, v);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// FC 03 at 100, 1 register (MAP v1.1b3 §6.3).
    const READ_100: [u8; 5] = [/* fc */ 0x03, /* address */ 0x00, 0x64, /* quantity */ 0x00, 0x01];

    #[test]
    fn replayed_values_follow_their_recorded_course_and_loop() {
        let mut d = RecordedDevice::from_image(9, [((Table::HoldingRegisters, 100), 3)].into_iter().collect());
        // Holding 100 was 1, then 2 a second later, then 3 at two seconds.
        d.replay_values(vec![
            (0, Table::HoldingRegisters, 100, 1),
            (1_000_000_000, Table::HoldingRegisters, 100, 2),
            (2_000_000_000, Table::HoldingRegisters, 100, 3),
        ]);
        let read = |d: &mut RecordedDevice| d.handle(9, &READ_100);
        assert_eq!(read(&mut d).unwrap(), [0x03, 2, 0, 1], "starts as first heard");
        d.step(1.5);
        assert_eq!(read(&mut d).unwrap(), [0x03, 2, 0, 2]);
        d.step(2.1);
        assert_eq!(read(&mut d).unwrap(), [0x03, 2, 0, 3]);
        // The period is the span and one mean step (2.67 s): 2.8 s is 0.13 s into the next loop.
        d.step(2.8);
        assert_eq!(read(&mut d).unwrap(), [0x03, 2, 0, 1], "from the start again");
    }
}
