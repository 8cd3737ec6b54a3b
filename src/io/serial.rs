//! Live serial ports: opening with line settings, the adapter's latency timer, the host clock.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio_serial::{DataBits, Parity as SParity, SerialPortBuilder, StopBits};

use mbtap_analysis::chunk::Timestamp;
use mbtap_analysis::framer::{LineSettings, Parity};

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
    /// The USB-serial driver's latency timer is set to 1 ms (from `previous` ms).
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

/// `usb:VID:PID[:SERIAL]` (hex ids, as `lsusb` prints them): the adapter wherever the kernel
/// numbered it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UsbMatch {
    pub vid: u16,
    pub pid: u16,
    pub serial: Option<String>,
}

impl UsbMatch {
    /// `usb:0403:6001` or `usb:0403:6001:A10K1234`; `None` for anything else (a path).
    #[must_use]
    pub fn parse(spec: &str) -> Option<Self> {
        let rest = spec.strip_prefix("usb:")?;
        let mut parts = rest.splitn(3, ':');
        let vid = u16::from_str_radix(parts.next()?, 16).ok()?;
        let pid = u16::from_str_radix(parts.next()?, 16).ok()?;
        let serial = parts.next().filter(|s| !s.is_empty()).map(str::to_owned);
        Some(Self { vid, pid, serial })
    }

    fn matches(&self, vid: u16, pid: u16, serial: Option<&str>) -> bool {
        self.vid == vid && self.pid == pid && self.serial.as_deref().is_none_or(|s| Some(s) == serial)
    }
}

/// The path to open for a port as the user named it: a path as it is (a `/dev/serial/by-id/…`
/// link follows its adapter when the kernel renumbers it), `usb:VID:PID[:SERIAL]` looked up
/// among the USB serial ports present now.
///
/// # Errors
/// No USB serial port matches (or more than one without a serial number to choose).
pub fn resolve_port(spec: &str) -> std::io::Result<String> {
    let Some(want) = UsbMatch::parse(spec) else { return Ok(spec.to_owned()) };
    let ports = tokio_serial::available_ports().map_err(std::io::Error::other)?;
    let found: Vec<String> = ports
        .into_iter()
        .filter(|p| match &p.port_type {
            tokio_serial::SerialPortType::UsbPort(u) => want.matches(u.vid, u.pid, u.serial_number.as_deref()),
            _ => false,
        })
        .map(|p| p.port_name)
        .collect();
    match found.as_slice() {
        [one] => Ok(one.clone()),
        [] => Err(std::io::Error::new(std::io::ErrorKind::NotFound, format!("no USB serial port matches {spec}"))),
        many => Err(std::io::Error::other(format!(
            "{} USB serial ports match {spec} ({}): add the adapter's serial number, usb:VID:PID:SERIAL",
            many.len(),
            many.join(", ")
        ))),
    }
}

/// Which device a port name leads to now, to tell the user when it changed (an adapter that
/// came back as another `/dev/ttyUSBn` behind the same by-id link or USB ids).
#[derive(Debug, Default)]
pub struct DeviceWatch {
    last: Option<std::path::PathBuf>,
}

impl DeviceWatch {
    /// `spec` was just opened as `path`: a line to log when the device behind it changed.
    pub fn opened(&mut self, spec: &str, path: &str) -> Option<String> {
        let device = std::fs::canonicalize(path).ok()?;
        let said = match &self.last {
            Some(old) if *old != device => Some(format!("{spec} is now {} (was {})", device.display(), old.display())),
            _ => None,
        };
        self.last = Some(device);
        said
    }
}

/// Opens a port as the user named it ([`resolve_port`]); says on `err` when the device behind
/// the name is not the one `watch` saw last.
///
/// # Errors
/// The name resolves to no port, or the port does not open.
pub fn open_named(
    spec: &str,
    line: LineSettings,
    watch: &mut DeviceWatch,
    err: &mut dyn std::io::Write,
) -> std::io::Result<tokio_serial::SerialStream> {
    use tokio_serial::SerialPortBuilderExt as _;
    let path = resolve_port(spec)?;
    let port = builder(&path, line).open_native_async()?;
    if let Some(said) = watch.opened(spec, &path) {
        let _ = writeln!(err, "mbtap: {said}");
    }
    Ok(port)
}

#[cfg(test)]
mod port_name_tests {
    use super::*;

    #[test]
    fn usb_ids_with_and_without_a_serial_number() {
        let m = UsbMatch::parse("usb:0403:6001:A10K").unwrap();
        assert_eq!((m.vid, m.pid, m.serial.as_deref()), (0x0403, 0x6001, Some("A10K")));
        assert!(m.matches(0x0403, 0x6001, Some("A10K")));
        assert!(!m.matches(0x0403, 0x6001, Some("B2")));
        let any = UsbMatch::parse("usb:1a86:7523").unwrap();
        assert!(any.matches(0x1a86, 0x7523, None) && any.matches(0x1a86, 0x7523, Some("x")));
        assert_eq!(UsbMatch::parse("/dev/ttyUSB0"), None);
        assert_eq!(UsbMatch::parse("usb:zz:1"), None);
        assert_eq!(resolve_port("/dev/ttyUSB0").unwrap(), "/dev/ttyUSB0");
    }
}
