//! Findings: things a user wants flagged on a frame that still decodes — a quantity outside the
//! spec's limits, a byte count that disagrees, a coil value other than FF00/0000, trailing bytes,
//! a reserved address. They are data on the decoded frame, never errors.
//!
//! Its `pair` module judges a request and its response together (MAP v1.1b3 §6).

use std::fmt;

use super::data::{FILE_REFERENCE_TYPE, FileRecords, bit_bytes};
use super::function::DiagnosticSubFunction;
use super::request::Request;
use super::response::Response;

mod pair;
pub use pair::check_pair;

/// Coil ON in Write Single Coil (MAP v1.1b3 §6.5: "FF 00 hex requests the output to be ON").
pub const COIL_ON: u16 = 0xFF00;
/// Coil OFF in Write Single Coil (MAP v1.1b3 §6.5: "00 00 requests it to be OFF").
pub const COIL_OFF: u16 = 0x0000;

/// Quantity limits, MAP v1.1b3: read coils / discrete inputs 1–2000 (0x7D0, §6.1, §6.2);
/// read registers 1–125 (0x7D, §6.3, §6.4); write coils 1–1968 (0x7B0, §6.11); write registers
/// 1–123 (0x7B, §6.12); 0x17 read 1–125 and write 1–121 (0x79, §6.17); FIFO count ≤ 31 (§6.18).
pub mod limits {
    pub const READ_BITS: (u16, u16) = (1, 2000);
    pub const READ_REGISTERS: (u16, u16) = (1, 125);
    pub const WRITE_BITS: (u16, u16) = (1, 1968);
    pub const WRITE_REGISTERS: (u16, u16) = (1, 123);
    pub const RW_READ_REGISTERS: (u16, u16) = (1, 125);
    pub const RW_WRITE_REGISTERS: (u16, u16) = (1, 121);
    pub const FIFO_COUNT_MAX: u16 = 31;
    /// Byte count of a Read File Record request, 0x07–0xF5 (§6.14).
    pub const READ_FILE_BYTES: (usize, usize) = (0x07, 0xF5);
    /// Request data length of a Write File Record request, 0x09–0xFB (§6.15).
    pub const WRITE_FILE_BYTES: (usize, usize) = (0x09, 0xFB);
    /// Highest unicast server address; 248–255 are reserved (Modbus over Serial Line v1.02 §2.2).
    pub const MAX_UNICAST_ADDRESS: u8 = 247;
}

/// How much a finding matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// Worth knowing, not wrong (a broadcast).
    Info,
    /// Breaks the spec or disagrees with itself.
    Warning,
}

/// One finding on a decoded frame or transaction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Finding {
    QuantityOutOfRange {
        field: &'static str,
        value: u16,
        min: u16,
        max: u16,
    },
    ByteCountMismatch {
        field: &'static str,
        byte_count: usize,
        expected: usize,
    },
    ByteCountOutOfRange {
        field: &'static str,
        byte_count: usize,
        min: usize,
        max: usize,
    },
    InvalidCoilValue {
        value: u16,
    },
    InvalidValue {
        field: &'static str,
        value: u16,
    },
    AddressOverflow {
        address: u16,
        quantity: u16,
    },
    TrailingBytes {
        count: usize,
    },
    OddRegisterBytes {
        byte_count: usize,
    },
    DiagnosticDataLength {
        sub_function: u16,
        len: usize,
    },
    FileReferenceType {
        value: u8,
    },
    MalformedRecords {
        offset: usize,
    },
    BroadcastAddress,
    ResponseFromBroadcastAddress,
    ReservedAddress {
        unit: u8,
    },
    /// An exception to function 0, which does not exist (MAP v1.1b3 §5.1: codes 1–127): a
    /// slave answering garbage, or answering for an absent unit.
    ExceptionToFunctionZero,
    AduTooLong {
        len: usize,
        max: usize,
    },
    LowercaseHex,
    MissingCrLf,
    /// A response that does not answer its request the way the spec says it must.
    ResponseMismatch {
        field: &'static str,
        request: u32,
        response: u32,
    },
}

