//! The bridge on real RS-485 hardware, as far as pseudo-terminals and scripted adapters go:
//! RTU over TCP on the client side of reverse mode, adapters that echo what is
//! sent, per-unit timeouts, ports that come back under another name, and direction control
//! refused clearly where the port cannot do it. What only real hardware can prove is listed in
//! the README's "Wiring and adapters". Real ptys (socat, `mbtap simulate`): `#[ignore]`d in a
//! plain `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use crate::common;
use common::{BIN, Kill, socat_pair};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-hw-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn simulator(link: &Path, extra: &[&str]) -> Kill {
    common::simulate(link, &[&["--duration", "120"][..], extra].concat())
}

/// Starts `mbtap bridge` with `args`; the process, the addresses it listens on (Modbus TCP,
/// RTU over TCP, in that order, as asked for) and its later stderr.
fn bridge(args: &[&str]) -> (Kill, Vec<String>, std::sync::Arc<std::sync::Mutex<Vec<String>>>) {
    let b = common::bridge(args);
    (b.child, b.tcp.into_iter().chain(b.rtu).collect(), b.log)
}

fn mbtap(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// An RTU master on one pty, the reverse bridge on the other, forwarding as RTU over TCP to a
/// forward bridge's `--listen-rtu` in front of the simulated devices: the master reads the
/// MK4's voltages and the MKZP's currents through both hops.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn reverse_mode_reaches_an_rtu_over_tcp_server() {
    let d = dir("rtutcp");
    let bus = d.join("bus");
    let _sim = simulator(&bus, &[]);
    let (_fwd, addrs, _) = bridge(&["--serial", bus.to_str().unwrap(), "--listen-rtu", "127.0.0.1:0"]);
    let rtu = addrs[0].clone();
    let (_socat, a, b) = socat_pair(&d);
    let (_rev, _, _) =
        bridge(&["--reverse", "--serial", a.to_str().unwrap(), "--target-rtu", &rtu, "--answer-as", "1,17"]);
    let o = mbtap(&["read", b.to_str().unwrap(), "--device", "mk4", "--format", "jsonl", "430..433"]);
    assert!(o.status.success(), "{}", text(&o));
    let volts: Vec<i64> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["raw"].as_i64().unwrap())
        .collect();
    assert_eq!(volts.len(), 4);
    assert!(volts.iter().all(|v| (2000..=2600).contains(v)), "{volts:?}");
    let o = mbtap(&["read", b.to_str().unwrap(), "--unit", "17", "--format", "jsonl", "holding", "50..52"]);
    assert!(o.status.success(), "{}", text(&o));
    // An address outside the MK4's map: the device's exception 02 comes back unchanged.
    let o = mbtap(&["read", b.to_str().unwrap(), "--unit", "1", "--format", "jsonl", "holding", "9999"]);
    assert!(text(&o).contains("Illegal Data Address"), "the device's own exception comes back: {}", text(&o));
}

fn metrics(addr: &str) -> String {
    common::metrics_text(addr)
}

fn gauge(text: &str, name: &str, unit: u8) -> Option<f64> {
    common::metric(text, &format!("{name}{{unit=\"{unit}\"}}"))
}

/// Starts a bridge with metrics; its Modbus TCP address and metrics address.
fn bridge_with_metrics(bus: &Path, extra: &[&str]) -> (Kill, String, String) {
    let mut args = vec!["--serial", bus.to_str().unwrap(), "--listen", "127.0.0.1:0", "--metrics", "127.0.0.1:0"];
    args.extend_from_slice(extra);
    let b = common::bridge(&args);
    (b.child, b.tcp.unwrap(), b.metrics.unwrap())
}

