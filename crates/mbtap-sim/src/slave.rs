//! One simulated slave: a register memory shaped by a profile and the request handling of a
//! Modbus server (MAP v1.1b3 §6 for each function, §7 for exception responses).

use std::collections::BTreeMap;
use std::sync::Arc;

use mbtap_device::profile::format::{Access, Table, ValueType};
use mbtap_device::profile::model::Profile;
use mbtap_proto::{EXCEPTION_FLAG, ExceptionCode, Request, parse_request};

/// Broadcast address: every slave acts, none answers (Serial Line v1.02 §2.2).
pub const BROADCAST: u8 = 0;

use super::answers::{COIL_OFF, COIL_ON, MAX_WRITE_BITS, MAX_WRITE_REGISTERS, write_echo};

/// A slave on the simulated line.
#[derive(Debug, Clone)]
pub struct Slave {
    profile: Arc<Profile>,
    address: u8,
    memory: BTreeMap<(Table, u16), u16>,
}

impl Slave {
    /// A slave at `address` with every mapped value at rest: 0, or the bottom of its range when
    /// 0 is outside it (a device never holds a value its document forbids).
    #[must_use]
    pub fn new(profile: Arc<Profile>, address: u8) -> Self {
        let mut memory = BTreeMap::new();
        for (&table, slots) in &profile.tables {
            for (&a, slot) in slots {
                let rest = profile
                    .defs
                    .get(slot.def)
                    .and_then(|d| d.range)
                    .filter(|&(min, max)| !(min..=max).contains(&0))
                    .and_then(|(min, _)| u16::try_from(min).ok())
                    .unwrap_or(0);
                memory.insert((table, a), rest);
            }
        }
        // Reserved addresses answer (as 0) so a read across them, as the documents' own
        // examples do, is not refused.
        for &(table, from, to) in &profile.reserved {
            for a in from..=to {
                memory.entry((table, a)).or_insert(0);
            }
        }
        Self { profile, address, memory }
    }

    /// The slave's own address.
    #[must_use]
    pub const fn address(&self) -> u8 {
        self.address
    }

    /// The profile it implements.
    #[must_use]
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// Whether a request to `unit` concerns this slave: its address, an address its document
    /// says it also answers (MKZP: 247), or broadcast.
    #[must_use]
    pub fn listens_to(&self, unit: u8) -> bool {
        unit == self.address || unit == BROADCAST || self.profile.meta.also_answers.contains(&unit)
    }

    /// A value in memory (`None` outside the map).
    #[must_use]
    pub fn get(&self, table: Table, address: u16) -> Option<u16> {
        self.memory.get(&(table, address)).copied()
    }

    /// Sets a mapped value as the device itself would (measurements moving); `false` outside the map.
    pub fn set(&mut self, table: Table, address: u16, value: u16) -> bool {
        match self.memory.get_mut(&(table, address)) {
            Some(v) => {
                *v = value;
                true
            }
            None => false,
        }
    }

    /// Handles one request PDU addressed to `unit`. Returns the response PDU, or `None` when the
    /// slave stays silent: not its address, or a broadcast (acted on, never answered).
    pub fn handle(&mut self, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        if !self.listens_to(unit) {
            return None;
        }
        let function = *pdu.first()?;
        let answer = self.answer(function, pdu);
        if unit == BROADCAST {
            return None;
        }
        Some(match answer {
            Ok(body) => body,
            Err(code) => vec![function | EXCEPTION_FLAG, code.value()],
        })
    }

    fn supports(&self, function: u8) -> bool {
        self.profile.meta.functions.is_empty() || self.profile.meta.functions.contains(&function)
    }