impl Finding {
    /// A stable snake_case name, for JSON and filters.
    #[must_use]
    pub const fn kind(&self) -> &'static str {
        match self {
            Self::QuantityOutOfRange { .. } => "quantity_out_of_range",
            Self::ByteCountMismatch { .. } => "byte_count_mismatch",
            Self::ByteCountOutOfRange { .. } => "byte_count_out_of_range",
            Self::InvalidCoilValue { .. } => "invalid_coil_value",
            Self::InvalidValue { .. } => "invalid_value",
            Self::AddressOverflow { .. } => "address_overflow",
            Self::TrailingBytes { .. } => "trailing_bytes",
            Self::OddRegisterBytes { .. } => "odd_register_bytes",
            Self::DiagnosticDataLength { .. } => "diagnostic_data_length",
            Self::FileReferenceType { .. } => "file_reference_type",
            Self::MalformedRecords { .. } => "malformed_records",
            Self::BroadcastAddress => "broadcast",
            Self::ResponseFromBroadcastAddress => "response_from_broadcast_address",
            Self::ReservedAddress { .. } => "reserved_address",
            Self::ExceptionToFunctionZero => "exception_to_function_zero",
            Self::AduTooLong { .. } => "adu_too_long",
            Self::LowercaseHex => "lowercase_hex",
            Self::MissingCrLf => "missing_crlf",
            Self::ResponseMismatch { .. } => "response_mismatch",
        }
    }

    /// How much it matters.
    #[must_use]
    pub const fn severity(&self) -> Severity {
        match self {
            Self::BroadcastAddress | Self::LowercaseHex | Self::MissingCrLf => Severity::Info,
            _ => Severity::Warning,
        }
    }
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::QuantityOutOfRange { field, value, min, max } => {
                write!(f, "{field} {value} is outside the spec's limit {min}..={max}")
            }
            Self::ByteCountMismatch { field, byte_count, expected } => {
                write!(f, "{field} byte count is {byte_count}, the quantity needs {expected}")
            }
            Self::ByteCountOutOfRange { field, byte_count, min, max } => {
                write!(f, "{field} byte count {byte_count} is outside {min}..={max}")
            }
            Self::InvalidCoilValue { value } => {
                write!(f, "coil value 0x{value:04X} is neither 0xFF00 (on) nor 0x0000 (off)")
            }
            Self::InvalidValue { field, value } => write!(f, "{field} 0x{value:04X} is not a value the spec allows"),
            Self::AddressOverflow { address, quantity } => {
                write!(f, "address {address} + quantity {quantity} runs past 65535")
            }
            Self::TrailingBytes { count } => write!(f, "{count} trailing byte(s) after the last field"),
            Self::OddRegisterBytes { byte_count } => {
                write!(f, "register byte count {byte_count} is odd: the last byte is half a register")
            }
            Self::DiagnosticDataLength { sub_function, len } => {
                write!(f, "diagnostics sub-function 0x{sub_function:04X} carries {len} data bytes, the spec says 2")
            }
            Self::FileReferenceType { value } => {
                write!(f, "file reference type is {value}, the spec requires {FILE_REFERENCE_TYPE}")
            }
            Self::MalformedRecords { offset } => {
                write!(f, "file records stop making sense at byte {offset} of the record data")
            }
            Self::BroadcastAddress => write!(f, "broadcast (unit 0): no response is expected"),
            Self::ResponseFromBroadcastAddress => write!(f, "a response from unit 0: nobody may answer a broadcast"),
            Self::ReservedAddress { unit } => write!(f, "unit {unit} is in the reserved range 248..=255"),
            Self::ExceptionToFunctionZero => write!(
                f,
                "an exception to function 0, which does not exist: a slave answering garbage, or answering for an absent unit"
            ),
            Self::AduTooLong { len, max } => write!(f, "frame is {len} bytes, longer than the spec's {max}"),
            Self::LowercaseHex => write!(f, "lower-case hex digits (the spec uses upper case)"),
            Self::MissingCrLf => write!(f, "no CR LF at the end of the ASCII frame"),
            Self::ResponseMismatch { field, request, response } => {
                write!(f, "response {field} is {response}, the request's is {request}")
            }
        }
    }
}

fn quantity(out: &mut Vec<Finding>, field: &'static str, value: u16, (min, max): (u16, u16)) {
    if !(min..=max).contains(&value) {
        out.push(Finding::QuantityOutOfRange { field, value, min, max });
    }
}