/// `--timeout auto` learns a live unit's timeout from its answers (well under the ceiling) and
/// keeps the ceiling for a unit never heard; `--unit-timeout` gives a unit its own, and the
/// line time lost waiting is counted per unit.
#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn per_unit_timeouts_fixed_and_learnt() {
    let d = dir("timeouts");
    let bus = d.join("bus");
    let _sim = simulator(&bus, &["--turnaround-ms", "0"]);
    let (_bridge, tcp, m) = bridge_with_metrics(&bus, &["--timeout", "auto", "--unit-timeout", "9=50"]);
    for _ in 0..8 {
        let o = mbtap(&["read", &tcp, "--unit", "1", "--format", "jsonl", "input", "430"]);
        assert!(o.status.success(), "{}", text(&o));
    }
    let o = mbtap(&["read", &tcp, "--unit", "9", "--format", "jsonl", "holding", "0"]);
    assert!(text(&o).contains("0x0B"), "{}", text(&o));
    let o = mbtap(&["read", &tcp, "--unit", "8", "--timeout-ms", "3000", "--format", "jsonl", "holding", "0"]);
    assert!(text(&o).contains("0x0B"), "{}", text(&o));
    let text = metrics(&m);
    let learnt = gauge(&text, "mbtap_bridge_unit_timeout_seconds", 1).unwrap();
    assert!((0.02..1.0).contains(&learnt), "unit 1's learnt timeout {learnt} s: {text}");
    assert_eq!(gauge(&text, "mbtap_bridge_unit_timeout_seconds", 9), Some(0.05), "{text}");
    // The ceiling is the default --timeout-ms, 800 (a dead unit's 0x0B before a client's own
    // 1 s timeout).
    assert_eq!(gauge(&text, "mbtap_bridge_unit_timeout_seconds", 8), Some(0.8), "never heard: the ceiling");
    assert_eq!(gauge(&text, "mbtap_bridge_timeout_wait_seconds_total", 9), Some(0.05), "{text}");
    assert_eq!(gauge(&text, "mbtap_bridge_timeout_wait_seconds_total", 1), Some(0.0), "{text}");
}

/// How the scripted adapter gives a request back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EchoKind {
    Exact,
    /// One byte of the echo changed: another driver on the line.
    ChangedByte,
    /// The echo 30 ms after the request.
    Late,
    Never,
}

/// A scripted half-duplex adapter with a device behind it on the far end of a pty pair: each
/// read-holding-registers request (8 bytes) is given back as `kind` says, then answered by unit
/// 1 with holding register N = 100 + N.
fn fake_adapter(path: &Path, kind: EchoKind) {
    use std::io::{Read, Write};
    let _ = Command::new("stty").args(["-F", path.to_str().unwrap(), "raw", "-echo"]).status();
    let mut port = std::fs::OpenOptions::new().read(true).write(true).open(path).unwrap();
    std::thread::spawn(move || {
        let mut req = Vec::new();
        let mut buf = [0u8; 256];
        loop {
            let Ok(n) = port.read(&mut buf) else { return };
            if n == 0 {
                return;
            }
            req.extend_from_slice(&buf[..n]);
            while req.len() >= 8 {
                let r: Vec<u8> = req.drain(..8).collect();
                let mut echo = r.clone();
                match kind {
                    EchoKind::Exact => {}
                    EchoKind::ChangedByte => echo[3] ^= 0x10,
                    EchoKind::Late => std::thread::sleep(std::time::Duration::from_millis(30)),
                    EchoKind::Never => echo.clear(),
                }
                let (address, quantity) = (u16::from_be_bytes([r[2], r[3]]), u16::from_be_bytes([r[4], r[5]]));
                // Unit 1, function 03, byte count, the registers, CRC low byte first.
                let mut answer = vec![r[0], 0x03, u8::try_from(quantity * 2).unwrap()];
                for a in address..address + quantity {
                    answer.extend_from_slice(&(100 + a).to_be_bytes());
                }
                let crc = mbtap_proto::crc16(&answer);
                answer.extend_from_slice(&crc.to_le_bytes());
                echo.extend_from_slice(&answer);
                if port.write_all(&echo).is_err() {
                    return;
                }
            }
        }
    });
}

/// A bridge with `--echo echo` on a pty whose far end is the scripted adapter; what a read of
/// holding 0..3 gave, and the bridge's metrics after it.
fn through_adapter(name: &str, kind: EchoKind, echo: &str) -> (Output, String) {
    let d = dir(name);
    let (_socat, a, b) = socat_pair(&d);
    fake_adapter(&b, kind);
    let (_bridge, tcp, m) = bridge_with_metrics(&a, &["--echo", echo, "--timeout-ms", "300"]);
    let o = mbtap(&["read", &tcp, "--unit", "1", "--timeout-ms", "2000", "--format", "jsonl", "holding", "0..3"]);
    let text = metrics(&m);
    (o, text)
}

fn raws(o: &Output) -> Vec<i64> {
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()?["raw"].as_i64())
        .collect()
}

