//! The emulated devices as every shell serving them holds them (`simulate`'s pseudo-terminal,
//! the bridge's fronts through [`crate::bridge::emulated`]): one set, one lock, one clock for
//! their values, and the one rule for how long a device takes to answer.

use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use mbtap_sim::Device;

/// The devices, shared with whatever else serves them (the pseudo-terminal of `simulate`).
#[derive(Debug)]
pub struct Emulated {
    pub devices: Mutex<Vec<Device>>,
    /// The clock the devices' values move by.
    pub started: Instant,
    /// A fixed time to answer (`--turnaround-ms`); `None`: each device's own (a recording's
    /// median), else `usual_turnaround`.
    pub turnaround: Option<Duration>,
    pub usual_turnaround: Duration,
}

impl Emulated {
    /// The answer of the device at `unit` and how long it takes to give it; `None` when no
    /// device answers (another unit, a broadcast).
    pub fn answer(&self, unit: u8, pdu: &[u8]) -> Option<(Vec<u8>, Duration)> {
        let t = self.started.elapsed().as_secs_f64();
        let mut devices = self.devices.lock().unwrap_or_else(PoisonError::into_inner);
        let (answer, own) = mbtap_sim::device::answer(&mut devices, unit, pdu, t)?;
        let wait = self.turnaround.or_else(|| own.map(Duration::from_nanos)).unwrap_or(self.usual_turnaround);
        Some((answer, wait))
    }
}