fn span(out: &mut Vec<Finding>, address: u16, quantity: u16) {
    if u32::from(address) + u32::from(quantity) > 0x1_0000 {
        out.push(Finding::AddressOverflow { address, quantity });
    }
}

fn byte_count(out: &mut Vec<Finding>, field: &'static str, byte_count: usize, expected: usize) {
    if byte_count != expected {
        out.push(Finding::ByteCountMismatch { field, byte_count, expected });
    }
}

fn coil(out: &mut Vec<Finding>, value: u16) {
    if value != COIL_ON && value != COIL_OFF {
        out.push(Finding::InvalidCoilValue { value });
    }
}

fn odd(out: &mut Vec<Finding>, bytes: &[u8]) {
    if bytes.len() % 2 == 1 {
        out.push(Finding::OddRegisterBytes { byte_count: bytes.len() });
    }
}

fn diagnostic(out: &mut Vec<Finding>, sub_function: DiagnosticSubFunction, data: &[u8]) {
    let sub = sub_function.value();
    if sub != 0 && data.len() != 2 {
        out.push(Finding::DiagnosticDataLength { sub_function: sub, len: data.len() });
    }
    if sub_function == DiagnosticSubFunction::RestartCommunicationsOption && data.len() == 2 {
        let v = u16::from_be_bytes([data[0], data[1]]);
        if v != 0x0000 && v != 0xFF00 {
            out.push(Finding::InvalidValue { field: "restart option", value: v });
        }
    }
}

fn records(out: &mut Vec<Finding>, records: FileRecords<'_>) {
    if let Some(offset) = records.malformed_at() {
        out.push(Finding::MalformedRecords { offset });
    }
    if let Some(r) = records.iter().find(|r| r.reference_type != FILE_REFERENCE_TYPE) {
        out.push(Finding::FileReferenceType { value: r.reference_type });
    }
}

fn byte_range(out: &mut Vec<Finding>, field: &'static str, n: usize, (min, max): (usize, usize)) {
    if !(min..=max).contains(&n) {
        out.push(Finding::ByteCountOutOfRange { field, byte_count: n, min, max });
    }
}

/// Findings on a request by itself.
pub fn check_request(req: &Request<'_>, out: &mut Vec<Finding>) {
    match *req {
        Request::ReadCoils { address, quantity } | Request::ReadDiscreteInputs { address, quantity } => {
            quantity_and_span(out, address, quantity, limits::READ_BITS);
        }
        Request::ReadHoldingRegisters { address, quantity } | Request::ReadInputRegisters { address, quantity } => {
            quantity_and_span(out, address, quantity, limits::READ_REGISTERS);
        }
        Request::WriteSingleCoil { value, .. } => coil(out, value),
        Request::Diagnostics { sub_function, data } => diagnostic(out, sub_function, data),
        Request::WriteMultipleCoils { address, quantity, values } => {
            quantity_and_span(out, address, quantity, limits::WRITE_BITS);
            byte_count(out, "coil", values.as_bytes().len(), bit_bytes(quantity));
        }
        Request::WriteMultipleRegisters { address, quantity, values } => {
            quantity_and_span(out, address, quantity, limits::WRITE_REGISTERS);
            byte_count(out, "register", values.as_bytes().len(), usize::from(quantity) * 2);
        }
        Request::ReadFileRecord { sub_requests } => {
            byte_range(out, "read file record", sub_requests.as_bytes().len(), limits::READ_FILE_BYTES);
            if !sub_requests.remainder().is_empty() {
                out.push(Finding::MalformedRecords {
                    offset: sub_requests.as_bytes().len() - sub_requests.remainder().len(),
                });
            }
            if let Some(s) = sub_requests.iter().find(|s| s.reference_type != FILE_REFERENCE_TYPE) {
                out.push(Finding::FileReferenceType { value: s.reference_type });
            }
        }
        Request::WriteFileRecord { records: r } => {
            byte_range(out, "write file record", r.as_bytes().len(), limits::WRITE_FILE_BYTES);
            records(out, r);
        }
        Request::ReadWriteMultipleRegisters { read_address, read_quantity, write_address, write_quantity, values } => {
            quantity_and_span(out, read_address, read_quantity, limits::RW_READ_REGISTERS);
            quantity_and_span(out, write_address, write_quantity, limits::RW_WRITE_REGISTERS);
            byte_count(out, "register", values.as_bytes().len(), usize::from(write_quantity) * 2);
        }
        Request::ReadDeviceIdentification { read_code, .. } => {
            // Read device id code 01–04 (MAP v1.1b3 §6.21).
            if !(1..=4).contains(&read_code) {
                out.push(Finding::InvalidValue { field: "read device id code", value: u16::from(read_code) });
            }
        }
        Request::WriteSingleRegister { .. }
        | Request::ReadExceptionStatus
        | Request::GetCommEventCounter
        | Request::GetCommEventLog
        | Request::ReportServerId
        | Request::MaskWriteRegister { .. }
        | Request::ReadFifoQueue { .. }
        | Request::Encapsulated { .. }
        | Request::Other { .. } => {}
    }
}

