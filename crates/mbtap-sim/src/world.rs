//! Values that move the way a real installation's do, as a function of time (an input, like
//! everywhere in the core). The MK4's mains voltages wander around 230 V with a small phase
//! imbalance and their average is what it reports at 433; its pumps take turns (M1 and M2
//! alternate, a minute each) and their currents follow their state. The Display's first
//! level sensor loses the fuel its first flow meter counts.
//! Addresses and scales are the documents' (MK4 §3.4; Display input registers).

use mbtap_device::profile::Table;

use super::Slave;

/// MK4 phase voltages L1, L2, L3 and their average, in 0.1 V (430–433).
const MK4_VOLTAGES: u16 = 430;
/// MK4 motor M1–M3 states (403–405): 0 stopped, 3 running.
const MK4_MOTOR_STATE: u16 = 403;
/// MK4 per-motor currents from 435, four registers each (A, C, average, imbalance %), 0.1 A.
const MK4_MOTOR_CURRENTS: u16 = 435;
/// MK4 coils 0–2 mirror the motors (on while running).
const MK4_MOTOR_COILS: u16 = 0;
/// Each MK4 pump runs this long before handing over (s).
const PUMP_TURN_S: f64 = 60.0;

/// Display totals: level sensors (0–1) and flow meters (2–3), u32 high word first, 0.01 l.
const DISPLAY_TOTALS: u16 = 0;
/// Display level sensor 1: volume (u32, 0.01 l), percent (0.01 %), temperature (°C).
const DISPLAY_LEVEL_1: u16 = 4;
/// Display flow meter 1: total volume (i32, 0.01 l) at 44, consumption rate (0.1 l/h) at 56.
const DISPLAY_FLOW_1: u16 = 44;
const DISPLAY_FLOW_1_RATE: u16 = 56;
/// The simulated tank and engine: 60 000 l, starting at 48 000 l, burning 180 l/h.
const TANK_L: f64 = 60_000.0;
const START_L: f64 = 48_000.0;
const BURN_L_PER_H: f64 = 180.0;

/// Moves the values of `slave` to time `t` (seconds since the simulation started).
pub fn step(slave: &mut Slave, t: f64) {
    match slave.profile().meta.name.as_str() {
        "mk4" => mk4(slave, t),
        "display" => display(slave, t),
        "mkzp" => mkzp(slave, t),
        "sdm120" | "sdm230" => super::meters::single_phase(slave, t),
        "sdm630" => super::meters::three_phase(slave, t),
        "em24" | "em340" => super::meters::carlo_gavazzi(slave, t),
        "dtsu666" => super::meters::dtsu666(slave, t),
        "ddsu666" => super::meters::ddsu666(slave, t),
        "b21" => super::meters::abb(slave, t, 1),
        "b23" | "b24" => super::meters::abb(slave, t, 3),
        _ => {}
    }
}

fn mk4(slave: &mut Slave, t: f64) {
    // Three phases a little apart (imbalance of a few volts), each drifting slowly.
    let phases: [f64; 3] = [0.0, 2.1, 4.2].map(|phase| 230.0 + 1.5 * (t / 7.0 + phase).sin() + (phase - 2.1) * 0.4);
    let average = phases.iter().sum::<f64>() / 3.0;
    for (a, v) in (MK4_VOLTAGES..).zip(phases.into_iter().chain([average])) {
        slave.set(Table::InputRegisters, a, tenths(v));
    }
    // M1 and M2 take turns; M3 is the standby pump and stays stopped.
    let turn = (t / PUMP_TURN_S).floor();
    let running_m1 = turn.rem_euclid(2.0) < 1.0;
    for (motor, running) in (0u16..).zip([running_m1, !running_m1, false]) {
        slave.set(Table::InputRegisters, MK4_MOTOR_STATE + motor, if running { 3 } else { 0 });
        slave.set(Table::Coils, MK4_MOTOR_COILS + motor, u16::from(running));
        let base = MK4_MOTOR_CURRENTS + motor * 4;
        let (a, c) = if running {
            let ripple = 0.3 * (t * 1.3 + f64::from(motor)).sin();
            (12.4 + ripple, 12.1 - ripple)
        } else {
            (0.0, 0.0)
        };
        let avg = f64::midpoint(a, c);
        let imbalance = if avg > 0.0 { (a - c).abs() / avg * 100.0 } else { 0.0 };
        for (i, v) in [a, c, avg].into_iter().enumerate() {
            slave.set(Table::InputRegisters, base + u16::try_from(i).unwrap_or(0), tenths(v));
        }
        slave.set(Table::InputRegisters, base + 3, whole(imbalance));
    }
}

