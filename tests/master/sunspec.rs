//! `mbtap read … --device sunspec` against a simulated SunSpec device (pymodbus, on
//! Modbus TCP and as RTU on a pseudo-terminal) gives the same values as pysunspec2 — the SunSpec
//! Alliance's reference implementation — reading the same device: a chain with a repeated model
//! (two three-phase inverters) and a model nobody defines (shown raw, by ID). Needs pymodbus,
//! pysunspec2 and socat (CI installs them): run with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use crate::common;

use std::path::Path;
use std::process::{Command, Stdio};

use common::{Kill, socat_pair, wait_for, wait_port};

const BIN: &str = env!("CARGO_BIN_EXE_mbtap");
const POINTS: [&str; 13] = ["Mn", "Md", "Vr", "SN", "DA", "A", "AphA", "AphB", "PhVphA", "W", "Hz", "WH", "TmpCab"];

fn script(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop").join(name)
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Compares mbtap's reading of every point pysunspec2 read, for `target` (`tcp PORT` or
/// `rtu PATH` for the reference; mbtap's target and line options).
fn same_values_as_pysunspec2(reference: [&str; 2], target: &str, line: &[&str]) {
    let r = Command::new("python3").arg(script("pysunspec_read.py")).args(reference).output().unwrap();
    assert!(r.status.success(), "pysunspec2: {}", String::from_utf8_lossy(&r.stderr));
    let expected: serde_json::Map<String, serde_json::Value> = serde_json::from_slice(&r.stdout).unwrap();
    let names: Vec<String> = expected.keys().cloned().collect();
    assert!(names.len() >= 20 && names.iter().any(|n| n.starts_with("inverter_three_phase[2].")), "{names:?}");
    let mut args = vec!["read", target, "--device", "sunspec", "--format", "jsonl"];
    args.extend_from_slice(line);
    args.extend(names.iter().map(String::as_str));
    args.push("64999");
    let out = Command::new(BIN).args(&args).output().unwrap();
    assert!(out.status.success(), "mbtap: {}", String::from_utf8_lossy(&out.stderr));
    let rows: Vec<serde_json::Value> =
        String::from_utf8_lossy(&out.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    for (name, want) in &expected {
        let row = rows.iter().find(|r| r["name"] == name.as_str()).unwrap_or_else(|| panic!("{name} not in {rows:?}"));
        let got = &row["value"];
        let same = match (want.as_f64(), got.as_f64()) {
            (Some(a), Some(b)) => (a - b).abs() < 1e-9,
            _ => want == got,
        };
        assert!(same, "{name}: pysunspec2 {want}, mbtap {got}");
    }
    // The model nobody defines: shown by its ID, its registers raw.
    let raw = rows.iter().find(|r| r["name"] == "64999.raw").unwrap();
    assert_eq!(raw["value"], "0001000200030004");
    assert!(POINTS.iter().all(|p| names.iter().any(|n| n.ends_with(&format!(".{p}")))), "{names:?}");
}

#[test]
#[ignore = "needs pymodbus and pysunspec2; .ci/run installs them and runs this with --ignored"]
fn sunspec_over_tcp_reads_as_pysunspec2_reads() {
    let port = free_port();
    let _device = Kill(
        Command::new("python3")
            .arg(script("sunspec_device.py"))
            .args(["tcp", &port.to_string()])
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    wait_port(port);
    let target = format!("127.0.0.1:{port}");
    same_values_as_pysunspec2(["tcp", &port.to_string()], &target, &[]);
    // What it discovered, written as a profile, names and scales the same registers for every
    // profile-driven command (here: a plain profile read).
    let profile = std::env::temp_dir().join(format!("mbtap-sunspec-{}.toml", std::process::id()));
    let out = Command::new(BIN)
        .args(["profiles", "import", "--from", &target, "--name", "sim", "-o", profile.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("skipped model 64999"), "{err}");
    let out = Command::new(BIN)
        .args(["read", &target, "--device", profile.to_str().unwrap(), "--format", "jsonl"])
        .args(["inverter_three_phase.W", "inverter_three_phase.PhVphA", "inverter_three_phase[2].W"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let values: Vec<serde_json::Value> =
        text.lines().map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["value"].clone()).collect();
    assert_eq!(values, [serde_json::json!(4500.0), serde_json::json!(230.1), serde_json::json!(2000.0)], "{text}");
    std::fs::remove_file(&profile).unwrap();
    // `watch` and `write` take `--device sunspec` too: the chain becomes a profile at start.
    let out = Command::new(BIN)
        .args(["watch", &target, "--device", "sunspec", "--count", "2", "--interval", "100ms", "--format", "jsonl"])
        .arg("inverter_three_phase.W")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(text.lines().filter(|l| l.contains("\"value\":4500")).count(), 2, "{text}");
}

#[test]
#[ignore = "needs pymodbus, pysunspec2 and socat; .ci/run installs them and runs this with --ignored"]
fn sunspec_over_rtu_on_a_pty_reads_as_pysunspec2_reads() {
    let d = std::env::temp_dir().join(format!("mbtap-sunspec-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let (_socat, device_end, master_end) = socat_pair(&d);
    let _device = Kill(
        Command::new("python3")
            .arg(script("sunspec_device.py"))
            .args(["rtu", device_end.to_str().unwrap()])
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    wait_for(&master_end);
    // Give the server a moment to open its end (a request sent before is lost, and retried).
    std::thread::sleep(std::time::Duration::from_millis(1500));
    same_values_as_pysunspec2(
        ["rtu", master_end.to_str().unwrap()],
        master_end.to_str().unwrap(),
        &["--baud", "19200", "--parity", "none", "--retries", "2"],
    );
}
