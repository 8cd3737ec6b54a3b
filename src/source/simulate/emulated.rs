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
    /// `simulate --read-only`: a request that could change a device is answered exception 01
    /// (the core's one read-only rule, `mbtap_gateway::rules::read_only_safe`), whatever front
    /// it came by; the bridge's fronts refuse it at admission before it gets here.
    pub read_only: bool,
}

impl Emulated {
    /// The answer of the device at `unit` and how long it takes to give it; `None` when no
    /// device answers (another unit, a broadcast).
    pub fn answer(&self, unit: u8, pdu: &[u8]) -> Option<(Vec<u8>, Duration)> {
        let t = self.started.elapsed().as_secs_f64();
        let mut devices = self.devices.lock().unwrap_or_else(PoisonError::into_inner);
        if self.read_only && !mbtap_gateway::rules::read_only_safe(pdu) {
            // Only a device that is there refuses (another unit's request stays another's), and
            // a broadcast is never answered (Serial Line v1.02 §2.2).
            let function = pdu.first().copied().unwrap_or(0);
            let here = devices.iter().any(|d| d.address() == unit);
            return here.then(|| (vec![function | mbtap_proto::EXCEPTION_FLAG, 0x01], self.usual_turnaround));
        }
        let (answer, own) = mbtap_sim::device::answer(&mut devices, unit, pdu, t)?;
        let wait = self.turnaround.or_else(|| own.map(Duration::from_nanos)).unwrap_or(self.usual_turnaround);
        Some((answer, wait))
    }
}
