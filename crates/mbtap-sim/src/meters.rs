//! The built-in energy meters' values, as a household's would move: mains near 230 V and 50 Hz,
//! a load whose current swings slowly between 2 and 6 A per phase at power factor 0.95, and
//! energy counters that only count up (the load's power integrated: a counter read twice never
//! goes back, as Home Assistant's `total_increasing` requires). Addresses are the Eastron maps'
//! (`sdm120`/`sdm230` and `sdm630` profiles); every value is an IEEE 754 float, high word first.

use mbtap_device::profile::Table;

use super::Slave;

/// The power factor of the simulated load.
const PF: f64 = 0.95;
/// Where the import counters start (kWh): a meter that has been in service a while.
const START_KWH: f64 = 1234.5;

/// One phase at `t` seconds: (volts, amps), the phase `i` a little apart from the others.
fn phase(i: u8, t: f64) -> (f64, f64) {
    let k = f64::from(i);
    let volts = 230.0 + 1.5 * (t / 7.0 + 2.1 * k).sin() + (k - 1.0) * 0.4;
    let amps = 4.0 + 2.0 * (t / 30.0 + k).sin();
    (volts, amps)
}

/// Energy phase `i` has taken by `t` (kWh): its power integrated in closed form (the volts held
/// at their mean, 230 V), so the counter rises with the load and never falls.
fn energy(i: u8, t: f64) -> f64 {
    let k = f64::from(i);
    let joules = 230.0 * PF * (4.0 * t - 60.0 * (t / 30.0 + k).cos() + 60.0 * k.cos());
    joules / 3.6e6
}

fn set_f32(slave: &mut Slave, address: u16, value: f64) {
    // Within f32's range by construction (volts, amps, watts, kWh of a household).
    #[allow(clippy::cast_possible_truncation)]
    let bits = (value as f32).to_bits();
    let [a, b, c, d] = bits.to_be_bytes();
    slave.set(Table::InputRegisters, address, u16::from_be_bytes([a, b]));
    slave.set(Table::InputRegisters, address.wrapping_add(1), u16::from_be_bytes([c, d]));
}

/// The angle of the load's power factor, in degrees.
fn angle() -> f64 {
    PF.acos().to_degrees()
}

/// Eastron SDM120 and SDM230 (one phase): input registers 0–94, 258–264, 342–344.
pub fn single_phase(slave: &mut Slave, t: f64) {
    let (v, a) = phase(0, t);
    let (p, s) = (v * a * PF, v * a);
    let q = (s * s - p * p).sqrt();
    let kwh = START_KWH + energy(0, t);
    let kvarh = kwh * (1.0 - PF * PF).sqrt() / PF;
    for (address, value) in [
        (0, v),
        (6, a),
        (12, p),
        (18, s),
        (24, q),
        (30, PF),
        (36, angle()),
        (70, 50.0 + 0.02 * (t / 11.0).sin()),
        (72, kwh),
        (74, 0.0),
        (76, kvarh),
        (78, 0.0),
        (84, p),
        (86, 6.0 * 232.0 * PF),
        (88, p),
        (90, 6.0 * 232.0 * PF),
        (92, 0.0),
        (94, 0.0),
        (258, a),
        (264, 6.0),
        (342, kwh),
        (344, kvarh),
    ] {
        set_f32(slave, address, value);
    }
}

/// Eastron SDM630 (three phases): input registers 0–102, 200–206, 224, 342–344.
pub fn three_phase(slave: &mut Slave, t: f64) {
    let phases: [(f64, f64); 3] = [0, 1, 2].map(|i| phase(i, t));
    let mut totals = (0.0, 0.0, 0.0, 0.0);
    for (i, &(v, a)) in (0u16..).zip(&phases) {
        let (p, s) = (v * a * PF, v * a);
        let q = (s * s - p * p).sqrt();
        for (address, value) in [(0, v), (6, a), (12, p), (18, s), (24, q), (30, PF), (36, angle())] {
            set_f32(slave, address + 2 * i, value);
        }
        totals = (totals.0 + p, totals.1 + s, totals.2 + q, totals.3 + a);
    }
    let (p, s, q, amps) = totals;
    let volts = phases.iter().map(|(v, _)| v).sum::<f64>() / 3.0;
    let kwh = START_KWH + energy(0, t) + energy(1, t) + energy(2, t);
    let kvarh = kwh * (1.0 - PF * PF).sqrt() / PF;
    let line_to_line: [f64; 3] = [0, 1, 2].map(|i| {
        let (a, b) = (phases[i].0, phases[(i + 1) % 3].0);
        // Two phasors 120° apart: |a − b| = √(a² + b² + ab).
        (a * a + b * b + a * b).sqrt()
    });
    for (address, value) in [
        (42, volts),
        (46, amps / 3.0),
        (48, amps),
        (52, p),
        (56, s),
        (60, q),
        (62, PF),
        (66, angle()),
        (70, 50.0 + 0.02 * (t / 11.0).sin()),
        (72, kwh),
        (74, 0.0),
        (76, kvarh),
        (78, 0.0),
        (80, kwh / PF),
        (84, p),
        (86, 3.0 * 6.0 * 232.0 * PF),
        (100, s),
        (102, 3.0 * 6.0 * 232.0),
        (200, line_to_line[0]),
        (202, line_to_line[1]),
        (204, line_to_line[2]),
        (206, line_to_line.iter().sum::<f64>() / 3.0),
        (224, 0.3 + 0.1 * (t / 13.0).sin()),
        (342, kwh),
        (344, kvarh),
    ] {
        set_f32(slave, address, value);
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;

    fn f32_at(slave: &Slave, address: u16) -> f32 {
        let hi = slave.get(Table::InputRegisters, address).unwrap();
        let lo = slave.get(Table::InputRegisters, address + 1).unwrap();
        f32::from_bits(u32::from(hi) << 16 | u32::from(lo))
    }

    fn meter(name: &str) -> Slave {
        let profile = mbtap_device::profile::builtin::get(name).unwrap().unwrap();
        Slave::new(Arc::new(profile), 1)
    }

    #[test]
    fn a_three_phase_meter_reads_as_mains_and_its_energy_only_counts_up() {
        let mut m = meter("sdm630");
        let mut last = 0.0;
        for step in 0..200 {
            three_phase(&mut m, f64::from(step) * 17.0);
            for address in [0, 2, 4] {
                assert!((225.0..235.0).contains(&f32_at(&m, address)), "volts at {address}");
            }
            assert!((390.0..410.0).contains(&f32_at(&m, 200)), "line to line");
            assert!((49.9..50.1).contains(&f32_at(&m, 70)), "hertz");
            let kwh = f32_at(&m, 342);
            assert!(kwh >= last && kwh >= 1234.0, "total kWh {kwh} after {last}");
            last = kwh;
            let p = f32_at(&m, 52);
            let sum = f32_at(&m, 12) + f32_at(&m, 14) + f32_at(&m, 16);
            assert!((p - sum).abs() < 0.1, "total power {p} is the phases' {sum}");
        }
        assert!(last > 1234.5 + 2.0, "an hour of a ~2.6 kW load counts: {last}");
    }

    #[test]
    fn a_single_phase_meter_reads_as_mains() {
        for name in ["sdm120", "sdm230"] {
            let mut m = meter(name);
            single_phase(&mut m, 100.0);
            assert!((225.0..235.0).contains(&f32_at(&m, 0)), "{name}");
            assert!((2.0..=6.0).contains(&f32_at(&m, 6)), "{name}");
            assert!(f32_at(&m, 342) > 1234.0, "{name}");
        }
    }
}
