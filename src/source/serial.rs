//! Live serial ports: opening with line settings, the adapter's latency timer, the host clock.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio_serial::{DataBits, Parity as SParity, SerialPortBuilder, StopBits};

use mbtap_core::chunk::Timestamp;
use mbtap_core::framer::{LineSettings, Parity};

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
    /// The driver has a latency timer (`current` ms) but we may not change it.
    Denied { path: String, error: String, current: Option<u64> },
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
        Err(e) => LowLatency::Denied { path: timer, error: e.to_string(), current: previous.trim().parse().ok() },
    }
}

/// The least delivery latency a live reader allows when the user did not say: a process on a
/// busy machine is not always scheduled the moment its bytes arrive, and a read that returns
/// late would otherwise show as a pause inside a frame.
pub const LIVE_LATENCY_NS: u64 = 1_000_000;

/// Asks for low latency on `port` (telling `err` what came of it) and gives the delivery
/// latency the framer should allow: `said` (`--latency-ms`) when given, else what the
/// adapter's latency timer lets through, at least [`LIVE_LATENCY_NS`].
pub fn prepare_latency(port: &str, said: Option<u64>, err: &mut dyn std::io::Write) -> u64 {
    let low = request_low_latency(port);
    let found = match &low {
        LowLatency::Set { previous } => {
            let _ = writeln!(err, "mbtap: adapter latency timer set to 1 ms (was {previous} ms)");
            LIVE_LATENCY_NS
        }
        LowLatency::Denied { path, error, current } => {
            let timer = current.unwrap_or(16);
            let _ = writeln!(
                err,
                "mbtap: could not set the adapter's latency timer ({path}: {error}); it stays at {timer} ms, so pauses \
                 shorter than that cannot be judged — run as root or add a udev rule for finer timing"
            );
            timer.saturating_mul(1_000_000).max(LIVE_LATENCY_NS)
        }
        LowLatency::NotApplicable => LIVE_LATENCY_NS,
    };
    said.unwrap_or(found)
}
