//! Live serial ports: opening with line settings, the adapter's latency timer, the host clock.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio_serial::{DataBits, Parity as SParity, SerialPortBuilder, StopBits};

use crate::chunk::Timestamp;
use crate::framer::{LineSettings, Parity};

/// Now, as a [`Timestamp`] (the only clock read in mbtap is here and in the other sources).
#[must_use]
pub fn now() -> Timestamp {
    let d = SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or(Duration::ZERO);
    Timestamp(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// A port builder with `line`'s settings.
#[must_use]
pub fn builder(path: &str, line: LineSettings) -> SerialPortBuilder {
    tokio_serial::new(path, line.baud)
        .data_bits(match line.data_bits {
            5 => DataBits::Five,
            6 => DataBits::Six,
            7 => DataBits::Seven,
            _ => DataBits::Eight,
        })
        .parity(match line.parity {
            Parity::None => SParity::None,
            Parity::Even => SParity::Even,
            Parity::Odd => SParity::Odd,
        })
        .stop_bits(if line.stop_bits == 2 { StopBits::Two } else { StopBits::One })
        .timeout(Duration::from_millis(100))
}

/// What happened when we asked for low latency.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LowLatency {
    /// The USB-serial driver's latency timer was set to 1 ms (was `previous` ms).
    Set { previous: String },
    /// The driver has a latency timer but we may not change it.
    Denied { path: String, error: String },
    /// Not a USB-serial adapter with a latency timer (a built-in UART, a pseudo-terminal):
    /// nothing to set.
    NotApplicable,
}

/// On Linux, FTDI-style adapters expose their latency timer (default 16 ms) at
/// `/sys/bus/usb-serial/devices/<tty>/latency_timer`; 1 ms makes reads arrive close to when
/// bytes did. Needs write access to sysfs (root or a udev rule).
#[must_use]
pub fn request_low_latency(path: &str) -> LowLatency {
    let resolved = std::fs::canonicalize(path).unwrap_or_else(|_| path.into());
    let Some(name) = resolved.file_name().and_then(|n| n.to_str()) else { return LowLatency::NotApplicable };
    let timer = format!("/sys/bus/usb-serial/devices/{name}/latency_timer");
    let Ok(previous) = std::fs::read_to_string(&timer) else { return LowLatency::NotApplicable };
    match std::fs::write(&timer, "1") {
        Ok(()) => LowLatency::Set { previous: previous.trim().to_owned() },
        Err(e) => LowLatency::Denied { path: timer, error: e.to_string() },
    }
}
