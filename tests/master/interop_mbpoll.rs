//! `mbtap simulate` against a real third-party master: mbpoll (libmodbus-based) reads and writes
//! the simulated devices through mbtap's pseudo-terminal, and what it gets is checked against the
//! profiles and the documents. Needs mbpoll: `#[ignore]`d in a plain `cargo test`, run by
//! `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::path::Path;
use std::process::Command;

use crate::common;
use common::Kill;

/// Runs mbpoll on `bus` with `args` (reads pass `-1` to poll once; mbpoll refuses it on writes,
/// which it does once anyway); returns (success, stdout + stderr).
fn mbpoll(bus: &Path, args: &[&str]) -> (bool, String) {
    mbpoll_write(bus, args, &[])
}

/// mbpoll with values to write, which follow the device on its command line.
fn mbpoll_write(bus: &Path, args: &[&str], write: &[&str]) -> (bool, String) {
    let out = Command::new("mbpoll")
        .args(["-m", "rtu", "-b", "19200", "-P", "even", "-0", "-o", "2"])
        .args(args)
        .arg(bus)
        .args(write)
        .output()
        .expect("mbpoll must be installed for this test");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.success(), text)
}

/// The `[address]: value` lines of mbpoll's output.
fn values(text: &str) -> Vec<(u16, i64)> {
    text.lines()
        .filter_map(|l| {
            let (a, v) = l.trim().strip_prefix('[')?.split_once("]:")?;
            Some((a.parse().ok()?, v.trim().parse().ok()?))
        })
        .collect()
}

fn simulator(name: &str) -> (Kill, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("mbtap-sim-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bus = dir.join("bus");
    let sim = common::simulate(&bus, &["--duration", "60"]);
    (sim, bus)
}

/// The brief's own check: four plausible MK4 voltages in 0.1 V, the fourth their average.
#[test]
#[ignore = "needs mbpoll; .ci/run installs it and runs this with --ignored"]
fn mbpoll_reads_plausible_mk4_voltages() {
    let (_sim, bus) = simulator("volts");
    let (ok, text) = mbpoll(&bus, &["-a", "1", "-t", "3", "-r", "430", "-c", "4", "-1"]);
    assert!(ok, "{text}");
    let v = values(&text);
    assert_eq!(v.iter().map(|(a, _)| *a).collect::<Vec<_>>(), [430, 431, 432, 433], "{text}");
    for (a, raw) in &v {
        assert!((2000..=2600).contains(raw), "register {a} = {raw}: not a mains voltage in 0.1 V\n{text}");
    }
    // Within 0.1 V of the mean of the three (each phase is itself rounded to 0.1 V).
    let sum = v[0].1 + v[1].1 + v[2].1;
    assert!((3 * v[3].1 - sum).abs() <= 3, "433 must be the average of 430–432: {v:?}");
}

/// Writes as the MK4 document says: in range kept, out of range clamped (§3.3), and the answer
/// to a register outside the map is exception 02.
#[test]
#[ignore = "needs mbpoll; .ci/run installs it and runs this with --ignored"]
fn mbpoll_writes_are_kept_clamped_or_refused() {
    let (_sim, bus) = simulator("write");
    // 108, overflow set point, range 0–10000.
    let (ok, text) = mbpoll_write(&bus, &["-a", "1", "-t", "4", "-r", "108"], &["1234"]);
    assert!(ok, "{text}");
    let (_, text) = mbpoll(&bus, &["-a", "1", "-t", "4", "-r", "108", "-c", "1", "-1"]);
    assert_eq!(values(&text), [(108, 1234)], "{text}");
    let (ok, text) = mbpoll_write(&bus, &["-a", "1", "-t", "4", "-r", "108"], &["30000"]);
    assert!(ok, "a clamped write is still acknowledged: {text}");
    let (_, text) = mbpoll(&bus, &["-a", "1", "-t", "4", "-r", "108", "-c", "1", "-1"]);
    assert_eq!(values(&text), [(108, 10000)], "clamped to the top of the range: {text}");
    let (_, text) = mbpoll(&bus, &["-a", "1", "-t", "4", "-r", "1000", "-c", "1", "-1"]);
    assert!(text.contains("Illegal data address"), "{text}");
}

/// The MKZP answers its own address and 247, holding registers only (03/06).
#[test]
#[ignore = "needs mbpoll; .ci/run installs it and runs this with --ignored"]
fn mbpoll_reaches_the_mkzp_at_its_address_and_247() {
    let (_sim, bus) = simulator("mkzp");
    for address in ["17", "247"] {
        let (ok, text) = mbpoll(&bus, &["-a", address, "-t", "4", "-r", "50", "-c", "3", "-1"]);
        assert!(ok, "address {address}: {text}");
        assert_eq!(values(&text).len(), 3, "{text}");
    }
    let (_, text) = mbpoll(&bus, &["-a", "17", "-t", "3", "-r", "50", "-c", "1", "-1"]);
    assert!(text.contains("Illegal function"), "input registers are not an MKZP function: {text}");
}
