//! `sniff rtu-over-tcp://HOST:PORT` hears a remote line through a serial server —
//! Debian's ser2net in raw TCP mode in front of `mbtap simulate --poll` (the whole line, master
//! and slaves, on a pseudo-terminal). TCP keeps no timing: frames are found by structure and CRC.
//! Needs ser2net (CI installs it): run with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use crate::common;

use std::fmt::Write as _;
use std::process::{Command, Stdio};

use common::{BIN, Kill, wait_port};

#[test]
#[ignore = "needs ser2net; .ci/run installs it and runs this with --ignored"]
fn sniff_hears_a_line_through_ser2net() {
    let dir = std::env::temp_dir().join(format!("mbtap-ser2net-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let line = dir.join("line");
    let _sim = common::simulate(&line, &["--poll"]);
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let config = dir.join("ser2net.yaml");
    std::fs::write(
        &config,
        format!(
            "connection: &line\n  accepter: tcp,127.0.0.1,{port}\n  connector: serialdev,{},19200e81,local\n",
            line.display()
        ),
    )
    .unwrap();
    let _ser2net = Kill(
        Command::new("ser2net")
            .args(["-n", "-d", "-c", config.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("ser2net must be installed"),
    );
    wait_port(port);
    let target = format!("rtu-over-tcp://127.0.0.1:{port}");
    let out = Command::new(BIN)
        .args(["sniff", &target, "--parity", "even", "--duration", "4", "--format", "jsonl"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let events: Vec<serde_json::Value> =
        String::from_utf8_lossy(&out.stdout).lines().filter_map(|l| serde_json::from_str(l).ok()).collect();
    let transactions: Vec<&serde_json::Value> = events.iter().filter(|e| e["event"] == "transaction").collect();
    // The connection opens and closes wherever the line is: the first and last frames may be
    // cut. Every frame between must check.
    let frames: Vec<&serde_json::Value> = events.iter().filter(|e| e["event"] == "frame").collect();
    let inner = frames.get(1..frames.len().saturating_sub(1)).unwrap_or_default();
    let failed = inner.iter().filter(|e| e["check_ok"] == false).count();
    assert!(transactions.len() >= 10, "{} transactions", transactions.len());
    assert_eq!(failed, 0, "{failed} of {} frames failed their check", inner.len());
    let units: std::collections::BTreeSet<u64> = transactions.iter().filter_map(|t| t["unit"].as_u64()).collect();
    for u in [1, 5, 17] {
        assert!(units.contains(&u), "unit {u} not heard: {units:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// ser2net (Debian) in front of a simulated line, as raw TCP and as RFC 2217, with a bridge
/// through each: `--serial rtu-over-tcp://` and `--serial rfc2217://`.
fn ser2net_in_front(dir: &std::path::Path, lines: &[(&str, &std::path::Path)]) -> Kill {
    let config = dir.join("ser2net.yaml");
    let mut text = String::new();
    for (i, (accepter, line)) in lines.iter().enumerate() {
        let connector = format!("serialdev,{},19200e81,local", line.display());
        writeln!(text, "connection: &c{i}\n  accepter: {accepter}\n  connector: {connector}").unwrap();
    }
    std::fs::write(&config, text).unwrap();
    Kill(
        Command::new("ser2net")
            .args(["-n", "-d", "-c", config.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("ser2net must be installed"),
    )
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Mbpoll and pymodbus through `mbtap bridge` to `mbtap simulate` behind ser2net —
/// raw TCP (`rtu-over-tcp://`) and RFC 2217 (`rfc2217://`, the bridge setting the remote
/// port's line) — every read and write right, a missing unit answered 0x0B.
#[test]
#[ignore = "needs ser2net, mbpoll and pymodbus; .ci/run installs them and runs this with --ignored"]
fn the_bridge_reaches_a_line_behind_ser2net_raw_and_rfc2217() {
    let d = super::serial::dir("ser2net-bridge");
    let (raw_line, rfc_line) = (d.join("raw"), d.join("rfc"));
    let _sims = (super::serial::simulator(&raw_line, &[]), super::serial::simulator(&rfc_line, &[]));
    let (raw, rfc) = (free_port(), free_port());
    let _ser2net = ser2net_in_front(
        &d,
        &[(&format!("tcp,127.0.0.1,{raw}"), &raw_line), (&format!("telnet(rfc2217),tcp,127.0.0.1,{rfc}"), &rfc_line)],
    );
    wait_port(raw);
    wait_port(rfc);
    for target in [format!("rtu-over-tcp://127.0.0.1:{raw}"), format!("rfc2217://127.0.0.1:{rfc}")] {
        let (_bridge, addr, _) = super::serial::bridge(std::path::Path::new(&target), &["--parity", "even"]);
        let (host, port) = addr.rsplit_once(':').unwrap();
        let out = Command::new("mbpoll")
            .args(["-m", "tcp", "-p", port, "-a", "1", "-t", "3", "-0", "-r", "430", "-c", "4", "-1", host])
            .output()
            .expect("mbpoll must be installed");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{target}: {text}");
        let volts: Vec<u32> =
            text.lines().filter_map(|l| l.split_once("]:").map(|(_, v)| v.trim().parse().unwrap())).collect();
        assert_eq!(volts.len(), 4, "{target}: {text}");
        assert!(volts.iter().all(|v| (2200..=2400).contains(v)), "{target}: mains around 230 V: {volts:?}");
        let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_tcp_client.py");
        let out = Command::new("python3").arg(script).args([host, port]).output().expect("python3 must be installed");
        let text = String::from_utf8_lossy(&out.stdout) + String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && text.contains("ALL OK"), "{target}: {text}");
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// `read` and `watch` reach a line behind ser2net's RFC 2217 port as `sniff` and `bridge` do:
/// the master is a line of the bridge's, so `rfc2217://` sets the remote port's line and reads
/// through it — mains voltages from the simulated meter, and exception 0x0B named as a timeout
/// for a unit nobody is.
#[test]
#[ignore = "needs ser2net; .ci/run installs it and runs this with --ignored"]
fn read_and_watch_reach_a_line_behind_ser2net_rfc2217() {
    let d = super::serial::dir("ser2net-read");
    let line = d.join("rfc");
    let _sim = super::serial::simulator(&line, &[]);
    let rfc = free_port();
    let _ser2net = ser2net_in_front(&d, &[(&format!("telnet(rfc2217),tcp,127.0.0.1,{rfc}"), &line)]);
    wait_port(rfc);
    let target = format!("rfc2217://127.0.0.1:{rfc}");
    let read = |args: &[&str]| {
        let out = Command::new(BIN).arg("read").arg(&target).args(args).args(["--format", "jsonl"]).output().unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, out, err) = read(&["--unit", "1", "--device", "mk4", "430..432"]);
    assert_eq!(code, Some(0), "{out}{err}");
    let raws: Vec<u64> =
        out.lines().map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["raw"].as_u64().unwrap()).collect();
    assert_eq!(raws.len(), 3, "{out}");
    assert!(raws.iter().all(|v| (2200..=2400).contains(v)), "mains around 230 V: {raws:?}");
    let (code, out, err) = read(&["--unit", "77", "input", "430", "--timeout-ms", "300"]);
    assert_ne!(code, Some(0), "{out}{err}");
    assert!((out.clone() + &err).contains("no answer from unit 77 within 300 ms"), "{out}{err}");
    let out = Command::new(BIN)
        .args(["watch", &target, "--device", "mk4", "--interval", "200ms", "--count", "2", "--format", "jsonl", "430"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.lines().filter(|l| l.contains("\"raw\"")).count() >= 2, "{text}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// A Modbus TCP device that takes one connection at a time (a pymodbus server that
/// closes every second connection) behind `--serial tcp://`: 8 clients at once through the
/// bridge, 50 requests each on both units, every answer right and its own — and the device saw
/// one connection, never a refused one.
#[test]
#[ignore = "needs pymodbus; .ci/run installs it and runs this with --ignored"]
fn eight_clients_share_a_device_that_takes_one_connection() {
    let port = free_port();
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_one_connection_server.py");
    let mut server = Kill(
        Command::new("python3")
            .arg(script)
            .arg(port.to_string())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("python3 must be installed"),
    );
    let said = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let out = server.0.stdout.take().unwrap();
    let lines = std::sync::Arc::clone(&said);
    std::thread::spawn(move || {
        for l in std::io::BufRead::lines(std::io::BufReader::new(out)).map_while(Result::ok) {
            lines.lock().unwrap().push(l);
        }
    });
    wait_port(port);
    // wait_port's own probe was one connection: the device's count starts after it.
    std::thread::sleep(std::time::Duration::from_millis(300));
    let before = said.lock().unwrap().len();
    let target = format!("tcp://127.0.0.1:{port}");
    let (_bridge, addr, _) = super::serial::bridge(std::path::Path::new(&target), &[]);
    let clients: Vec<_> = (0..8u16)
        .map(|c| {
            let addr = addr.clone();
            std::thread::spawn(move || {
                let mut s = std::net::TcpStream::connect(&addr).unwrap();
                s.set_read_timeout(Some(std::time::Duration::from_secs(10))).unwrap();
                for i in 0..50u16 {
                    let unit = u8::try_from(1 + i % 2).unwrap();
                    let first = (c * 7 + i) % 90;
                    let tid = c * 1000 + i;
                    let pdu = common::call(&mut s, tid, unit, &[0x03, 0x00, u8::try_from(first).unwrap(), 0x00, 0x03]);
                    let want: Vec<u8> = std::iter::once([0x03u8, 6])
                        .flatten()
                        .chain((first..first + 3).flat_map(|a| (a * 10).to_be_bytes()))
                        .collect();
                    assert_eq!(pdu, want, "client {c} request {i}");
                }
            })
        })
        .collect();
    for c in clients {
        c.join().unwrap();
    }
    let said: Vec<String> = said.lock().unwrap()[before..].to_vec();
    assert_eq!(said, ["accepted"], "the device saw: {said:?}");
}

/// `tap rtu-over-tcp://` — an application reads a device behind ser2net through
/// mbtap's pseudo-terminal, and the tap hears the transaction, request and answer paired.
#[test]
#[ignore = "needs ser2net; .ci/run installs it and runs this with --ignored"]
fn tap_puts_an_application_on_a_line_behind_ser2net() {
    let d = super::serial::dir("ser2net-tap");
    let line = d.join("line");
    let _sim = super::serial::simulator(&line, &[]);
    let raw = free_port();
    let _ser2net = ser2net_in_front(&d, &[(&format!("tcp,127.0.0.1,{raw}"), &line)]);
    wait_port(raw);
    let app = d.join("app");
    let target = format!("rtu-over-tcp://127.0.0.1:{raw}");
    let mut tap = Kill(
        Command::new(BIN)
            .args(["tap", &target, "--link", app.to_str().unwrap(), "--format", "jsonl", "--duration", "4"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    common::wait_for(&app);
    let read = Command::new(BIN)
        .args(["read", app.to_str().unwrap(), "--parity", "even", "--unit", "1", "input", "430..433"])
        .output()
        .unwrap();
    assert!(read.status.success(), "{}", String::from_utf8_lossy(&read.stderr));
    let volts: Vec<u64> = String::from_utf8_lossy(&read.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|j| j["raw"].as_u64())
        .collect();
    assert_eq!(volts.len(), 4, "{volts:?}");
    let mut stdout = String::new();
    std::io::Read::read_to_string(&mut tap.0.stdout.take().unwrap(), &mut stdout).unwrap();
    let heard: Vec<serde_json::Value> = stdout
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .filter(|j: &serde_json::Value| j["event"] == "transaction")
        .collect();
    assert_eq!(heard.len(), 1, "{heard:?}");
    assert_eq!((heard[0]["unit"].as_u64(), heard[0]["function"].as_u64()), (Some(1), Some(4)), "{heard:?}");
    std::fs::remove_dir_all(&d).unwrap();
}