    fn answer(&mut self, function: u8, pdu: &[u8]) -> Result<Vec<u8>, ExceptionCode> {
        if !self.supports(function) {
            return Err(ExceptionCode::IllegalFunction);
        }
        // A request the device cannot make sense of: MAP v1.1b3 §7 gives 03 for a malformed data field.
        let Ok((_, request)) = parse_request(pdu) else { return Err(ExceptionCode::IllegalDataValue) };
        match request {
            Request::ReadCoils { address, quantity } => self.read_bits(Table::Coils, function, address, quantity),
            Request::ReadDiscreteInputs { address, quantity } => {
                self.read_bits(Table::DiscreteInputs, function, address, quantity)
            }
            Request::ReadHoldingRegisters { address, quantity } => {
                self.read_registers(Table::HoldingRegisters, function, address, quantity)
            }
            Request::ReadInputRegisters { address, quantity } => {
                self.read_registers(Table::InputRegisters, function, address, quantity)
            }
            Request::WriteSingleCoil { address, value } => {
                if value != COIL_ON && value != COIL_OFF {
                    return Err(ExceptionCode::IllegalDataValue);
                }
                self.check_writable(Table::Coils, address, 1)?;
                self.memory.insert((Table::Coils, address), u16::from(value == COIL_ON));
                Ok(pdu.get(..5).unwrap_or(pdu).to_vec())
            }
            Request::WriteSingleRegister { address, value } => {
                self.check_writable(Table::HoldingRegisters, address, 1)?;
                let stored = self.accept(address, value)?;
                self.memory.insert((Table::HoldingRegisters, address), stored);
                // The echo is the request (MAP v1.1b3 §6.6), even when the device clamped the value.
                Ok(pdu.get(..5).unwrap_or(pdu).to_vec())
            }
            Request::WriteMultipleCoils { address, quantity, values } => {
                if quantity == 0 || quantity > MAX_WRITE_BITS {
                    return Err(ExceptionCode::IllegalDataValue);
                }
                self.check_writable(Table::Coils, address, quantity)?;
                for i in 0..quantity {
                    let on = values.get(usize::from(i)).ok_or(ExceptionCode::IllegalDataValue)?;
                    self.memory.insert((Table::Coils, address + i), u16::from(on));
                }
                Ok(write_echo(function, address, quantity))
            }
            Request::WriteMultipleRegisters { address, quantity, values } => {
                if quantity == 0 || quantity > MAX_WRITE_REGISTERS || values.len() != usize::from(quantity) {
                    return Err(ExceptionCode::IllegalDataValue);
                }
                self.check_writable(Table::HoldingRegisters, address, quantity)?;
                // All or nothing: check every value before storing any.
                let mut stored = Vec::with_capacity(values.len());
                for (i, v) in (0..quantity).zip(values.iter()) {
                    stored.push(self.accept(address + i, v)?);
                }
                for (i, v) in (0..quantity).zip(stored) {
                    self.memory.insert((Table::HoldingRegisters, address + i), v);
                }
                Ok(write_echo(function, address, quantity))
            }
            // Listed in the profile but not simulated yet: say so the standard way.
            _ => Err(ExceptionCode::IllegalFunction),
        }
    }

    /// Every address of `[address, address + quantity)` in the table's map (MAP v1.1b3 §7: 02).
    fn check_mapped(&self, table: Table, address: u16, quantity: u16) -> Result<(), ExceptionCode> {
        // Callers have refused quantity 0; the end must not run past 65535 either.
        let end = super::answers::last_address(address, quantity)?;
        if (address..=end).all(|a| self.memory.contains_key(&(table, a))) {
            Ok(())
        } else {
            Err(ExceptionCode::IllegalDataAddress)
        }
    }

    /// Mapped and writable; a read-only register refuses the write as an illegal address, as
    /// it is not in the device's writable map.
    fn check_writable(&self, table: Table, address: u16, quantity: u16) -> Result<(), ExceptionCode> {
        self.check_mapped(table, address, quantity.max(1))?;
        let read_only =
            (0..quantity).any(|i| self.profile.slot(table, address + i).is_some_and(|(_, d)| d.access == Access::Read));
        if read_only { Err(ExceptionCode::IllegalDataAddress) } else { Ok(()) }
    }

