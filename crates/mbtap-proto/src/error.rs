//! Typed errors of the protocol core. They are `Copy + PartialEq` so tests assert them exactly.
//! A decode *problem* that still lets the frame be shown is a [`Finding`](super::Finding), not an
//! error; these are for bytes that cannot be given the structure their function code demands.

use thiserror::Error;

/// A PDU that cannot be given the structure of its function code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum PduError {
    /// No function code at all.
    #[error("empty PDU: there is no function code")]
    Empty,
    /// The bytes end before the fields the function code requires.
    #[error(
        "function 0x{function:02X} {direction} is too short: its fields need {needed} bytes, the PDU has {available}"
    )]
    Truncated { function: u8, direction: &'static str, needed: usize, available: usize },
}

/// A value that cannot be put on the wire as it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum EncodeError {
    /// A byte-count field cannot describe this many bytes.
    #[error("{field} is {len} bytes, more than its byte-count field can describe ({max})")]
    TooLong { field: &'static str, len: usize, max: usize },
}

/// An application data unit (RTU, ASCII or TCP frame) that cannot be split into its fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum AduError {
    /// Fewer bytes than address + function + check.
    #[error("{mode} frame of {len} bytes is too short: at least {min} are needed")]
    TooShort { mode: &'static str, len: usize, min: usize },
    /// More bytes than the mode's largest frame (RTU: 256, Serial Line v1.02 §2.5.1).
    #[error("{mode} frame of {len} bytes is too long: at most {max} are allowed")]
    TooLong { mode: &'static str, len: usize, max: usize },
    /// The frame's check (CRC, LRC) does not match its bytes.
    #[error("{mode} frame fails its check: its bytes were damaged or it is not one frame")]
    BadCheck { mode: &'static str },
    /// ASCII frame not starting with ':'.
    #[error("ASCII frame must start with ':' (0x3A), found 0x{found:02X}")]
    MissingStart { found: u8 },
    /// A character that is not a hex digit where one is required.
    #[error("ASCII frame has a non-hex character 0x{byte:02X} at position {position}")]
    BadCharacter { position: usize, byte: u8 },
    /// An odd number of hex digits.
    #[error("ASCII frame has an odd number of hex digits ({digits})")]
    OddDigits { digits: usize },
    /// MBAP protocol identifier other than 0 (Modbus Messaging on TCP/IP v1.0b §3.1.3).
    #[error("MBAP protocol identifier is {0}, Modbus requires 0")]
    ProtocolId(u16),
    /// MBAP length field outside 2..=254 (Modbus Messaging on TCP/IP v1.0b §3.1.3).
    #[error("MBAP length field is {0}; it must count the unit id and a PDU, 2 to 254 bytes")]
    Length(u16),
    /// MBAP length disagrees with the bytes given (complete-frame parsing only).
    #[error("MBAP length field says {declared} bytes follow, {actual} do")]
    LengthMismatch { declared: usize, actual: usize },
}
