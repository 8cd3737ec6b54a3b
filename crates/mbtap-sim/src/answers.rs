//! The response PDUs a server builds from values, shared by every emulated device (a profile's
//! [`super::Slave`], a recording's [`super::recorded::RecordedDevice`]): one encoding of each
//! answer, so two devices cannot disagree on the wire.

use mbtap_proto::ExceptionCode;

/// Largest quantities a request may ask for (MAP v1.1b3 §6.1–§6.4, §6.11, §6.12).
pub const MAX_READ_BITS: u16 = 2000; // 0x07D0
pub const MAX_READ_REGISTERS: u16 = 125; // 0x007D
pub const MAX_WRITE_BITS: u16 = 1968; // 0x07B0
pub const MAX_WRITE_REGISTERS: u16 = 123; // 0x007B

/// Single-coil write values: ON and OFF (MAP v1.1b3 §6.5); anything else is exception 03.
pub const COIL_ON: u16 = 0xFF00;
pub const COIL_OFF: u16 = 0x0000;

/// The last address of `[address, address + quantity)`; exception 02 when it runs past 65535
/// (callers have refused quantity 0).
///
/// # Errors
/// [`ExceptionCode::IllegalDataAddress`] when the range leaves the address space.
pub fn last_address(address: u16, quantity: u16) -> Result<u16, ExceptionCode> {
    address.checked_add(quantity.saturating_sub(1)).ok_or(ExceptionCode::IllegalDataAddress)
}

/// A read-bits answer (FC 01/02, MAP v1.1b3 §6.1, §6.2): function, byte count, bits packed
/// LSB first, from `value(i)` for each of `quantity` bits.
///
/// # Errors
/// 03 for a quantity of 0 or above 2000.
pub fn read_bits(function: u8, quantity: u16, value: impl Fn(u16) -> u16) -> Result<Vec<u8>, ExceptionCode> {
    if quantity == 0 || quantity > MAX_READ_BITS {
        return Err(ExceptionCode::IllegalDataValue);
    }
    let mut packed = vec![0u8; usize::from(quantity).div_ceil(8)];
    for i in 0..quantity {
        if value(i) != 0
            && let Some(byte) = packed.get_mut(usize::from(i / 8))
        {
            *byte |= 1 << (i % 8);
        }
    }
    let mut out = vec![function, u8::try_from(packed.len()).map_err(|_| ExceptionCode::IllegalDataValue)?];
    out.extend_from_slice(&packed);
    Ok(out)
}

/// A read-registers answer (FC 03/04, MAP v1.1b3 §6.3, §6.4): function, byte count, values
/// high byte first.
///
/// # Errors
/// 03 for a quantity of 0 or above 125.
pub fn read_registers(function: u8, quantity: u16, value: impl Fn(u16) -> u16) -> Result<Vec<u8>, ExceptionCode> {
    if quantity == 0 || quantity > MAX_READ_REGISTERS {
        return Err(ExceptionCode::IllegalDataValue);
    }
    let bytes = u8::try_from(quantity.saturating_mul(2)).map_err(|_| ExceptionCode::IllegalDataValue)?;
    let mut out = Vec::with_capacity(2 + usize::from(bytes));
    out.extend_from_slice(&[function, bytes]);
    for i in 0..quantity {
        out.extend_from_slice(&value(i).to_be_bytes());
    }
    Ok(out)
}

/// The response to 0x0F / 0x10: function, start address, quantity (MAP v1.1b3 §6.11, §6.12).
#[must_use]
pub fn write_echo(function: u8, address: u16, quantity: u16) -> Vec<u8> {
    let mut out = vec![function];
    out.extend_from_slice(&address.to_be_bytes());
    out.extend_from_slice(&quantity.to_be_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_pack_least_significant_first() {
        // Bits 0, 2 and 8 of 9: 0b0000_0101, 0b0000_0001 (MAP v1.1b3 §6.1's example packing).
        let r = read_bits(0x01, 9, |i| u16::from(matches!(i, 0 | 2 | 8))).unwrap();
        assert_eq!(r, [/* fc */ 0x01, /* bytes */ 2, 0b0000_0101, 0b0000_0001]);
    }

    #[test]
    fn quantities_outside_the_spec_are_exception_03() {
        assert_eq!(read_bits(0x01, 0, |_| 0), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(read_bits(0x01, 2001, |_| 0), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(read_registers(0x03, 126, |_| 0), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(last_address(0xFFFF, 2), Err(ExceptionCode::IllegalDataAddress));
    }
}