/// MK4 alarm log (input registers 500–839): 20 records of 17 registers, newest first.
const MK4_ALARM_LOG: u16 = 500;
const MK4_ALARM_RECORD: u16 = 17;
const MK4_ALARM_RECORDS: u16 = 20;
/// MK4 motor M1–M3 alarm codes (415–417; 1 = overcurrent).
const MK4_MOTOR_ALARM: u16 = 415;
/// The simulated clock starts at this date and time (day, month, year, hour, minute — the
/// order of the log's date registers).
const CLOCK_START: [u16; 5] = [22, 11, 2026, 8, 0];

/// The running MK4 pump trips on overcurrent at time `t`: its alarm code is set (415–417) and a
/// record goes to the top of the alarm log, older records moving down and the oldest dropped —
/// with the date, the currents and the voltages at the moment of the alarm (MK4 §3.4).
/// Returns the log's alarm code (21 = M1 overcurrent, 31 = M2), or none on another device.
pub fn mk4_pump_trip(slave: &mut Slave, t: f64) -> Option<u16> {
    if slave.profile().meta.name != "mk4" {
        return None;
    }
    step(slave, t);
    let motor = (0u16..3).find(|&m| slave.get(Table::InputRegisters, MK4_MOTOR_STATE + m) == Some(3))?;
    slave.set(Table::InputRegisters, MK4_MOTOR_ALARM + motor, 1);
    let code = 21 + 10 * motor;
    let log_end = MK4_ALARM_LOG + MK4_ALARM_RECORD * MK4_ALARM_RECORDS;
    // Newest first: shift every record one place down, from the bottom up.
    for a in (MK4_ALARM_LOG + MK4_ALARM_RECORD..log_end).rev() {
        let older = slave.get(Table::InputRegisters, a - MK4_ALARM_RECORD).unwrap_or(0);
        slave.set(Table::InputRegisters, a, older);
    }
    let ir = |a: u16| slave.get(Table::InputRegisters, a).unwrap_or(0);
    let currents = [0u16, 1, 2].map(|m| ir(MK4_MOTOR_CURRENTS + m * 4 + 2));
    let voltages = [0u16, 1, 2].map(|p| ir(MK4_VOLTAGES + p));
    let mut record = vec![code];
    record.extend_from_slice(&clock(t));
    record.extend_from_slice(&currents);
    record.extend_from_slice(&voltages);
    // Reset time (12–16): zeros until someone resets the alarm.
    record.resize(usize::from(MK4_ALARM_RECORD), 0);
    for (a, v) in (MK4_ALARM_LOG..).zip(record) {
        slave.set(Table::InputRegisters, a, v);
    }
    Some(code)
}

/// The simulated wall clock at `t` s: day, month, year, hour, minute (within the start day's
/// month, which is all a demo run needs).
fn clock(t: f64) -> [u16; 5] {
    let [day, month, year, hour, minute] = CLOCK_START;
    let minutes = u64::from(hour) * 60 + u64::from(minute) + u64::from(whole32((t / 60.0).floor()));
    let days = minutes / (24 * 60);
    let at = |v: u64| u16::try_from(v).unwrap_or(u16::MAX);
    [day.saturating_add(at(days)), month, year, at(minutes / 60 % 24), at(minutes % 60)]
}

