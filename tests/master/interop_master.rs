//! `mbtap read`/`write` against real third-party peers: mbpoll (libmodbus) reads the same
//! registers of the same simulated device; pymodbus's Modbus TCP server is read and written;
//! socat's pty pair with `mbtap sniff` on the far end proves that refused writes and
//! `--dry-run` put nothing on the line. Needs mbpoll, python3 with pymodbus and socat:
//! `#[ignore]`d in a plain `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use crate::common;
use common::{BIN, Kill, socat_pair, wait_port};

fn mbtap(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn raws(o: &Output) -> Vec<(u64, i64)> {
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|j| (j["address"].as_u64().unwrap(), j["raw"].as_i64().unwrap()))
        .collect()
}

fn dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-imaster-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
#[ignore = "needs mbpoll; .ci/run installs it and runs this with --ignored"]
fn read_gives_the_values_mbpoll_reads() {
    let bus = dir("mbpoll").join("bus");
    let _sim = common::simulate(&bus, &["--duration", "60"]);
    // The MK4's set points 104–112 (holding registers, stable while nobody writes).
    let o = Command::new("mbpoll")
        .args(["-m", "rtu", "-b", "19200", "-P", "even", "-0", "-o", "2", "-1"])
        .args(["-a", "1", "-t", "4", "-r", "104", "-c", "9"])
        .arg(&bus)
        .output()
        .expect("mbpoll must be installed for this test");
    assert!(o.status.success(), "{}", text(&o));
    let theirs: Vec<(u64, i64)> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| {
            let (a, v) = l.trim().strip_prefix('[')?.split_once("]:")?;
            Some((a.parse().ok()?, v.trim().parse().ok()?))
        })
        .collect();
    assert_eq!(theirs.len(), 9, "{}", text(&o));
    let o = mbtap(&["read", bus.to_str().unwrap(), "--device", "mk4", "--format", "jsonl", "104..112"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(raws(&o), theirs);
}

#[test]
#[ignore = "needs python3 with pymodbus; .ci/run installs it and runs this with --ignored"]
fn read_and_write_a_pymodbus_tcp_server() {
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_tcp_server.py");
    let _server =
        Kill(Command::new("python3").arg(script).arg(port.to_string()).stderr(Stdio::null()).spawn().unwrap());
    wait_port(port);
    let target = format!("127.0.0.1:{port}");
    // The server holds 10 × address in holding registers 0–99.
    let o = mbtap(&["read", &target, "--format", "jsonl", "holding", "0..9"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(raws(&o), (0u8..10).map(|a| (u64::from(a), 10 * i64::from(a))).collect::<Vec<_>>());
    let o = mbtap(&["write", &target, "--format", "jsonl", "holding 5=777"]);
    assert!(o.status.success(), "{}", text(&o));
    let o = mbtap(&["read", &target, "--format", "jsonl", "holding", "4..6"]);
    assert_eq!(raws(&o), [(4, 40), (5, 777), (6, 60)]);
    // A unit the server does not have: an exception or silence, reported, exit 1.
    let o = mbtap(&["read", &target, "--unit", "9", "--timeout-ms", "500", "--format", "jsonl", "holding", "0"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
}

/// The control write on the wire: unit 1, function 06, address 105 (0x0069), value 150
/// (0x0096), CRC 0xB8D9 (low byte first).
const SENT: &str = "01 06 0069 0096 D9B8";

/// Sniffs the far end of a socat pty pair while `write` runs on the near end; the frames heard.
fn heard_while(write_args: &[&str]) -> (Output, Vec<serde_json::Value>) {
    let d = dir(&format!("line{}", write_args.len()));
    let (_socat, a, b) = socat_pair(&d);
    let sniff = Command::new(BIN)
        .args(["sniff", b.to_str().unwrap(), "--format", "jsonl", "--duration", "2"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let mut args = vec!["write", a.to_str().unwrap(), "--timeout-ms", "100"];
    args.extend_from_slice(write_args);
    let o = mbtap(&args);
    let out = sniff.wait_with_output().unwrap();
    let events = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|e| e["event"] == "frame" || e["event"] == "noise" || e["event"] == "glitch")
        .collect();
    (o, events)
}

#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn refused_and_dry_run_writes_put_nothing_on_the_line() {
    let (o, heard) = heard_while(&["--device", "mk4", "Level 2 set point=150"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(heard.is_empty(), "a refused write reached the line: {heard:?}");
    let (o, heard) = heard_while(&["--device", "mk4", "--dry-run", "Level 2 set point=1.50"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(heard.is_empty(), "--dry-run reached the line: {heard:?}");
    // The control: the same write, sent, is heard (nobody answers, so it fails).
    let (o, heard) = heard_while(&["--device", "mk4", "Level 2 set point=1.50"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let sent = SENT.replace(' ', "");
    assert!(heard.iter().any(|e| e["hex"].as_str().unwrap().eq_ignore_ascii_case(&sent)), "{heard:?}");
}
