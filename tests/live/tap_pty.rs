//! `mbtap tap` on real pseudo-terminals: an application talks to a device through mbtap's pty
//! link; the bytes arrive untouched both ways, both directions are analysed with the direction
//! known (echo-shaped frames included), and the two-port recording replays the same. Needs
//! socat: `#[ignore]`d in a plain `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::io::{Read, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::common;
use common::{BIN, Kill, wait_for};

/// MK4 §3.3 read of 3 holding registers from 101, and the answer.
const READ_REQ: &[u8] = &[0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4];
const READ_RESP: &[u8] = &[0x01, 0x03, 0x06, 0x00, 0x00, 0x00, 0x00, 0x01, 0x90, 0x20, 0x89];
/// MK4 §3.3 write of register 108 = 10: the response echoes the request byte for byte.
const WRITE_108: &[u8] = &[0x01, 0x06, 0x00, 0x6C, 0x00, 0x0A, 0xC9, 0xD0];

fn open(path: &std::path::Path) -> Box<dyn tokio_serial::SerialPort> {
    tokio_serial::new(path.to_str().unwrap(), 19_200).timeout(Duration::from_secs(5)).open().unwrap()
}

fn read_exact(port: &mut dyn tokio_serial::SerialPort, n: usize) -> Vec<u8> {
    let mut got = vec![0u8; n];
    port.read_exact(&mut got).unwrap();
    got
}