/// MKZP-0.4 registers (holding): phase currents in % of nominal (50–52), insulation
/// resistance in kΩ (53), asymmetry % (54), voltage in V (60), System_Status bits (66).
const MKZP_CURRENTS: u16 = 50;
const MKZP_INSULATION: u16 = 53;
const MKZP_ASYMMETRY: u16 = 54;
const MKZP_VOLTAGE: u16 = 60;
const MKZP_STATUS: u16 = 66;
/// System_Status bits 10 (motor on) and 11 (start complete).
const MKZP_RUNNING: u16 = 1 << 10 | 1 << 11;

fn mkzp(slave: &mut Slave, t: f64) {
    // A motor at about 85 % of its nominal current, phases a little apart.
    let currents: [f64; 3] = [0.0, 2.1, 4.2].map(|p| 85.0 + 2.0 * (t / 5.0 + p).sin() + (p - 2.1));
    for (a, v) in (MKZP_CURRENTS..).zip(currents) {
        slave.set(Table::HoldingRegisters, a, whole(v));
    }
    let max = currents.iter().copied().fold(f64::MIN, f64::max);
    let min = currents.iter().copied().fold(f64::MAX, f64::min);
    slave.set(Table::HoldingRegisters, MKZP_ASYMMETRY, whole((max - min) / max * 100.0));
    slave.set(Table::HoldingRegisters, MKZP_INSULATION, 9_500);
    slave.set(Table::HoldingRegisters, MKZP_VOLTAGE, whole(380.0 + 3.0 * (t / 11.0).sin()));
    slave.set(Table::HoldingRegisters, MKZP_STATUS, MKZP_RUNNING);
}

fn display(slave: &mut Slave, t: f64) {
    let burnt = BURN_L_PER_H * t / 3600.0;
    let level = (START_L - burnt).max(0.0);
    let hundredths = |litres: f64| whole32(litres * 100.0);
    set_u32(slave, DISPLAY_LEVEL_1, hundredths(level));
    slave.set(Table::InputRegisters, DISPLAY_LEVEL_1 + 2, whole(level / TANK_L * 10_000.0));
    slave.set(Table::InputRegisters, DISPLAY_LEVEL_1 + 3, 18);
    set_u32(slave, DISPLAY_FLOW_1, hundredths(burnt));
    slave.set(Table::InputRegisters, DISPLAY_FLOW_1_RATE, whole(BURN_L_PER_H * 10.0));
    set_u32(slave, DISPLAY_TOTALS, hundredths(level));
    set_u32(slave, DISPLAY_TOTALS + 2, hundredths(burnt));
}

/// A 32-bit value, high word first (the Display document's order).
fn set_u32(slave: &mut Slave, address: u16, v: u32) {
    let [a, b, c, d] = v.to_be_bytes();
    slave.set(Table::InputRegisters, address, u16::from_be_bytes([a, b]));
    slave.set(Table::InputRegisters, address + 1, u16::from_be_bytes([c, d]));
}

/// Volts or amperes to the registers' 0.1 units.
fn tenths(v: f64) -> u16 {
    whole(v * 10.0)
}

/// Rounded into 0..=65535 (the values here stay far inside it).
fn whole(v: f64) -> u16 {
    // Clamped into range first, so the conversion is exact.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let r = v.round().clamp(0.0, f64::from(u16::MAX)) as u16;
    r
}