fn quantity_and_span(out: &mut Vec<Finding>, address: u16, q: u16, limit: (u16, u16)) {
    quantity(out, "quantity", q, limit);
    span(out, address, q);
}

/// Findings on a response by itself.
pub fn check_response(resp: &Response<'_>, out: &mut Vec<Finding>) {
    if let Response::Exception { function: 0, .. } = resp {
        out.push(Finding::ExceptionToFunctionZero);
    }
    match *resp {
        Response::ReadHoldingRegisters { values }
        | Response::ReadInputRegisters { values }
        | Response::ReadWriteMultipleRegisters { values } => {
            odd(out, values.as_bytes());
            let n = u16::try_from(values.len()).unwrap_or(u16::MAX);
            if n > limits::READ_REGISTERS.1 {
                quantity(out, "register count", n, limits::READ_REGISTERS);
            }
        }
        Response::WriteSingleCoil { value, .. } => coil(out, value),
        Response::Diagnostics { sub_function, data } => diagnostic(out, sub_function, data),
        Response::ReadFileRecord { records: r } | Response::WriteFileRecord { records: r } => records(out, r),
        Response::ReadFifoQueue { fifo_count, values } => {
            odd(out, values.as_bytes());
            if fifo_count > limits::FIFO_COUNT_MAX {
                quantity(out, "FIFO count", fifo_count, (0, limits::FIFO_COUNT_MAX));
            }
            byte_count(out, "FIFO", values.as_bytes().len(), usize::from(fifo_count) * 2);
        }
        Response::ReadDeviceIdentification { more_follows, conformity_level, .. } => {
            // More follows is 00 or FF; conformity level 01–03 or 81–83 (MAP v1.1b3 §6.21).
            if more_follows != 0x00 && more_follows != 0xFF {
                out.push(Finding::InvalidValue { field: "more follows", value: u16::from(more_follows) });
            }
            if !matches!(conformity_level, 0x01..=0x03 | 0x81..=0x83) {
                out.push(Finding::InvalidValue { field: "conformity level", value: u16::from(conformity_level) });
            }
        }
        Response::ReadCoils { .. }
        | Response::ReadDiscreteInputs { .. }
        | Response::WriteSingleRegister { .. }
        | Response::ReadExceptionStatus { .. }
        | Response::GetCommEventCounter { .. }
        | Response::GetCommEventLog { .. }
        | Response::WriteMultipleCoils { .. }
        | Response::WriteMultipleRegisters { .. }
        | Response::ReportServerId { .. }
        | Response::MaskWriteRegister { .. }
        | Response::Encapsulated { .. }
        | Response::Exception { .. }
        | Response::Other { .. } => {}
    }
}

/// Findings on the server address of a frame (Modbus over Serial Line v1.02 §2.2: 0 is
/// broadcast, 1–247 individual, 248–255 reserved).
pub fn check_unit(unit: u8, is_response: bool, out: &mut Vec<Finding>) {
    match unit {
        0 if is_response => out.push(Finding::ResponseFromBroadcastAddress),
        0 => out.push(Finding::BroadcastAddress),
        u if u > limits::MAX_UNICAST_ADDRESS => out.push(Finding::ReservedAddress { unit: u }),
        _ => {}
    }
}
