//! Line settings and the RTU timing they imply (Modbus over Serial Line v1.02 §2.5.1.1).

use std::fmt;
use std::str::FromStr;

/// Parity bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Parity {
    None,
    Even,
    Odd,
}

/// Serial transmission mode (Serial Line v1.02 §2.5: RTU, binary with a CRC and silences between
/// frames; ASCII, hex characters between `:` and CR LF with an LRC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SerialMode {
    Rtu,
    Ascii,
}

impl SerialMode {
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Rtu => "rtu",
            Self::Ascii => "ascii",
        }
    }
}

/// Serial line settings. The default is the spec's: 19200 baud, 8 data bits, even parity, 1 stop
/// bit (Modbus over Serial Line v1.02 §2.5.1: "even parity is required" by default, §3.3.1
/// 19200 default baud rate).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LineSettings {
    pub baud: u32,
    pub data_bits: u8,
    pub parity: Parity,
    pub stop_bits: u8,
}

impl Default for LineSettings {
    fn default() -> Self {
        Self { baud: 19_200, data_bits: 8, parity: Parity::Even, stop_bits: 1 }
    }
}

/// Above this baud rate the spec fixes t1.5 and t3.5 (§2.5.1.1: "for baud rates greater than
/// 19200 Bps, fixed values for the 2 timers should be used").
pub const FIXED_TIMERS_ABOVE_BAUD: u32 = 19_200;
/// Fixed inter-character timeout t1.5 above 19200 baud: 750 µs (§2.5.1.1).
pub const FIXED_T15_NS: u64 = 750_000;
/// Fixed inter-frame delay t3.5 above 19200 baud: 1.750 ms (§2.5.1.1).
pub const FIXED_T35_NS: u64 = 1_750_000;

impl LineSettings {
    /// Bits on the wire per character: start + data + parity + stop.
    #[must_use]
    pub const fn bits_per_char(&self) -> u32 {
        1 + self.data_bits as u32 + if matches!(self.parity, Parity::None) { 0 } else { 1 } + self.stop_bits as u32
    }

    /// One character time in nanoseconds (at least 1).
    #[must_use]
    pub fn char_ns(&self) -> u64 {
        let baud = u64::from(self.baud.max(1));
        (u64::from(self.bits_per_char()) * 1_000_000_000).div_ceil(baud).max(1)
    }

    /// t1.5: the longest silence allowed between two characters of one frame.
    #[must_use]
    pub fn t15_ns(&self) -> u64 {
        if self.baud > FIXED_TIMERS_ABOVE_BAUD { FIXED_T15_NS } else { self.char_ns() * 3 / 2 }
    }

    /// t3.5: the shortest silence between two frames.
    #[must_use]
    pub fn t35_ns(&self) -> u64 {
        if self.baud > FIXED_TIMERS_ABOVE_BAUD { FIXED_T35_NS } else { self.char_ns() * 7 / 2 }
    }
}

impl fmt::Display for LineSettings {
    /// `19200 8E1`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = match self.parity {
            Parity::None => 'N',
            Parity::Even => 'E',
            Parity::Odd => 'O',
        };
        write!(f, "{} {}{}{}", self.baud, self.data_bits, p, self.stop_bits)
    }
}

impl FromStr for LineSettings {
    type Err = String;

    /// Parses `19200 8E1` / `19200-8E1` / `19200,8,E,1`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let cleaned: String = s.chars().filter(|c| !matches!(c, ' ' | '-' | ',' | '/')).collect();
        let digits: String = cleaned.chars().take_while(char::is_ascii_digit).collect();
        let rest = &cleaned[digits.len()..];
        let bad =
            || format!("line settings {s:?} are not like \"19200 8E1\" (baud, data bits, parity N/E/O, stop bits)");
        if digits.len() < 3 || rest.len() != 2 {
            return Err(bad());
        }
        let baud: u32 = digits[..digits.len() - 1].parse().map_err(|_| bad())?;
        let data_bits = digits[digits.len() - 1..].parse::<u8>().map_err(|_| bad())?;
        let mut r = rest.chars();
        let parity = match r.next().map(|c| c.to_ascii_uppercase()) {
            Some('N') => Parity::None,
            Some('E') => Parity::Even,
            Some('O') => Parity::Odd,
            _ => return Err(bad()),
        };
        let stop_bits = r.next().and_then(|c| c.to_digit(10)).ok_or_else(bad)?;
        let stop_bits = u8::try_from(stop_bits).map_err(|_| bad())?;
        if !(5..=8).contains(&data_bits) || !(1..=2).contains(&stop_bits) || baud == 0 {
            return Err(bad());
        }
        Ok(Self { baud, data_bits, parity, stop_bits })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_timers() {
        let l = LineSettings { baud: 9600, ..LineSettings::default() };
        // 11 bits at 9600 baud = 1145.8 µs per character.
        assert_eq!(l.char_ns(), 1_145_834);
        assert_eq!(l.t35_ns(), 4_010_419);
        let fast = LineSettings { baud: 115_200, ..LineSettings::default() };
        assert_eq!((fast.t15_ns(), fast.t35_ns()), (750_000, 1_750_000));
    }

    #[test]
    fn parse_and_display() {
        let l: LineSettings = "9600 8N2".parse().unwrap();
        assert_eq!(l, LineSettings { baud: 9600, data_bits: 8, parity: Parity::None, stop_bits: 2 });
        assert_eq!(l.to_string(), "9600 8N2");
        assert!("9600 9X1".parse::<LineSettings>().is_err());
    }
}