    /// The value a holding register will hold after a write: clamped into range when the
    /// device clamps (MK4), refused with 03 when it does not.
    fn accept(&self, address: u16, value: u16) -> Result<u16, ExceptionCode> {
        let Some((slot, def)) = self.profile.slot(Table::HoldingRegisters, address) else { return Ok(value) };
        let Some((min, max)) = def.range.filter(|_| def.width == 1 && slot.part == 0) else { return Ok(value) };
        let raw = if def.value_type == ValueType::I16 {
            i64::from(i16::from_ne_bytes(value.to_ne_bytes()))
        } else {
            i64::from(value)
        };
        if (min..=max).contains(&raw) {
            Ok(value)
        } else if self.profile.meta.clamps_writes {
            let clamped = raw.clamp(min, max);
            Ok(if def.value_type == ValueType::I16 {
                i16::try_from(clamped).map_or(value, |v| u16::from_ne_bytes(v.to_ne_bytes()))
            } else {
                u16::try_from(clamped).unwrap_or(value)
            })
        } else {
            Err(ExceptionCode::IllegalDataValue)
        }
    }

    fn read_bits(&self, table: Table, function: u8, address: u16, quantity: u16) -> Result<Vec<u8>, ExceptionCode> {
        if quantity == 0 || quantity > super::answers::MAX_READ_BITS {
            return Err(ExceptionCode::IllegalDataValue);
        }
        self.check_mapped(table, address, quantity)?;
        super::answers::read_bits(function, quantity, |i| self.get(table, address + i).unwrap_or(0))
    }

