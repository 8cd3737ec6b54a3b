//! Values that move the way a real installation's do, as a function of time (an input, like
//! everywhere in the core): the MK4's mains voltages wander around 230 V with a small phase
//! imbalance, and their average is what the MK4 reports at 433.

use crate::profile::Table;

use super::Slave;

/// MK4 phase voltages L1, L2, L3 and their average, in 0.1 V (MK4 document §3.4, 430–433).
const MK4_VOLTAGES: u16 = 430;

/// Moves the values of `slave` to time `t` (seconds since the simulation started).
pub fn step(slave: &mut Slave, t: f64) {
    if slave.profile().meta.name == "mk4" {
        // Three phases a little apart (imbalance of a few volts), each drifting slowly.
        let phases: [f64; 3] = [0.0, 2.1, 4.2].map(|phase| 230.0 + 1.5 * (t / 7.0 + phase).sin() + (phase - 2.1) * 0.4);
        let tenths = phases.map(to_tenths);
        let average = to_tenths(phases.iter().sum::<f64>() / 3.0);
        for (a, v) in (MK4_VOLTAGES..).zip(tenths.into_iter().chain([average])) {
            slave.set(Table::InputRegisters, a, v);
        }
    }
}

/// Volts to the register's 0.1 V units (values here stay far inside u16).
fn to_tenths(volts: f64) -> u16 {
    let t = (volts * 10.0).round().clamp(0.0, f64::from(u16::MAX));
    // Inside 0..=65535 after the clamp, so the conversion is exact.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let v = t as u16;
    v
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::profile::builtin;

    #[test]
    fn mk4_voltages_are_plausible_and_move() {
        let mut s = Slave::new(Arc::new(builtin::get("mk4").unwrap().unwrap()), 1);
        let mut seen = std::collections::BTreeSet::new();
        for t in 0..60 {
            step(&mut s, f64::from(t));
            for a in 430..434 {
                let v = s.get(Table::InputRegisters, a).unwrap();
                assert!((2200..=2400).contains(&v), "{a} = {v}");
                seen.insert(v);
            }
        }
        assert!(seen.len() > 4, "values should move: {seen:?}");
    }
}