#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn an_echoing_adapter_exact_late_changed_and_silent() {
    // Echo given back exactly: consumed, the answer read after it.
    let (o, m) = through_adapter("echo-exact", EchoKind::Exact, "on");
    assert_eq!(raws(&o), [100, 101, 102, 103], "{}\n{m}", text(&o));
    assert_eq!(gauge(&m, "mbtap_bridge_collisions_total", 1), Some(0.0), "{m}");
    // auto finds it from the first request.
    let (o, _) = through_adapter("echo-auto", EchoKind::Exact, "auto");
    assert_eq!(raws(&o), [100, 101, 102, 103], "{}", text(&o));
    // Late (30 ms): still the echo, then the answer.
    let (o, _) = through_adapter("echo-late", EchoKind::Late, "on");
    assert_eq!(raws(&o), [100, 101, 102, 103], "{}", text(&o));
    // A changed byte: a collision, counted; the client gets 0B, never the garbled exchange.
    let (o, m) = through_adapter("echo-changed", EchoKind::ChangedByte, "on");
    assert!(text(&o).contains("0x0B"), "{}", text(&o));
    assert_eq!(gauge(&m, "mbtap_bridge_collisions_total", 1), Some(1.0), "{m}");
    // Never echoed under --echo on: what came is a whole valid answer, so the adapter does not
    // echo — counted as a missing echo, and the answer used (not mistaken for a collision).
    let (o, m) = through_adapter("echo-never-on", EchoKind::Never, "on");
    assert_eq!(raws(&o), [100, 101, 102, 103], "{}\n{m}", text(&o));
    assert_eq!(gauge(&m, "mbtap_bridge_echo_missing_total", 1), Some(1.0), "{m}");
    assert_eq!(gauge(&m, "mbtap_bridge_collisions_total", 1), Some(0.0), "{m}");
    // …and under auto: no echo found, the answer read as it is.
    let (o, m) = through_adapter("echo-never-auto", EchoKind::Never, "auto");
    assert_eq!(raws(&o), [100, 101, 102, 103], "{}\n{m}", text(&o));
    // The control: an echoing adapter with --echo off takes the echo for the answer and fails.
    let (o, _) = through_adapter("echo-off", EchoKind::Exact, "off");
    assert_ne!(raws(&o), [100, 101, 102, 103], "{}", text(&o));
}

