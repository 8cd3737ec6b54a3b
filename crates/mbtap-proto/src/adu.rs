//! One owned view over a frame of any mode, for callers that take frames from users (the
//! `decode` command) rather than from a framer: mode detection, the check, ADU-level findings.

use super::ascii::{ASCII_MAX_LEN, ASCII_START, parse_ascii};
use super::error::AduError;
use super::findings::Finding;
use super::rtu::{RTU_MAX_LEN, parse_rtu};
use super::tcp::{MBAP_LEN, parse_tcp};

/// Transmission mode / framing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    Rtu,
    Ascii,
    Tcp,
}

impl Mode {
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Rtu => "RTU",
            Self::Ascii => "ASCII",
            Self::Tcp => "TCP",
        }
    }
}

/// The frame check and whether it held.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    Crc {
        received: u16,
        computed: u16,
    },
    Lrc {
        received: u8,
        computed: u8,
    },
    /// TCP has no checksum; the MBAP length agreeing with the bytes is the check.
    Mbap,
}

impl Check {
    #[must_use]
    pub const fn ok(self) -> bool {
        match self {
            Self::Crc { received, computed } => received == computed,
            Self::Lrc { received, computed } => received == computed,
            Self::Mbap => true,
        }
    }
}

/// A frame split into unit, PDU and check, whatever its mode.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Adu {
    pub mode: Mode,
    pub unit: u8,
    pub pdu: Vec<u8>,
    pub check: Check,
    /// TCP only.
    pub transaction_id: Option<u16>,
    /// Findings on the framing itself (length, ASCII case, missing CR LF).
    pub findings: Vec<Finding>,
}

/// Guesses the mode of one whole frame: ':' starts ASCII; otherwise RTU when the CRC holds,
/// TCP when the MBAP header is consistent with the length, else RTU (with a failed CRC).
#[must_use]
pub fn detect_mode(wire: &[u8]) -> Mode {
    if wire.first() == Some(&ASCII_START) {
        return Mode::Ascii;
    }
    if parse_rtu(wire).is_ok_and(|f| f.check_ok()) {
        return Mode::Rtu;
    }
    if wire.len() > MBAP_LEN && parse_tcp(wire).is_ok() {
        return Mode::Tcp;
    }
    Mode::Rtu
}

/// Splits one whole frame in `mode` (detected when `None`).
///
/// # Errors
/// The mode's [`AduError`] when the bytes cannot be split into unit, PDU and check.
pub fn parse_adu(wire: &[u8], mode: Option<Mode>) -> Result<Adu, AduError> {
    let mode = mode.unwrap_or_else(|| detect_mode(wire));
    let mut findings = Vec::new();
    let adu = match mode {
        Mode::Rtu => {
            let f = parse_rtu(wire)?;
            if wire.len() > RTU_MAX_LEN {
                findings.push(Finding::AduTooLong { len: wire.len(), max: RTU_MAX_LEN });
            }
            Adu {
                mode,
                unit: f.unit,
                pdu: f.pdu.to_vec(),
                check: Check::Crc { received: f.crc_received, computed: f.crc_computed },
                transaction_id: None,
                findings,
            }
        }
        Mode::Ascii => {
            let f = parse_ascii(wire)?;
            if wire.len() > ASCII_MAX_LEN {
                findings.push(Finding::AduTooLong { len: wire.len(), max: ASCII_MAX_LEN });
            }
            if f.lowercase {
                findings.push(Finding::LowercaseHex);
            }
            if !f.terminated {
                findings.push(Finding::MissingCrLf);
            }
            Adu {
                mode,
                unit: f.unit(),
                pdu: f.pdu().to_vec(),
                check: Check::Lrc { received: f.lrc_received(), computed: f.lrc_computed },
                transaction_id: None,
                findings,
            }
        }
        Mode::Tcp => {
            let f = parse_tcp(wire)?;
            Adu {
                mode,
                unit: f.header.unit,
                pdu: f.pdu.to_vec(),
                check: Check::Mbap,
                transaction_id: Some(f.header.transaction_id),
                findings,
            }
        }
    };
    Ok(adu)
}