    fn read_registers(
        &self,
        table: Table,
        function: u8,
        address: u16,
        quantity: u16,
    ) -> Result<Vec<u8>, ExceptionCode> {
        if quantity == 0 || quantity > super::answers::MAX_READ_REGISTERS {
            return Err(ExceptionCode::IllegalDataValue);
        }
        self.check_mapped(table, address, quantity)?;
        super::answers::read_registers(function, quantity, |i| self.get(table, address + i).unwrap_or(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mbtap_device::profile::builtin;

    fn slave(name: &str, address: u8) -> Slave {
        Slave::new(Arc::new(builtin::get(name).unwrap().unwrap()), address)
    }

    /// MK4 read input registers 430, quantity 4 (phase voltages L1, L2, L3, average).
    const READ_VOLTAGES: [u8; 5] = [/* fc */ 0x04, /* address */ 0x01, 0xAE, /* quantity */ 0x00, 0x04];

    #[test]
    fn reads_the_values_in_memory() {
        let mut s = slave("mk4", 1);
        for (i, v) in [2305u16, 2298, 2310, 2304].into_iter().enumerate() {
            assert!(s.set(Table::InputRegisters, 430 + u16::try_from(i).unwrap(), v));
        }
        let r = s.handle(1, &READ_VOLTAGES).unwrap();
        assert_eq!(r, [0x04, 0x08, 0x09, 0x01, 0x08, 0xFA, 0x09, 0x06, 0x09, 0x00]);
    }

    #[test]
    fn silent_to_other_addresses() {
        let mut s = slave("mk4", 1);
        assert_eq!(s.handle(2, &READ_VOLTAGES), None);
    }

    #[test]
    fn unsupported_function_is_exception_01() {
        // The MKZP supports 03 and 06 only.
        let mut s = slave("mkzp", 17);
        assert_eq!(s.handle(17, &[0x04, 0x00, 0x32, 0x00, 0x01]).unwrap(), [0x84, 0x01]);
    }

    #[test]
    fn mkzp_answers_247_too() {
        let mut s = slave("mkzp", 17);
        let r = s.handle(247, &[/* fc */ 0x03, /* address 50 */ 0x00, 0x32, /* quantity */ 0x00, 0x01]).unwrap();
        assert_eq!(&r[..2], [0x03, 0x02]);
    }

    #[test]
    fn outside_the_map_is_exception_02() {
        // MK4 holding registers are 100–312 (313–399 documented as reserved): 98 and 99 precede the map.
        let mut s = slave("mk4", 1);
        assert_eq!(s.handle(1, &[0x03, 0x00, 0x62, 0x00, 0x03]).unwrap(), [0x83, 0x02]);
        assert_eq!(s.handle(1, &[0x03, 0x03, 0xE8, 0x00, 0x01]).unwrap(), [0x83, 0x02], "1000");
        // The top of the address space: the range must not wrap around.
        assert_eq!(s.handle(1, &[0x03, 0xFF, 0xFF, 0x00, 0x02]).unwrap(), [0x83, 0x02]);
    }

    #[test]
    fn reads_across_reserved_addresses() {
        // MK4 discrete inputs 050–088 with 067, 074, 081 and 088 reserved.
        let mut s = slave("mk4", 1);
        let r = s.handle(1, &[0x02, 0x00, 0x32, 0x00, 39]).unwrap();
        assert_eq!(&r[..2], [0x02, 5], "39 bits in 5 bytes");
    }

    #[test]
    fn bad_quantities_are_exception_03() {
        let mut s = slave("mk4", 1);
        assert_eq!(s.handle(1, &[0x04, 0x01, 0xAE, 0x00, 0x00]).unwrap(), [0x84, 0x03]);
        assert_eq!(s.handle(1, &[0x04, 0x01, 0xAE, 0x00, 126]).unwrap(), [0x84, 0x03]);
        assert_eq!(s.handle(1, &[0x05, 0x00, 0x00, 0x12, 0x34]).unwrap(), [0x85, 0x03], "coil value not FF00/0000");
    }

    /// The first MK4 holding register with a range that excludes 65535 and is writable.
    fn clampable(s: &Slave) -> (u16, i64, i64) {
        s.profile()
            .addresses(Table::HoldingRegisters)
            .find_map(|a| {
                let (slot, d) = s.profile().slot(Table::HoldingRegisters, a)?;
                let (min, max) = d.range?;
                (d.width == 1
                    && slot.part == 0
                    && d.access != Access::Read
                    && max < 1000
                    && d.value_type != ValueType::I16)
                    .then_some((a, min, max))
            })
            .unwrap()
    }

    #[test]
    fn mk4_clamps_out_of_range_writes() {
        let mut s = slave("mk4", 1);
        let (a, _, max) = clampable(&s);
        let [hi, lo] = a.to_be_bytes();
        let request = [0x06, hi, lo, 0x03, 0xE8]; // value 1000, above max
        assert_eq!(s.handle(1, &request).unwrap(), request, "the echo is the request");
        assert_eq!(i64::from(s.get(Table::HoldingRegisters, a).unwrap()), max);
    }

    #[test]
    fn write_to_read_only_is_refused() {
        // MK4 input registers cannot be written at all; the MKZP's 50 (phase A current) is read-only.
        let mut s = slave("mkzp", 17);
        assert_eq!(s.handle(17, &[0x06, 0x00, 0x32, 0x00, 0x01]).unwrap(), [0x86, 0x02]);
    }

    #[test]
    fn broadcast_writes_are_applied_silently() {
        let mut s = slave("mk4", 1);
        let (a, min, _) = clampable(&s);
        let value = u16::try_from(min).unwrap();
        let [hi, lo] = a.to_be_bytes();
        let [vh, vl] = value.to_be_bytes();
        s.set(Table::HoldingRegisters, a, value.wrapping_add(1));
        assert_eq!(s.handle(BROADCAST, &[0x06, hi, lo, vh, vl]), None);
        assert_eq!(s.get(Table::HoldingRegisters, a), Some(value));
    }

    #[test]
    fn write_multiple_registers_echoes_address_and_quantity() {
        let mut s = slave("mk4", 1);
        let (a, _, _) = clampable(&s);
        let [hi, lo] = a.to_be_bytes();
        let r = s.handle(1, &[0x10, hi, lo, 0x00, 0x01, 0x02, 0x00, 0x00]).unwrap();
        assert_eq!(r, [0x10, hi, lo, 0x00, 0x01]);
    }

    #[test]
    fn any_bytes_never_panic() {
        let mut s = slave("mk4", 1);
        for f in 0..=255u8 {
            for len in 0..8usize {
                let pdu: Vec<u8> =
                    std::iter::once(f).chain((0..len).map(|i| u8::try_from(i * 37 % 256).unwrap())).collect();
                let _ = s.handle(1, &pdu);
                let _ = s.handle(0, &pdu);
            }
        }
    }
}
