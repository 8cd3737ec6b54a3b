//! Request PDUs (client → server) of every public function code: types, the zero-copy parser
//! and the encoder. Layouts are MAP v1.1b3 §6.x, one section per function.
//!
//! Contract of [`parse_request`]: given a whole PDU (function code first), it returns the
//! request and the bytes after its last field (trailing bytes, normally empty), or
//! [`PduError`] when the PDU ends before the fields its function code requires. Unknown and
//! user-defined function codes, and MEI types without a public layout, are kept raw: never an
//! error.

use nom::IResult;
use nom::Parser;
use nom::multi::length_data;
use nom::number::complete::{be_u16, u8 as byte};

use super::data::{Bits, FileRecords, FileSubRequests, Registers};
use super::error::{EncodeError, PduError};
use super::function::{DiagnosticSubFunction, FunctionCode as F, MeiType};
use super::length::request_len;

/// A request PDU. Byte-count fields are not stored: they are the length of the data slice, so
/// a parsed request re-encodes to exactly the bytes it came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request<'a> {
    /// 0x01 (MAP v1.1b3 §6.1).
    ReadCoils { address: u16, quantity: u16 },
    /// 0x02 (§6.2).
    ReadDiscreteInputs { address: u16, quantity: u16 },
    /// 0x03 (§6.3).
    ReadHoldingRegisters { address: u16, quantity: u16 },
    /// 0x04 (§6.4).
    ReadInputRegisters { address: u16, quantity: u16 },
    /// 0x05 (§6.5). `value` is 0xFF00 (on) or 0x0000 (off); anything else is kept and flagged.
    WriteSingleCoil { address: u16, value: u16 },
    /// 0x06 (§6.6).
    WriteSingleRegister { address: u16, value: u16 },
    /// 0x07 (§6.7).
    ReadExceptionStatus,
    /// 0x08 (§6.8).
    Diagnostics { sub_function: DiagnosticSubFunction, data: &'a [u8] },
    /// 0x0B (§6.9).
    GetCommEventCounter,
    /// 0x0C (§6.10).
    GetCommEventLog,
    /// 0x0F (§6.11).
    WriteMultipleCoils { address: u16, quantity: u16, values: Bits<'a> },
    /// 0x10 (§6.12).
    WriteMultipleRegisters { address: u16, quantity: u16, values: Registers<'a> },
    /// 0x11 (§6.13).
    ReportServerId,
    /// 0x14 (§6.14).
    ReadFileRecord { sub_requests: FileSubRequests<'a> },
    /// 0x15 (§6.15).
    WriteFileRecord { records: FileRecords<'a> },
    /// 0x16 (§6.16).
    MaskWriteRegister { address: u16, and_mask: u16, or_mask: u16 },
    /// 0x17 (§6.17).
    ReadWriteMultipleRegisters {
        read_address: u16,
        read_quantity: u16,
        write_address: u16,
        write_quantity: u16,
        values: Registers<'a>,
    },
    /// 0x18 (§6.18).
    ReadFifoQueue { address: u16 },
    /// 0x2B / 0x0E (§6.21).
    ReadDeviceIdentification { read_code: u8, object_id: u8 },
    /// 0x2B with any other MEI type (0x0D CANopen included): kept raw (§6.19).
    Encapsulated { mei_type: MeiType, data: &'a [u8] },
    /// A function code without a public layout: kept raw.
    Other { function: u8, data: &'a [u8] },
}

type R<'a, T> = IResult<&'a [u8], T>;

fn addr_qty(i: &[u8]) -> R<'_, (u16, u16)> {
    (be_u16, be_u16).parse(i)
}

/// Parses a request PDU. See the module documentation for the contract.
///
/// # Errors
/// [`PduError::Empty`] for no bytes, [`PduError::Truncated`] when the fields do not fit.
pub fn parse_request(pdu: &[u8]) -> Result<(&[u8], Request<'_>), PduError> {
    let Some((&fc, body)) = pdu.split_first() else {
        return Err(PduError::Empty);
    };
    let parsed: R<'_, Request<'_>> = match F::from(fc) {
        F::ReadCoils => addr_qty(body).map(|(i, (address, quantity))| (i, Request::ReadCoils { address, quantity })),
        F::ReadDiscreteInputs => {
            addr_qty(body).map(|(i, (address, quantity))| (i, Request::ReadDiscreteInputs { address, quantity }))
        }
        F::ReadHoldingRegisters => {
            addr_qty(body).map(|(i, (address, quantity))| (i, Request::ReadHoldingRegisters { address, quantity }))
        }
        F::ReadInputRegisters => {
            addr_qty(body).map(|(i, (address, quantity))| (i, Request::ReadInputRegisters { address, quantity }))
        }
        F::WriteSingleCoil => {
            addr_qty(body).map(|(i, (address, value))| (i, Request::WriteSingleCoil { address, value }))
        }
        F::WriteSingleRegister => {
            addr_qty(body).map(|(i, (address, value))| (i, Request::WriteSingleRegister { address, value }))
        }
        F::ReadExceptionStatus => Ok((body, Request::ReadExceptionStatus)),
        F::Diagnostics => be_u16(body).map(|(data, sub)| {
            // Sub-function 0 echoes everything after it; the rest carry one 16-bit field, and
            // more bytes are trailing (MAP v1.1b3 §6.8.1).
            let sub_function = DiagnosticSubFunction::from(sub);
            let split = if sub == 0 { data.len() } else { data.len().min(2) };
            let (data, rest) = data.split_at(split);
            (rest, Request::Diagnostics { sub_function, data })
        }),
        F::GetCommEventCounter => Ok((body, Request::GetCommEventCounter)),
        F::GetCommEventLog => Ok((body, Request::GetCommEventLog)),
        F::WriteMultipleCoils => (be_u16, be_u16, length_data(byte)).parse(body).map(|(i, (address, quantity, v))| {
            (i, Request::WriteMultipleCoils { address, quantity, values: Bits::new(v) })
        }),
        F::WriteMultipleRegisters => {
            (be_u16, be_u16, length_data(byte)).parse(body).map(|(i, (address, quantity, v))| {
                (i, Request::WriteMultipleRegisters { address, quantity, values: Registers::new(v) })
            })
        }
        F::ReportServerId => Ok((body, Request::ReportServerId)),
        F::ReadFileRecord => length_data(byte)
            .parse(body)
            .map(|(i, v)| (i, Request::ReadFileRecord { sub_requests: FileSubRequests::new(v) })),
        F::WriteFileRecord => length_data(byte)
            .parse(body)
            .map(|(i, v)| (i, Request::WriteFileRecord { records: FileRecords::write_layout(v) })),
        F::MaskWriteRegister => (be_u16, be_u16, be_u16)
            .parse(body)
            .map(|(i, (address, and_mask, or_mask))| (i, Request::MaskWriteRegister { address, and_mask, or_mask })),
        F::ReadWriteMultipleRegisters => (be_u16, be_u16, be_u16, be_u16, length_data(byte)).parse(body).map(
            |(i, (read_address, read_quantity, write_address, write_quantity, v))| {
                (
                    i,
                    Request::ReadWriteMultipleRegisters {
                        read_address,
                        read_quantity,
                        write_address,
                        write_quantity,
                        values: Registers::new(v),
                    },
                )
            },
        ),
        F::ReadFifoQueue => be_u16(body).map(|(i, address)| (i, Request::ReadFifoQueue { address })),
        F::EncapsulatedInterface => byte(body).and_then(|(i, mei)| match MeiType::from(mei) {
            MeiType::ReadDeviceIdentification => (byte, byte)
                .parse(i)
                .map(|(i, (read_code, object_id))| (i, Request::ReadDeviceIdentification { read_code, object_id })),
            mei_type => Ok((&i[i.len()..], Request::Encapsulated { mei_type, data: i })),
        }),
        F::Other(function) => Ok((&body[body.len()..], Request::Other { function, data: body })),
    };
    parsed.map_err(|_| PduError::Truncated {
        function: fc,
        direction: "request",
        needed: request_len(pdu).needed().unwrap_or(pdu.len() + 1),
        available: pdu.len(),
    })
}

/// Appends a length-prefixed field, refusing data its one-byte count cannot describe.
pub(crate) fn put_counted(out: &mut Vec<u8>, field: &'static str, data: &[u8]) -> Result<(), EncodeError> {
    let n = u8::try_from(data.len()).map_err(|_| EncodeError::TooLong { field, len: data.len(), max: 255 })?;
    out.push(n);
    out.extend_from_slice(data);
    Ok(())
}

pub(crate) fn put_u16s(out: &mut Vec<u8>, words: &[u16]) {
    for w in words {
        out.extend_from_slice(&w.to_be_bytes());
    }
}

impl Request<'_> {
    /// The function code this request carries.
    #[must_use]
    pub fn function(&self) -> F {
        F::from(self.function_byte())
    }

    /// The function byte as on the wire.
    #[must_use]
    pub const fn function_byte(&self) -> u8 {
        match self {
            Self::ReadCoils { .. } => 0x01,
            Self::ReadDiscreteInputs { .. } => 0x02,
            Self::ReadHoldingRegisters { .. } => 0x03,
            Self::ReadInputRegisters { .. } => 0x04,
            Self::WriteSingleCoil { .. } => 0x05,
            Self::WriteSingleRegister { .. } => 0x06,
            Self::ReadExceptionStatus => 0x07,
            Self::Diagnostics { .. } => 0x08,
            Self::GetCommEventCounter => 0x0B,
            Self::GetCommEventLog => 0x0C,
            Self::WriteMultipleCoils { .. } => 0x0F,
            Self::WriteMultipleRegisters { .. } => 0x10,
            Self::ReportServerId => 0x11,
            Self::ReadFileRecord { .. } => 0x14,
            Self::WriteFileRecord { .. } => 0x15,
            Self::MaskWriteRegister { .. } => 0x16,
            Self::ReadWriteMultipleRegisters { .. } => 0x17,
            Self::ReadFifoQueue { .. } => 0x18,
            Self::ReadDeviceIdentification { .. } | Self::Encapsulated { .. } => 0x2B,
            Self::Other { function, .. } => *function,
        }
    }

    /// Appends the PDU's bytes to `out`.
    ///
    /// # Errors
    /// [`EncodeError::TooLong`] when a data slice is longer than its byte-count field allows.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        out.push(self.function_byte());
        match *self {
            Self::ReadCoils { address, quantity }
            | Self::ReadDiscreteInputs { address, quantity }
            | Self::ReadHoldingRegisters { address, quantity }
            | Self::ReadInputRegisters { address, quantity } => put_u16s(out, &[address, quantity]),
            Self::WriteSingleCoil { address, value } | Self::WriteSingleRegister { address, value } => {
                put_u16s(out, &[address, value]);
            }
            Self::ReadExceptionStatus | Self::GetCommEventCounter | Self::GetCommEventLog | Self::ReportServerId => {}
            Self::Diagnostics { sub_function, data } => {
                put_u16s(out, &[sub_function.value()]);
                out.extend_from_slice(data);
            }
            Self::WriteMultipleCoils { address, quantity, values } => {
                put_u16s(out, &[address, quantity]);
                put_counted(out, "coil values", values.as_bytes())?;
            }
            Self::WriteMultipleRegisters { address, quantity, values } => {
                put_u16s(out, &[address, quantity]);
                put_counted(out, "register values", values.as_bytes())?;
            }
            Self::ReadFileRecord { sub_requests } => put_counted(out, "file sub-requests", sub_requests.as_bytes())?,
            Self::WriteFileRecord { records } => put_counted(out, "file records", records.as_bytes())?,
            Self::MaskWriteRegister { address, and_mask, or_mask } => put_u16s(out, &[address, and_mask, or_mask]),
            Self::ReadWriteMultipleRegisters { read_address, read_quantity, write_address, write_quantity, values } => {
                put_u16s(out, &[read_address, read_quantity, write_address, write_quantity]);
                put_counted(out, "register values", values.as_bytes())?;
            }
            Self::ReadFifoQueue { address } => put_u16s(out, &[address]),
            Self::ReadDeviceIdentification { read_code, object_id } => {
                out.extend_from_slice(&[MeiType::ReadDeviceIdentification.value(), read_code, object_id]);
            }
            Self::Encapsulated { mei_type, data } => {
                out.push(mei_type.value());
                out.extend_from_slice(data);
            }
            Self::Other { data, .. } => out.extend_from_slice(data),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MK4 §3.3: `03` Read Holding Registers, address 0x0065 (101), quantity 3.
    const READ_101_X3: &[u8] = &[0x03, 0x00, 0x65, 0x00, 0x03];

    #[test]
    fn parses_read_holding_registers() {
        let (rest, req) = parse_request(READ_101_X3).unwrap();
        assert!(rest.is_empty());
        assert_eq!(req, Request::ReadHoldingRegisters { address: 101, quantity: 3 });
    }

    #[test]
    fn truncated_request_reports_what_it_needed() {
        assert_eq!(
            parse_request(&READ_101_X3[..3]),
            Err(PduError::Truncated { function: 3, direction: "request", needed: 5, available: 3 })
        );
    }

    #[test]
    fn byte_count_that_lies_is_truncation_not_panic() {
        // 0x10, address 0, quantity 1, byte count 200, only 2 data bytes.
        let pdu = [0x10, 0, 0, 0, 1, 200, 0, 1];
        assert_eq!(
            parse_request(&pdu),
            Err(PduError::Truncated { function: 0x10, direction: "request", needed: 206, available: 8 })
        );
    }

    #[test]
    fn unknown_function_kept_raw() {
        let (rest, req) = parse_request(&[0x41, 1, 2, 3]).unwrap();
        assert!(rest.is_empty());
        assert_eq!(req, Request::Other { function: 0x41, data: &[1, 2, 3] });
    }

    #[test]
    fn extra_bytes_are_returned_as_trailing() {
        let (rest, _) = parse_request(&[0x03, 0x00, 0x65, 0x00, 0x03, 0xAA]).unwrap();
        assert_eq!(rest, &[0xAA]);
    }

    #[test]
    fn encode_refuses_a_byte_count_that_cannot_be_written() {
        let big = vec![0u8; 300];
        let req = Request::WriteMultipleRegisters { address: 0, quantity: 150, values: Registers::new(&big) };
        assert_eq!(
            req.encode(&mut Vec::new()),
            Err(EncodeError::TooLong { field: "register values", len: 300, max: 255 })
        );
    }
}
