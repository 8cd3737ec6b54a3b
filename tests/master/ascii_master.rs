//! `read`, `write`, `watch`, `probe` with `--mode ascii`: the same values over a
//! Modbus ASCII line as over RTU, from the same emulated device; against a third-party ASCII
//! slave (pymodbus) too.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use crate::common::{self, BIN, Kill};

fn mbtap(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn raws(o: &Output) -> Vec<i64> {
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()?["raw"].as_i64())
        .collect()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// The MK4 document's recording emulated on a pty in `mode`: its values stay as recorded, so
/// two lines in two modes hold the same.
fn recorded_mk4(name: &str, mode: &str) -> (Kill, PathBuf) {
    let dir = std::env::temp_dir().join(format!("mbtap-ascii-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bus = dir.join(format!("bus-{mode}"));
    let capture = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/mk4-doc-examples-rtu.pcapng");
    let sim = common::simulate(&bus, &["--from", capture.to_str().unwrap(), "--mode", mode, "--duration", "60"]);
    (sim, bus)
}

#[test]
fn read_over_ascii_gives_what_rtu_gives_from_the_same_device() {
    let (_a, ascii) = recorded_mk4("same", "ascii");
    let (_r, rtu) = recorded_mk4("same", "rtu");
    let items = ["--device", "mk4", "--unit", "1", "--format", "jsonl", "holding", "101..105", "input", "400..402"];
    let a = mbtap(&[&["read", ascii.to_str().unwrap(), "--mode", "ascii"][..], &items[..]].concat());
    let r = mbtap(&[&["read", rtu.to_str().unwrap()][..], &items[..]].concat());
    assert!(a.status.success(), "{}", text(&a));
    assert!(r.status.success(), "{}", text(&r));
    assert_eq!(raws(&a), [0, 0, 400, 300, 10, 2, 0, 4], "{}", text(&a));
    assert_eq!(raws(&a), raws(&r));
}

#[test]
fn write_watch_and_probe_speak_ascii_too() {
    let (_a, bus) = recorded_mk4("write", "ascii");
    let port = bus.to_str().unwrap();
    let w = mbtap(&["write", port, "--mode", "ascii", "--device", "mk4", "--unit", "1", "holding 104=2.50"]);
    assert!(w.status.success(), "{}", text(&w));
    let o = mbtap(&[
        "watch",
        port,
        "--mode",
        "ascii",
        "--device",
        "mk4",
        "--unit",
        "1",
        "--count",
        "2",
        "--interval",
        "100ms",
        "--format",
        "jsonl",
        "holding",
        "104",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(raws(&o), [250, 250], "{}", text(&o));
    let p = mbtap(&[
        "probe", port, "--mode", "ascii", "--unit", "1", "--tables", "holding", "--range", "95-110", "--rate", "1000",
        "--format", "json",
    ]);
    let doc: serde_json::Value = serde_json::from_slice(&p.stdout).unwrap_or_default();
    assert_eq!(doc["tables"]["holding_registers"]["present"], serde_json::json!([[101, 105]]), "{}", text(&p));
}

#[test]
fn ascii_over_modbus_tcp_is_refused_saying_why() {
    let o = mbtap(&["read", "127.0.0.1:1", "--mode", "ascii", "holding", "0"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("framed by MBAP, not ASCII"), "{}", text(&o));
}

/// A third-party ASCII slave: pymodbus's serial ASCII server (holding 0–99 = 10 × address) on
/// one end of a pty pair, `mbtap read/write --mode ascii` on the other.
#[test]
#[ignore = "needs socat and pymodbus; .ci/run installs them and runs this with --ignored"]
fn read_and_write_a_pymodbus_ascii_server() {
    let dir = std::env::temp_dir().join(format!("mbtap-ascii-pymodbus-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (_socat, a, b) = common::socat_pair(&dir);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_ascii_server.py");
    let _server = Kill(Command::new("python3").arg(script).arg(&b).stderr(Stdio::null()).spawn().unwrap());
    let port = a.to_str().unwrap();
    let line = ["--mode", "ascii", "--baud", "19200", "--parity", "none", "--format", "jsonl"];
    // pymodbus needs a moment to open its port: a hang guard while it starts.
    let start = std::time::Instant::now();
    let o = loop {
        let o = mbtap(&[&["read", port][..], &line[..], &["holding", "0..4"][..]].concat());
        if o.status.success() || start.elapsed() > std::time::Duration::from_secs(20) {
            break o;
        }
        std::thread::sleep(std::time::Duration::from_millis(300));
    };
    assert_eq!(raws(&o), [0, 10, 20, 30, 40], "{}", text(&o));
    let w = mbtap(&[&["write", port][..], &line[..], &["holding 3=4321"][..]].concat());
    assert!(w.status.success(), "{}", text(&w));
    let o = mbtap(&[&["read", port][..], &line[..], &["holding", "2..4"][..]].concat());
    assert_eq!(raws(&o), [20, 4321, 40], "{}", text(&o));
}