/// Direction control a port cannot do is refused at start with the port's name and what to do,
/// never a silent fallback: a pseudo-terminal has neither the kernel's RS-485 mode nor an RTS
/// line. (Real transceivers: README "Wiring and adapters".)
#[test]
fn rs485_modes_a_pty_cannot_do_are_refused_clearly() {
    let d = dir("rs485");
    let bus = d.join("bus");
    let _sim = simulator(&bus, &[]);
    let b = bus.to_str().unwrap();
    for (mode, says) in [("kernel", "does not take the kernel's RS-485 mode"), ("rts", "has no RTS line")] {
        let o = mbtap(&["bridge", "--serial", b, "--listen", "127.0.0.1:0", "--rs485", mode, "--duration", "1"]);
        assert_eq!(o.status.code(), Some(2), "--rs485 {mode}: {}", text(&o));
        assert!(text(&o).contains(says) && text(&o).contains(b), "--rs485 {mode}: {}", text(&o));
    }
    let capture = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/mk4-doc-examples-rtu.pcapng");
    let o = mbtap(&["play", capture.to_str().unwrap(), b, "--rs485", "kernel"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("TIOCSRS485"), "{}", text(&o));
    // Off (an auto-direction adapter) is what a pty can do.
    let o = mbtap(&["bridge", "--serial", b, "--listen", "127.0.0.1:0", "--rs485", "off", "--duration", "1"]);
    assert!(o.status.success(), "{}", text(&o));
}

/// Points `link` (standing in for `/dev/serial/by-id/…`) at `target`.
fn relink(link: &Path, target: &Path) {
    let _ = std::fs::remove_file(link);
    std::os::unix::fs::symlink(target, link).unwrap();
}

/// A USB adapter unplugged and back as another `/dev/ttyUSBn`, its by-id link following it: the
/// bridge finds it again through the link and says which device it is now.
#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn the_bridge_follows_a_by_id_link_to_the_renumbered_adapter() {
    let d = dir("byid");
    let (one, two, by_id) = (d.join("ttyUSB0"), d.join("ttyUSB1"), d.join("usb-FTDI_FT232R_A10K-if00-port0"));
    let sim = simulator(&one, &[]);
    relink(&by_id, &one);
    let (_bridge, addrs, log) = bridge(&["--serial", by_id.to_str().unwrap(), "--listen", "127.0.0.1:0"]);
    let tcp = addrs[0].clone();
    let read = || mbtap(&["read", &tcp, "--unit", "1", "--format", "jsonl", "input", "430"]);
    assert!(read().status.success());
    let before = std::fs::canonicalize(&one).unwrap();
    drop(sim);
    let _sim = simulator(&two, &[]);
    relink(&by_id, &two);
    let after = std::fs::canonicalize(&two).unwrap();
    assert_ne!(before, after, "the second adapter must be another device");
    // The line reopens with backoff: a hang guard, not a timing assertion.
    let start = std::time::Instant::now();
    while !read().status.success() {
        assert!(
            start.elapsed() < std::time::Duration::from_secs(30),
            "never reached the adapter again: {:?}",
            log.lock().unwrap()
        );
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    let said = format!("is now {} (was {})", after.display(), before.display());
    let start = std::time::Instant::now();
    while !log.lock().unwrap().iter().any(|l| l.contains(&said)) {
        assert!(start.elapsed() < std::time::Duration::from_secs(10), "no {said:?} in {:?}", log.lock().unwrap());
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// The same for `sniff`: the port vanishes, comes back under another device behind the link,
/// and the sniffer hears the line again, saying where it is now.
#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn sniff_follows_a_by_id_link_to_the_renumbered_adapter() {
    let d = dir("byid-sniff");
    let (one, two, by_id) = (d.join("ttyUSB0"), d.join("ttyUSB1"), d.join("by-id-port"));
    let sim = simulator(&one, &["--poll"]);
    relink(&by_id, &one);
    let before = std::fs::canonicalize(&one).unwrap();
    let sniff = Command::new(BIN)
        .args(["sniff", by_id.to_str().unwrap(), "--format", "jsonl", "--duration", "7"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    drop(sim);
    let _sim = simulator(&two, &["--poll"]);
    relink(&by_id, &two);
    let relinked_ns =
        u64::try_from(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos()).unwrap();
    let after = std::fs::canonicalize(&two).unwrap();
    let out = sniff.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("is now {} (was {})", after.display(), before.display())), "{err}");
    assert!(err.contains(" is back"), "{err}");
    // Transactions heard from the second adapter, after the link moved.
    let ok_after = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|e| e["event"] == "transaction" && e["outcome"] == "ok" && e["t_ns"].as_u64() > Some(relinked_ns))
        .count();
    assert!(ok_after > 0, "nothing heard after the adapter came back:\n{err}");
}

/// The ASCII bridge against a real third-party ASCII slave: pymodbus's serial ASCII server on
/// one end of a pty pair, `bridge --mode ascii` on the other, `mbtap read` over Modbus TCP.
#[test]
#[ignore = "needs socat and pymodbus; .ci/run installs them and runs this with --ignored"]
fn the_ascii_bridge_reads_and_writes_a_pymodbus_ascii_server() {
    let d = dir("ascii");
    let (_socat, a, b) = socat_pair(&d);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_ascii_server.py");
    let _server = Kill(Command::new("python3").arg(script).arg(&b).stderr(Stdio::null()).spawn().unwrap());
    let (_bridge, addrs, _) = bridge(&["--serial", a.to_str().unwrap(), "--mode", "ascii", "--listen", "127.0.0.1:0"]);
    let tcp = addrs[0].clone();
    // pymodbus needs a moment to open its port: a hang guard while it starts.
    let start = std::time::Instant::now();
    let o = loop {
        let o = mbtap(&["read", &tcp, "--format", "jsonl", "holding", "0..4"]);
        if o.status.success() || start.elapsed() > std::time::Duration::from_secs(20) {
            break o;
        }
        std::thread::sleep(std::time::Duration::from_millis(300));
    };
    assert_eq!(raws(&o), [0, 10, 20, 30, 40], "{}", text(&o));
    let o = mbtap(&["write", &tcp, "--format", "jsonl", "holding 3=4321"]);
    assert!(o.status.success(), "{}", text(&o));
    let o = mbtap(&["read", &tcp, "--format", "jsonl", "holding", "2..4"]);
    assert_eq!(raws(&o), [20, 4321, 40], "{}", text(&o));
}
