//! The protocol core: parsers and encoders for Modbus RTU, ASCII and TCP frames and the PDU of
//! every public function code, both directions. Pure: no I/O, no clock, no async.
//!
//! Specs cited throughout: *MODBUS Application Protocol Specification v1.1b3* (MAP),
//! *MODBUS over Serial Line Specification and Implementation Guide v1.02*, and
//! *MODBUS Messaging on TCP/IP Implementation Guide v1.0b*.
//!
//! Layers: [`checksum`] (CRC-16, LRC) → [`rtu`] / [`ascii`] / [`tcp`] (ADU) →
//! [`request`] / [`response`] (PDU) → [`decode`] (direction hint) and [`findings`].
//! [`length`] says how long a frame of a function code must be; [`answer_end`] uses it to find
//! where an answer arriving byte by byte ends (the bridge's question); [`hexinput`] reads frames
//! that people paste as text; [`request_frames`] frames requests as a slave hears them (the
//! serial fronts' one framer); [`serial_line`] holds the
//! line settings and the RTU timing they imply; [`table`] the data model's four tables.
//!
//! This crate depends on `nom` and `thiserror` only: every parser here is fuzzed from
//! `fuzz/` without compiling the analysis, the terminal or an async runtime.
//!
//! Beside the layers: [`adu`] (one owned view over a frame of any mode, for frames users give),
//! [`duration`] (durations as people type them), [`rfc2217`] (the Telnet COM-port codec of serial
//! servers).

pub mod adu;
pub mod answer_end;
pub mod ascii;
pub mod checksum;
pub mod data;
pub mod decode;
pub mod duration;
pub mod error;
pub mod findings;
pub mod function;
pub mod hexinput;
pub mod length;
pub mod request;
pub mod request_frames;
pub mod response;
pub mod rfc2217;
pub mod rtu;
pub mod serial_line;
pub mod table;
pub mod tcp;

pub use adu::{Adu, Check, Mode, detect_mode, parse_adu};
pub use ascii::{AsciiFrame, encode_ascii, parse_ascii};
pub use checksum::{crc16, lrc};
pub use data::{Bits, DeviceObjects, FileRecords, FileSubRequests, Registers};
pub use decode::{DecodedPdu, DirectionHint, Pdu, PduDecode, decode_pdu, pair_findings};
pub use error::{AduError, EncodeError, PduError};
pub use findings::{Finding, Severity};
pub use function::{DiagnosticSubFunction, EXCEPTION_FLAG, ExceptionCode, FunctionCode, MeiType};
pub use length::{PduLength, answer_fits, answer_len, request_len, request_len_problem, response_len};
pub use request::{Request, parse_request};
pub use response::{Response, parse_response};
pub use rtu::{RtuFrame, encode_rtu, parse_rtu};
pub use table::Table;
pub use tcp::{MbapHeader, Streaming, TcpFrame, encode_tcp, parse_mbap, parse_tcp, parse_tcp_frame};
