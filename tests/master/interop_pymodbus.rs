//! `mbtap simulate` against pymodbus, a real third-party master, in RTU and ASCII: what it reads
//! and writes through mbtap's pseudo-terminal is checked against the profiles and documents.
//! Needs python3 with pymodbus: `#[ignore]`d in a plain `cargo test`, run by `.ci/run` with
//! `--ignored` after it installs pymodbus.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::{Command, Stdio};

use crate::common;
use common::{BIN, Kill, wait_for};

fn run(mode: &str) -> serde_json::Value {
    let dir = std::env::temp_dir().join(format!("mbtap-pymodbus-{mode}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bus = dir.join("bus");
    let _sim = Kill(
        Command::new(BIN)
            .args(["simulate", "--mode", mode, "--link", bus.to_str().unwrap(), "--duration", "60"])
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    wait_for(&bus);
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_master.py");
    let out = Command::new("python3").arg(script).arg(&bus).arg(mode).output().expect("python3 must be installed");
    assert!(
        out.status.success(),
        "pymodbus master failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn check(r: &serde_json::Value) {
    let volts: Vec<u64> = r["mk4_voltages"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    assert_eq!(volts.len(), 4, "{r}");
    assert!(volts.iter().all(|v| (2000..=2600).contains(v)), "MK4 voltages in 0.1 V: {volts:?}");
    assert_eq!(r["mk4_write_108"], true, "{r}");
    assert_eq!(r["mk4_read_108"], serde_json::json!([2500]), "a write in range is kept: {r}");
    assert_eq!(r["mk4_write_108_clamped"], true, "{r}");
    assert_eq!(r["mk4_read_108_after_clamp"], serde_json::json!([10000]), "MK4 clamps to the range top: {r}");
    assert_eq!(r["mk4_outside_map_exception"], 2, "{r}");
    assert_eq!(r["mkzp_input_registers_exception"], 1, "the MKZP has no function 04: {r}");
    assert_eq!(r["mkzp_currents"].as_array().unwrap().len(), 3, "{r}");
    // Exactly one of M1/M2 runs at a time; M3 is the standby pump.
    let coils: Vec<bool> = r["mk4_coils"].as_array().unwrap().iter().map(|c| c.as_bool().unwrap()).collect();
    assert_eq!(coils.iter().filter(|c| **c).count(), 1, "{coils:?}");
    assert!(!coils[2]);
    assert_eq!(r["display_totals"].as_array().unwrap().len(), 4, "{r}");
}

#[test]
#[ignore = "needs python3 with pymodbus; .ci/run installs it and runs this with --ignored"]
fn pymodbus_rtu_master_reads_and_writes_the_simulated_devices() {
    check(&run("rtu"));
}

#[test]
#[ignore = "needs python3 with pymodbus; .ci/run installs it and runs this with --ignored"]
fn pymodbus_ascii_master_reads_and_writes_the_simulated_devices() {
    check(&run("ascii"));
}