#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn tap_relays_untouched_and_knows_directions() {
    let dir = std::env::temp_dir().join(format!("mbtap-tap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (bus, dev, app, rec) = (dir.join("bus"), dir.join("dev"), dir.join("app"), dir.join("rec.pcapng"));
    let _socat = Kill(
        Command::new("socat")
            .args([format!("pty,raw,echo=0,link={}", bus.display()), format!("pty,raw,echo=0,link={}", dev.display())])
            .spawn()
            .expect("socat must be installed for this test"),
    );
    wait_for(&bus);
    wait_for(&dev);
    let mut tap = Kill(
        Command::new(BIN)
            .args(["tap", bus.to_str().unwrap(), "--link", app.to_str().unwrap(), "--format", "jsonl"])
            .args(["--record", rec.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mut out = tap.0.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        out.read_to_string(&mut s).unwrap();
        s
    });
    wait_for(&app);

    // The device answers two requests, as a Modbus slave would.
    let device = std::thread::spawn(move || {
        let mut d = open(&dev);
        assert_eq!(read_exact(d.as_mut(), READ_REQ.len()), READ_REQ);
        std::thread::sleep(Duration::from_millis(5));
        d.write_all(READ_RESP).unwrap();
        assert_eq!(read_exact(d.as_mut(), WRITE_108.len()), WRITE_108);
        std::thread::sleep(Duration::from_millis(5));
        d.write_all(WRITE_108).unwrap();
    });
    let mut a = open(&app);
    a.write_all(READ_REQ).unwrap();
    assert_eq!(read_exact(a.as_mut(), READ_RESP.len()), READ_RESP, "the response reaches the application untouched");
    std::thread::sleep(Duration::from_millis(20));
    a.write_all(WRITE_108).unwrap();
    assert_eq!(read_exact(a.as_mut(), WRITE_108.len()), WRITE_108);
    device.join().unwrap();
    std::thread::sleep(Duration::from_millis(100));

    let pid = tap.0.id().to_string();
    assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
    let live = reader.join().unwrap();
    let events: Vec<serde_json::Value> = live.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let frames: Vec<(u64, String, String)> = events
        .iter()
        .filter(|j| j["event"] == "frame")
        .map(|j| {
            (
                j["port"].as_u64().unwrap(),
                j["direction"].as_str().unwrap().to_owned(),
                j["hex"].as_str().unwrap().to_owned(),
            )
        })
        .collect();
    assert_eq!(
        frames,
        vec![
            (0, "request".into(), "01030065000315d4".into()),
            (1, "response".into(), "0103060000000001902089".into()),
            (0, "request".into(), "0106006c000ac9d0".into()),
            (1, "response".into(), "0106006c000ac9d0".into()),
        ]
    );
    let outcomes: Vec<&str> =
        events.iter().filter(|j| j["event"] == "transaction").map(|j| j["outcome"].as_str().unwrap()).collect();
    assert_eq!(outcomes, ["ok", "ok"]);
    // The recording keeps the directions.
    let o = Command::new(BIN).args(["replay", rec.to_str().unwrap(), "--format", "jsonl"]).output().unwrap();
    let replayed = String::from_utf8(o.stdout).unwrap();
    let directions: Vec<String> = replayed
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|j| j["event"] == "frame")
        .map(|j| j["direction"].as_str().unwrap().to_owned())
        .collect();
    assert_eq!(directions, ["request", "response", "request", "response"]);
}

/// `tap` on `bus` offering `app`, recording to `rec`, quietly; once the link exists.
fn recording_tap(bus: &std::path::Path, app: &std::path::Path, rec: &std::path::Path) -> Kill {
    let tap = Kill(
        Command::new(BIN)
            .args(["tap", bus.to_str().unwrap(), "--link", app.to_str().unwrap(), "--format", "summary"])
            .args(["--record", rec.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    wait_for(app);
    tap
}

/// Frames in the replay of recording `rec`.
fn replayed_frames(rec: &std::path::Path) -> (usize, String) {
    let o = Command::new(BIN).args(["replay", rec.to_str().unwrap(), "--format", "jsonl"]).output().unwrap();
    let replayed = String::from_utf8_lossy(&o.stdout).into_owned();
    (replayed.lines().filter(|l| l.contains("\"event\":\"frame\"")).count(), replayed)
}

fn socat_pair(a: &std::path::Path, b: &std::path::Path) -> Kill {
    let k = Kill(
        Command::new("socat")
            .args([format!("pty,raw,echo=0,link={}", a.display()), format!("pty,raw,echo=0,link={}", b.display())])
            .stderr(Stdio::null())
            .spawn()
            .expect("socat must be installed for this test"),
    );
    wait_for(a);
    wait_for(b);
    k
}

/// When the real port is lost, `tap` keeps the application's side open while the port is reopened
/// (no "device disconnected"), and the recording is on disk within about a second, traffic or not
/// (a SIGKILL after a quiet spell loses nothing heard).
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn tap_outlives_its_port_and_flushes_in_the_quiet() {
    let dir = std::env::temp_dir().join(format!("mbtap-tap-lost-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (bus, dev, app, rec) = (dir.join("bus"), dir.join("dev"), dir.join("app"), dir.join("rec.pcapng"));
    let socat = socat_pair(&bus, &dev);
    let mut tap = recording_tap(&bus, &app, &rec);
    let mut a = open(&app);
    let mut d = open(&dev);
    a.write_all(READ_REQ).unwrap();
    assert_eq!(read_exact(d.as_mut(), READ_REQ.len()), READ_REQ);
    d.write_all(READ_RESP).unwrap();
    assert_eq!(read_exact(a.as_mut(), READ_RESP.len()), READ_RESP);
    // The real port goes away (socat ends: its ptys close).
    drop(d);
    drop(socat);
    std::thread::sleep(Duration::from_millis(1500));
    assert!(tap.0.try_wait().unwrap().is_none(), "tap must not exit when its port is lost");
    // The application can still write to its side without an error.
    a.write_all(READ_REQ).unwrap();
    // Quiet for over a second, then killed without a chance to flush: the first transaction is
    // on disk.
    std::thread::sleep(Duration::from_millis(1500));
    let pid = tap.0.id().to_string();
    assert!(Command::new("kill").args(["-KILL", &pid]).status().unwrap().success());
    let _ = tap.0.wait();
    let (frames, replayed) = replayed_frames(&rec);
    assert!(frames >= 2, "the request and its answer were flushed before the kill:\n{replayed}");
}

/// CPU time (user + system) a process has used so far, in clock ticks (/proc/PID/stat fields
/// 14 and 15).
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let after = &stat[stat.rfind(')').unwrap() + 2..];
    let fields: Vec<&str> = after.split_whitespace().collect();
    fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap()
}

/// `tap` idles without burning a core while the application holds the pty open without traffic, and
/// flushes when the application closes its side (a SIGKILL then loses no transaction). CPU is a
/// resource, measured from the kernel's count, not a timing assert.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn tap_idles_without_burning_a_core_and_flushes_when_the_application_leaves() {
    let dir = std::env::temp_dir().join(format!("mbtap-tap-idle-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (bus, dev, app, rec) = (dir.join("bus"), dir.join("dev"), dir.join("app"), dir.join("rec.pcapng"));
    let _socat = socat_pair(&bus, &dev);
    let mut tap = recording_tap(&bus, &app, &rec);
    let pid = tap.0.id();
    // The application opens its side, closes it once (as a program restarting does), opens it
    // again and then holds it open without a word.
    drop(open(&app));
    std::thread::sleep(Duration::from_millis(200));
    let mut a = open(&app);
    let before = cpu_ticks(pid);
    std::thread::sleep(Duration::from_secs(2));
    let idle = cpu_ticks(pid) - before;
    // 100 ticks a second on Linux: a spinning loop uses ~200 here; an idle tap 0-5.
    assert!(idle < 40, "tap used {idle} ticks of CPU in 2 s with an idle application");
    // One transaction, then the application leaves; killed 1.5 s later, it is on disk.
    let mut d = open(&dev);
    a.write_all(READ_REQ).unwrap();
    assert_eq!(read_exact(d.as_mut(), READ_REQ.len()), READ_REQ);
    d.write_all(READ_RESP).unwrap();
    assert_eq!(read_exact(a.as_mut(), READ_RESP.len()), READ_RESP);
    drop(a);
    std::thread::sleep(Duration::from_millis(1500));
    assert!(Command::new("kill").args(["-KILL", &pid.to_string()]).status().unwrap().success());
    let _ = tap.0.wait();
    let (frames, replayed) = replayed_frames(&rec);
    assert!(frames >= 2, "the transaction was flushed after the application left:\n{replayed}");
}