/// Rounded into 0..=u32::MAX.
fn whole32(v: f64) -> u32 {
    // Clamped into range first, so the conversion is exact.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let r = v.round().clamp(0.0, f64::from(u32::MAX)) as u32;
    r
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use mbtap_device::profile::builtin;

    fn slave(name: &str) -> Slave {
        Slave::new(Arc::new(builtin::get(name).unwrap().unwrap()), 1)
    }

    #[test]
    fn mk4_voltages_are_plausible_and_move() {
        let mut s = slave("mk4");
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

    #[test]
    fn mk4_pump_currents_follow_the_pump_state() {
        let mut s = slave("mk4");
        for t in [10.0, 70.0] {
            step(&mut s, t);
            for motor in 0..3u16 {
                let running = s.get(Table::InputRegisters, 403 + motor) == Some(3);
                let current = s.get(Table::InputRegisters, 437 + motor * 4).unwrap();
                assert_eq!(running, current > 0, "t={t} M{}: running {running}, current {current}", motor + 1);
                assert_eq!(s.get(Table::Coils, motor), Some(u16::from(running)));
            }
        }
        step(&mut s, 10.0);
        assert_eq!(s.get(Table::InputRegisters, 403), Some(3), "M1 runs first");
        step(&mut s, 70.0);
        assert_eq!(s.get(Table::InputRegisters, 404), Some(3), "then M2");
    }

    #[test]
    fn an_mk4_pump_trip_goes_to_the_top_of_the_alarm_log() {
        let mut s = slave("mk4");
        assert_eq!(s.get(Table::InputRegisters, 500), Some(0), "the log starts empty");
        // M1 runs in the first minute, M2 in the second.
        assert_eq!(mk4_pump_trip(&mut s, 10.0), Some(21));
        assert_eq!(s.get(Table::InputRegisters, 415), Some(1), "M1 overcurrent");
        assert_eq!(mk4_pump_trip(&mut s, 3690.0), Some(31));
        let record = |s: &Slave, n: u16| {
            (0..17).map(|i| s.get(Table::InputRegisters, 500 + n * 17 + i).unwrap()).collect::<Vec<_>>()
        };
        let newest = record(&s, 0);
        let older = record(&s, 1);
        assert_eq!(newest[0], 31);
        assert_eq!(&newest[1..6], &[22, 11, 2026, 9, 1], "61½ minutes after 08:00");
        assert!(newest[7] > 0 && newest[6] == 0, "M2's current recorded, M1 stopped: {newest:?}");
        assert!((2200..2400).contains(&newest[9]), "phase A voltage {}", newest[9]);
        assert_eq!(older[0], 21);
        assert_eq!(&older[1..6], &[22, 11, 2026, 8, 0]);
        for _ in 0..30 {
            mk4_pump_trip(&mut s, 10.0);
        }
        assert_eq!(record(&s, 19)[0], 21, "twenty records kept, the oldest dropped");
        assert_eq!(mk4_pump_trip(&mut slave("mkzp"), 10.0), None);
    }

    #[test]
    fn mkzp_reports_a_running_motor() {
        let mut s = slave("mkzp");
        step(&mut s, 12.0);
        for a in 50..53 {
            let v = s.get(Table::HoldingRegisters, a).unwrap();
            assert!((75..=95).contains(&v), "{a} = {v} %");
        }
        assert_eq!(s.get(Table::HoldingRegisters, 66), Some(0b1100_0000_0000), "motor on, start complete");
    }

    #[test]
    fn display_level_falls_while_the_flow_meter_counts() {
        let mut s = slave("display");
        let read32 = |s: &Slave, a: u16| {
            u32::from(s.get(Table::InputRegisters, a).unwrap()) << 16
                | u32::from(s.get(Table::InputRegisters, a + 1).unwrap())
        };
        step(&mut s, 0.0);
        let (level0, flow0) = (read32(&s, 4), read32(&s, 44));
        step(&mut s, 3600.0);
        let (level1, flow1) = (read32(&s, 4), read32(&s, 44));
        assert_eq!(level0 - level1, 18_000, "180 l in an hour, in 0.01 l");
        assert_eq!(flow1 - flow0, 18_000, "what the level lost, the flow meter counted");
    }
}
