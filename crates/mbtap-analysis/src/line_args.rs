//! Line settings as users give them (command line) and as captures store them (the interface
//! description `mbtap rtu 19200 8E1 latency_ns=0`), merged: command line > file > default.

use crate::analyzer::SerialMode;
use crate::framer::{LineSettings, Parity};

/// Settings a user or a file may give; `None` means "not said".
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LineOverrides {
    pub mode: Option<SerialMode>,
    pub baud: Option<u32>,
    pub data_bits: Option<u8>,
    pub parity: Option<Parity>,
    pub stop_bits: Option<u8>,
    pub latency_ns: Option<u64>,
    /// A capture's link type to read as raw serial bytes besides 147–162 (`--link-type`).
    pub link_type: Option<u16>,
}

impl LineOverrides {
    /// `self` where said, else `other`.
    #[must_use]
    pub fn or(self, other: Self) -> Self {
        Self {
            mode: self.mode.or(other.mode),
            baud: self.baud.or(other.baud),
            data_bits: self.data_bits.or(other.data_bits),
            parity: self.parity.or(other.parity),
            stop_bits: self.stop_bits.or(other.stop_bits),
            latency_ns: self.latency_ns.or(other.latency_ns),
            link_type: self.link_type.or(other.link_type),
        }
    }

    /// The settings, defaults filled in (19200 8E1 RTU, Modbus over Serial Line v1.02 §2.5.1).
    #[must_use]
    pub fn resolve(self) -> (SerialMode, LineSettings, Option<u64>) {
        let d = LineSettings::default();
        let mode = self.mode.unwrap_or(SerialMode::Rtu);
        // ASCII's default character is 7 data bits (§2.5.2).
        let data_bits = self.data_bits.unwrap_or(if mode == SerialMode::Ascii { 7 } else { d.data_bits });
        let line = LineSettings {
            baud: self.baud.unwrap_or(d.baud),
            data_bits,
            parity: self.parity.unwrap_or(d.parity),
            stop_bits: self.stop_bits.unwrap_or(d.stop_bits),
        };
        // "Not given" stays distinct from 0 (commands rebuilt it from the option).
        (mode, line, self.latency_ns)
    }

    /// The description written into a capture's interface block.
    #[must_use]
    pub fn describe(mode: SerialMode, line: LineSettings, latency_ns: u64) -> String {
        let p = match line.parity {
            Parity::None => 'N',
            Parity::Even => 'E',
            Parity::Odd => 'O',
        };
        format!("mbtap {} {} {}{}{} latency_ns={latency_ns}", mode.name(), line.baud, line.data_bits, p, line.stop_bits)
    }

    /// Reads a description written by [`Self::describe`]; anything else gives nothing.
    #[must_use]
    pub fn from_description(s: &str) -> Self {
        let mut out = Self::default();
        let mut words = s.split_whitespace();
        if words.next() != Some("mbtap") {
            return out;
        }
        for w in words {
            match w {
                "rtu" => out.mode = Some(SerialMode::Rtu),
                "ascii" => out.mode = Some(SerialMode::Ascii),
                _ => {
                    if let Some(v) = w.strip_prefix("latency_ns=") {
                        out.latency_ns = v.parse().ok();
                    } else if let Ok(b) = w.parse::<u32>() {
                        out.baud = Some(b);
                    } else if let Ok(l) = format!("9600 {w}").parse::<LineSettings>() {
                        out.data_bits = Some(l.data_bits);
                        out.parity = Some(l.parity);
                        out.stop_bits = Some(l.stop_bits);
                    }
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn description_round_trips() {
        let line = LineSettings { baud: 9600, data_bits: 8, parity: Parity::None, stop_bits: 2 };
        let d = LineOverrides::describe(SerialMode::Ascii, line, 16_000_000);
        let back = LineOverrides::from_description(&d).resolve();
        assert_eq!(back, (SerialMode::Ascii, line, Some(16_000_000)));
    }

    #[test]
    fn command_line_wins_over_file() {
        let cli = LineOverrides { baud: Some(115_200), ..LineOverrides::default() };
        let file = LineOverrides::from_description("mbtap rtu 9600 8N1 latency_ns=0");
        let (_, line, _) = cli.or(file).resolve();
        assert_eq!((line.baud, line.parity), (115_200, Parity::None));
    }
}
