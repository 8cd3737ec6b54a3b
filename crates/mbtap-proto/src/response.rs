//! Response PDUs (server → client) of every public function code, exceptions included: types,
//! the zero-copy parser and the encoder. Layouts are MAP v1.1b3 §6.x; exceptions §7.
//!
//! Contract of [`parse_response`]: as [`parse_request`](super::parse_request) — the response
//! and its trailing bytes, or [`PduError`] when the fields do not fit. A function byte with the
//! 0x80 bit set is an exception response whatever the function.

use nom::IResult;
use nom::Parser;
use nom::multi::length_data;
use nom::number::complete::{be_u16, u8 as byte};

use super::data::{Bits, DeviceObjects, FileRecords, Registers};
use super::error::{EncodeError, PduError};
use super::function::{DiagnosticSubFunction, EXCEPTION_FLAG, ExceptionCode, FunctionCode as F, MeiType};
use super::length::response_len;
use super::request::{put_counted, put_u16s};

/// A response PDU. As with requests, byte counts are the lengths of the stored slices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Response<'a> {
    /// 0x01: coil status, LSB first.
    ReadCoils { status: Bits<'a> },
    /// 0x02: input status, LSB first.
    ReadDiscreteInputs { status: Bits<'a> },
    /// 0x03.
    ReadHoldingRegisters { values: Registers<'a> },
    /// 0x04.
    ReadInputRegisters { values: Registers<'a> },
    /// 0x05: echo of the request.
    WriteSingleCoil { address: u16, value: u16 },
    /// 0x06: echo of the request.
    WriteSingleRegister { address: u16, value: u16 },
    /// 0x07: eight exception status outputs.
    ReadExceptionStatus { status: u8 },
    /// 0x08: echo (sub-function 0) or counter value.
    Diagnostics { sub_function: DiagnosticSubFunction, data: &'a [u8] },
    /// 0x0B.
    GetCommEventCounter { status: u16, event_count: u16 },
    /// 0x0C: byte count = 6 + events.
    GetCommEventLog { status: u16, event_count: u16, message_count: u16, events: &'a [u8] },
    /// 0x0F: the request's address and quantity.
    WriteMultipleCoils { address: u16, quantity: u16 },
    /// 0x10: the request's address and quantity.
    WriteMultipleRegisters { address: u16, quantity: u16 },
    /// 0x11: server id, run indicator and additional data; their split is device-specific.
    ReportServerId { data: &'a [u8] },
    /// 0x14: sub-responses.
    ReadFileRecord { records: FileRecords<'a> },
    /// 0x15: echo of the request.
    WriteFileRecord { records: FileRecords<'a> },
    /// 0x16: echo of the request.
    MaskWriteRegister { address: u16, and_mask: u16, or_mask: u16 },
    /// 0x17: the registers read.
    ReadWriteMultipleRegisters { values: Registers<'a> },
    /// 0x18: byte count (u16) = 2 + 2 × values; `fifo_count` as sent.
    ReadFifoQueue { fifo_count: u16, values: Registers<'a> },
    /// 0x2B / 0x0E.
    ReadDeviceIdentification {
        read_code: u8,
        conformity_level: u8,
        more_follows: u8,
        next_object_id: u8,
        objects: DeviceObjects<'a>,
    },
    /// 0x2B with another MEI type (0x0D CANopen included): kept raw.
    Encapsulated { mei_type: MeiType, data: &'a [u8] },
    /// Function | 0x80 and an exception code. `function` is the request's code (flag cleared).
    Exception { function: u8, code: ExceptionCode },
    /// A function code without a public layout: kept raw.
    Other { function: u8, data: &'a [u8] },
}

type R<'a, T> = IResult<&'a [u8], T>;

/// Parses a response PDU. See the module documentation for the contract.
///
/// # Errors
/// [`PduError::Empty`] for no bytes, [`PduError::Truncated`] when the fields do not fit.
pub fn parse_response(pdu: &[u8]) -> Result<(&[u8], Response<'_>), PduError> {
    let Some((&fc, body)) = pdu.split_first() else {
        return Err(PduError::Empty);
    };
    let parsed: R<'_, Response<'_>> = if fc & EXCEPTION_FLAG != 0 {
        byte(body).map(|(i, code)| {
            (i, Response::Exception { function: fc & !EXCEPTION_FLAG, code: ExceptionCode::from(code) })
        })
    } else {
        parse_normal(fc, body)
    };
    parsed.map_err(|_| PduError::Truncated {
        function: fc,
        direction: "response",
        needed: response_len(pdu).needed().unwrap_or(pdu.len() + 1),
        available: pdu.len(),
    })
}

fn parse_normal(fc: u8, body: &[u8]) -> R<'_, Response<'_>> {
    match F::from(fc) {
        F::ReadCoils => length_data(byte).parse(body).map(|(i, v)| (i, Response::ReadCoils { status: Bits::new(v) })),
        F::ReadDiscreteInputs => {
            length_data(byte).parse(body).map(|(i, v)| (i, Response::ReadDiscreteInputs { status: Bits::new(v) }))
        }
        F::ReadHoldingRegisters => length_data(byte)
            .parse(body)
            .map(|(i, v)| (i, Response::ReadHoldingRegisters { values: Registers::new(v) })),
        F::ReadInputRegisters => {
            length_data(byte).parse(body).map(|(i, v)| (i, Response::ReadInputRegisters { values: Registers::new(v) }))
        }
        F::WriteSingleCoil => {
            (be_u16, be_u16).parse(body).map(|(i, (address, value))| (i, Response::WriteSingleCoil { address, value }))
        }
        F::WriteSingleRegister => (be_u16, be_u16)
            .parse(body)
            .map(|(i, (address, value))| (i, Response::WriteSingleRegister { address, value })),
        F::ReadExceptionStatus => byte(body).map(|(i, status)| (i, Response::ReadExceptionStatus { status })),
        F::Diagnostics => be_u16(body).map(|(data, sub)| {
            let sub_function = DiagnosticSubFunction::from(sub);
            let split = if sub == 0 { data.len() } else { data.len().min(2) };
            let (data, rest) = data.split_at(split);
            (rest, Response::Diagnostics { sub_function, data })
        }),
        F::GetCommEventCounter => (be_u16, be_u16)
            .parse(body)
            .map(|(i, (status, event_count))| (i, Response::GetCommEventCounter { status, event_count })),
        F::GetCommEventLog => length_data(byte).parse(body).and_then(|(rest, block)| {
            let (events, (status, event_count, message_count)) = (be_u16, be_u16, be_u16).parse(block)?;
            Ok((rest, Response::GetCommEventLog { status, event_count, message_count, events }))
        }),
        F::WriteMultipleCoils => (be_u16, be_u16)
            .parse(body)
            .map(|(i, (address, quantity))| (i, Response::WriteMultipleCoils { address, quantity })),
        F::WriteMultipleRegisters => (be_u16, be_u16)
            .parse(body)
            .map(|(i, (address, quantity))| (i, Response::WriteMultipleRegisters { address, quantity })),
        F::ReportServerId => length_data(byte).parse(body).map(|(i, data)| (i, Response::ReportServerId { data })),
        F::ReadFileRecord => length_data(byte)
            .parse(body)
            .map(|(i, v)| (i, Response::ReadFileRecord { records: FileRecords::read_response_layout(v) })),
        F::WriteFileRecord => length_data(byte)
            .parse(body)
            .map(|(i, v)| (i, Response::WriteFileRecord { records: FileRecords::write_layout(v) })),
        F::MaskWriteRegister => (be_u16, be_u16, be_u16)
            .parse(body)
            .map(|(i, (address, and_mask, or_mask))| (i, Response::MaskWriteRegister { address, and_mask, or_mask })),
        F::ReadWriteMultipleRegisters => length_data(byte)
            .parse(body)
            .map(|(i, v)| (i, Response::ReadWriteMultipleRegisters { values: Registers::new(v) })),
        F::ReadFifoQueue => length_data(be_u16).parse(body).and_then(|(rest, block)| {
            let (values, fifo_count) = be_u16(block)?;
            Ok((rest, Response::ReadFifoQueue { fifo_count, values: Registers::new(values) }))
        }),
        F::EncapsulatedInterface => byte(body).and_then(|(i, mei)| match MeiType::from(mei) {
            MeiType::ReadDeviceIdentification => {
                let (i, (read_code, conformity_level, more_follows, next_object_id, count)) =
                    (byte, byte, byte, byte, byte).parse(i)?;
                let (objects, rest) = DeviceObjects::split(i, count)
                    .ok_or_else(|| nom::Err::Error(nom::error::Error::new(i, nom::error::ErrorKind::Eof)))?;
                Ok((
                    rest,
                    Response::ReadDeviceIdentification {
                        read_code,
                        conformity_level,
                        more_follows,
                        next_object_id,
                        objects,
                    },
                ))
            }
            mei_type => Ok((&i[i.len()..], Response::Encapsulated { mei_type, data: i })),
        }),
        F::Other(function) => Ok((&body[body.len()..], Response::Other { function, data: body })),
    }
}

impl Response<'_> {
    /// The function byte as on the wire (0x80 set for exceptions).
    #[must_use]
    pub const fn function_byte(&self) -> u8 {
        match self {
            Self::ReadCoils { .. } => 0x01,
            Self::ReadDiscreteInputs { .. } => 0x02,
            Self::ReadHoldingRegisters { .. } => 0x03,
            Self::ReadInputRegisters { .. } => 0x04,
            Self::WriteSingleCoil { .. } => 0x05,
            Self::WriteSingleRegister { .. } => 0x06,
            Self::ReadExceptionStatus { .. } => 0x07,
            Self::Diagnostics { .. } => 0x08,
            Self::GetCommEventCounter { .. } => 0x0B,
            Self::GetCommEventLog { .. } => 0x0C,
            Self::WriteMultipleCoils { .. } => 0x0F,
            Self::WriteMultipleRegisters { .. } => 0x10,
            Self::ReportServerId { .. } => 0x11,
            Self::ReadFileRecord { .. } => 0x14,
            Self::WriteFileRecord { .. } => 0x15,
            Self::MaskWriteRegister { .. } => 0x16,
            Self::ReadWriteMultipleRegisters { .. } => 0x17,
            Self::ReadFifoQueue { .. } => 0x18,
            Self::ReadDeviceIdentification { .. } | Self::Encapsulated { .. } => 0x2B,
            Self::Exception { function, .. } => *function | EXCEPTION_FLAG,
            Self::Other { function, .. } => *function,
        }
    }

    /// The function this responds to (exception flag cleared).
    #[must_use]
    pub fn function(&self) -> F {
        F::from(self.function_byte() & !EXCEPTION_FLAG)
    }

    /// Appends the PDU's bytes to `out`.
    ///
    /// # Errors
    /// [`EncodeError::TooLong`] when a data slice is longer than its byte-count field allows.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        out.push(self.function_byte());
        match *self {
            Self::ReadCoils { status } | Self::ReadDiscreteInputs { status } => {
                put_counted(out, "bit status", status.as_bytes())?;
            }
            Self::ReadHoldingRegisters { values }
            | Self::ReadInputRegisters { values }
            | Self::ReadWriteMultipleRegisters { values } => put_counted(out, "register values", values.as_bytes())?,
            Self::WriteSingleCoil { address, value } | Self::WriteSingleRegister { address, value } => {
                put_u16s(out, &[address, value]);
            }
            Self::ReadExceptionStatus { status } => out.push(status),
            Self::Diagnostics { sub_function, data } => {
                put_u16s(out, &[sub_function.value()]);
                out.extend_from_slice(data);
            }
            Self::GetCommEventCounter { status, event_count } => put_u16s(out, &[status, event_count]),
            Self::GetCommEventLog { status, event_count, message_count, events } => {
                let len = events.len().checked_add(6).filter(|&n| n <= 255).ok_or(EncodeError::TooLong {
                    field: "event log",
                    len: events.len(),
                    max: 249,
                })?;
                out.push(u8::try_from(len).unwrap_or(u8::MAX));
                put_u16s(out, &[status, event_count, message_count]);
                out.extend_from_slice(events);
            }
            Self::WriteMultipleCoils { address, quantity } | Self::WriteMultipleRegisters { address, quantity } => {
                put_u16s(out, &[address, quantity]);
            }
            Self::ReportServerId { data } => put_counted(out, "server id data", data)?,
            Self::ReadFileRecord { records } | Self::WriteFileRecord { records } => {
                put_counted(out, "file records", records.as_bytes())?;
            }
            Self::MaskWriteRegister { address, and_mask, or_mask } => put_u16s(out, &[address, and_mask, or_mask]),
            Self::ReadFifoQueue { fifo_count, values } => {
                let bytes = values.as_bytes();
                let count = bytes
                    .len()
                    .checked_add(2)
                    .and_then(|n| u16::try_from(n).ok())
                    .ok_or(EncodeError::TooLong { field: "FIFO values", len: bytes.len(), max: 65533 })?;
                put_u16s(out, &[count, fifo_count]);
                out.extend_from_slice(bytes);
            }
            Self::ReadDeviceIdentification { read_code, conformity_level, more_follows, next_object_id, objects } => {
                out.extend_from_slice(&[
                    MeiType::ReadDeviceIdentification.value(),
                    read_code,
                    conformity_level,
                    more_follows,
                    next_object_id,
                    objects.count(),
                ]);
                out.extend_from_slice(objects.as_bytes());
            }
            Self::Encapsulated { mei_type, data } => {
                out.push(mei_type.value());
                out.extend_from_slice(data);
            }
            Self::Exception { code, .. } => out.push(code.value()),
            Self::Other { data, .. } => out.extend_from_slice(data),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MK4 §3.3: `03`, byte count 6, registers 101..103 = 0x0000, 0x0000, 0x0190.
    const READ_101_X3_RESPONSE: &[u8] = &[0x03, 0x06, 0x00, 0x00, 0x00, 0x00, 0x01, 0x90];

    #[test]
    fn parses_register_values() {
        let (trailing, resp) = parse_response(READ_101_X3_RESPONSE).unwrap();
        assert!(trailing.is_empty());
        let Response::ReadHoldingRegisters { values } = resp else { panic!("{resp:?}") };
        assert_eq!(values.iter().collect::<Vec<_>>(), vec![0, 0, 400]);
    }

    #[test]
    fn exception_flag_wins_over_function() {
        let (_, resp) = parse_response(&[0x83, 0x03]).unwrap();
        assert_eq!(resp, Response::Exception { function: 3, code: ExceptionCode::IllegalDataValue });
        assert_eq!(resp.function_byte(), 0x83);
    }

    #[test]
    fn device_id_object_count_that_lies_is_truncation() {
        // 2B 0E, code 1, conformity 1, more 0, next 0, count 3 but only one object.
        let pdu = [0x2B, 0x0E, 1, 1, 0, 0, 3, 0, 1, b'A'];
        assert!(matches!(parse_response(&pdu), Err(PduError::Truncated { function: 0x2B, .. })));
    }

    #[test]
    fn fifo_byte_count_below_two_is_truncation() {
        assert!(parse_response(&[0x18, 0x00, 0x01, 0x00]).is_err());
    }
}
