//! Spy mode (`sniff --serve`): `simulate --poll` plays a whole line on a pseudo-terminal, socat
//! relays it to the port mbtap sniffs (and logs every byte in each direction), and mbpoll and
//! pymodbus read the sniffer's register image over Modbus TCP. They must get the values the
//! simulated master last read, the documented exceptions for what was never heard, for stale
//! values and for writes — and the sniffer must never have written a byte to its port.
//! Needs socat, mbpoll and pymodbus: `#[ignore]`d in a plain `cargo test`, run by `.ci/run`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::common;
use common::{BIN, Kill, wait_for};

/// Registers of a response PDU's data: `unit fc count data… crc`.
fn registers(response_hex: &str) -> Vec<i64> {
    let bytes: Vec<u8> =
        (0..response_hex.len()).step_by(2).map(|i| u8::from_str_radix(&response_hex[i..i + 2], 16).unwrap()).collect();
    bytes[3..bytes.len() - 2].chunks(2).map(|p| i64::from(u16::from_be_bytes([p[0], p[1]]))).collect()
}

/// The registers of the last good answer heard to `unit`/`function` starting at `address`.
fn last_heard(events: &[serde_json::Value], unit: u64, function: u64, address: u16) -> Vec<i64> {
    let start = format!("{address:04x}");
    events
        .iter()
        .rev()
        .find(|e| {
            e["event"] == "transaction"
                && e["outcome"] == "ok"
                && e["unit"] == unit
                && e["function"] == function
                && e["request_hex"].as_str().unwrap()[4..8] == start
        })
        .map_or_else(
            || panic!("no answer heard for unit {unit} function {function} at {address}"),
            |e| registers(e["response_hex"].as_str().unwrap()),
        )
}

fn mbpoll(port: u16, args: &[&str]) -> (bool, String, Vec<i64>) {
    mbpoll_write(port, &[&["-1"], args].concat(), &[])
}

/// mbpoll with values to write after the host (it refuses `-1` on writes; it writes once).
fn mbpoll_write(port: u16, args: &[&str], values: &[&str]) -> (bool, String, Vec<i64>) {
    let o = Command::new("mbpoll")
        .args(["-m", "tcp", "-p", &port.to_string(), "-0", "-o", "2"])
        .args(args)
        .arg("127.0.0.1")
        .args(values)
        .output()
        .expect("mbpoll must be installed for this test");
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    let values = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix('[')?.split_once("]:").and_then(|(_, v)| v.trim().parse().ok()))
        .collect();
    (o.status.success(), text, values)
}

fn pymodbus(port: u16, unit: &str, table: &str, address: &str, count: &str) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_tcp_read.py");
    let o = Command::new("python3")
        .arg(script)
        .args(["127.0.0.1", &port.to_string(), unit, table, address, count])
        .output()
        .expect("python3 with pymodbus");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
#[ignore = "needs socat, mbpoll and pymodbus; .ci/run installs them and runs this with --ignored"]
fn mbpoll_and_pymodbus_read_what_the_sniffer_heard_and_nothing_is_sent() {
    let dir = std::env::temp_dir().join(format!("mbtap-spy-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (line, port) = (dir.join("line"), dir.join("port"));
    // The line plays for 3 s, then stops: the image is then what the master last read.
    let mut sim = Command::new(BIN)
        .args(["simulate", "--poll", "--link", line.to_str().unwrap(), "--duration", "3"])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for(&line);
    let log = dir.join("socat.log");
    let _socat = Kill(
        Command::new("socat")
            .arg("-x")
            .arg(format!("pty,raw,echo=0,link={}", port.display()))
            .arg(format!("file:{},raw,echo=0", line.display()))
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .expect("socat must be installed for this test"),
    );
    wait_for(&port);
    let mut sniff = Command::new(BIN)
        .args(["sniff", port.to_str().unwrap(), "--format", "jsonl", "--serve", "127.0.0.1:0", "--max-age", "none"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(sniff.stderr.take().unwrap()).lines();
    let tcp: u16 = loop {
        let l = err.next().expect("sniff ended before serving").unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: spy server listening on ") {
            break rest.split_whitespace().next().unwrap().rsplit(':').next().unwrap().parse().unwrap();
        }
    };
    std::thread::spawn(move || for _ in err {});
    let events = Arc::new(Mutex::new(Vec::<serde_json::Value>::new()));
    let (out, sink) = (sniff.stdout.take().unwrap(), Arc::clone(&events));
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(Result::ok) {
            sink.lock().unwrap().push(serde_json::from_str(&l).unwrap());
        }
    });
    let _sniff = Kill(sniff);
    assert!(sim.wait().unwrap().success());
    std::thread::sleep(Duration::from_millis(300));
    let heard = events.lock().unwrap().clone();

    // MK4 (unit 1): voltages (input 430–433) and set points (holding 100–109).
    let volts = last_heard(&heard, 1, 4, 430);
    let (ok, text, got) = mbpoll(tcp, &["-a", "1", "-t", "3", "-r", "430", "-c", "4"]);
    assert!(ok, "{text}");
    assert_eq!(got, volts, "{text}");
    let set_points = last_heard(&heard, 1, 3, 100);
    let (ok, text, got) = mbpoll(tcp, &["-a", "1", "-t", "4", "-r", "100", "-c", "10"]);
    assert!(ok, "{text}");
    assert_eq!(got, set_points, "{text}");
    assert_eq!(pymodbus(tcp, "1", "input", "430", "4")["registers"], serde_json::json!(volts));
    // MKZP (unit 17): phase currents.
    let currents = last_heard(&heard, 17, 3, 50);
    assert_eq!(pymodbus(tcp, "17", "holding", "50", "8")["registers"], serde_json::json!(currents));

    // Never heard: an address (02), a unit (0B). A write: 01.
    assert_eq!(pymodbus(tcp, "1", "holding", "2000", "1")["exception"], 2);
    assert_eq!(pymodbus(tcp, "9", "holding", "100", "1")["exception"], 0x0B);
    let (ok, text, _) = mbpoll_write(tcp, &["-a", "1", "-t", "4", "-r", "105"], &["7"]);
    assert!(!ok && text.contains("Illegal function"), "{text}");

    // socat -x logs the sniffer's side to the line as "> …" blocks: there must be none, while
    // the line's side ("< …") carried the whole run.
    let log = std::fs::read_to_string(&log).unwrap();
    assert!(log.lines().any(|l| l.starts_with('<')), "socat relayed nothing: the check would prove nothing");
    let written: Vec<&str> = log.lines().filter(|l| l.starts_with('>')).collect();
    assert!(written.is_empty(), "the sniffer wrote to its port: {written:?}");
}

#[test]
#[ignore = "needs mbpoll; .ci/run installs it and runs this with --ignored"]
fn a_replayed_image_goes_stale_by_its_own_bus_time() {
    // The MK4 document's examples, replayed: served with no age limit, then with 1 ms (the
    // capture spans longer, so its first values are stale by the capture's newest time).
    let serve = |age: &str| {
        let (server, addr) = common::spy_replay(age);
        (server, addr.rsplit(':').next().unwrap().parse::<u16>().unwrap())
    };
    let (_fresh, port) = serve("none");
    let (ok, text, got) = mbpoll(port, &["-a", "1", "-t", "0", "-r", "0", "-c", "8"]);
    assert!(ok, "{text}");
    assert_eq!(got.len(), 8, "{text}");
    let (_stale, port) = serve("1ms");
    let (ok, text, _) = mbpoll(port, &["-a", "1", "-t", "0", "-r", "0", "-c", "8"]);
    assert!(!ok && text.contains("Target device failed to respond"), "{text}");
}

/// Read coils 0–7 of unit 1 (MBAP: transaction 1, protocol 0, length 6, unit 1; PDU 01 0000 0008).
const READ_COILS: [u8; 12] = [0, 1, 0, 0, 0, 6, 1, 0x01, 0x00, 0x00, 0x00, 0x08];

/// A client opening connection after connection gets 64 and no more: the 65th is closed at
/// once and counted, and a place that frees is taken again.
#[test]
fn the_spy_server_holds_at_most_64_connections() {
    use std::io::{Read, Write};
    let (_server, addr) = common::spy_replay("none");
    // Answered at all — the coils, or any exception: the MBAP header's length says how much
    // follows (this test is about the connection limit, not the image).
    let ask = |s: &mut std::net::TcpStream| -> bool {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut header = [0u8; 6];
        if s.write_all(&READ_COILS).is_err() || s.read_exact(&mut header).is_err() {
            return false;
        }
        let mut rest = vec![0u8; usize::from(u16::from_be_bytes([header[4], header[5]]))];
        s.read_exact(&mut rest).is_ok()
    };
    let mut held: Vec<_> = (0..64).map(|_| std::net::TcpStream::connect(&addr).unwrap()).collect();
    for s in &mut held {
        assert!(ask(s), "each of the first 64 is served");
    }
    // All 64 busy (each asked within the last second, so none may be evicted for idling).
    for s in &mut held {
        assert!(ask(s));
    }
    let mut extra = std::net::TcpStream::connect(&addr).unwrap();
    assert!(!ask(&mut extra), "the 65th is closed");
    drop(held.pop());
    // The freed place is taken again (the server notices the close asynchronously: retry).
    let start = std::time::Instant::now();
    while !ask(&mut std::net::TcpStream::connect(&addr).unwrap()) {
        assert!(start.elapsed() < Duration::from_secs(10), "the freed place never came back");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// 64 sockets that never ask cannot hold every place of the spy server until they close themselves:
/// as on the bridge, a socket that has not asked within its grace gives its place to a newcomer.
#[test]
fn idle_sockets_give_their_places_to_clients_that_ask() {
    use std::io::{Read, Write};
    let (_server, addr) = common::spy_replay("none");
    let _idle: Vec<_> = (0..64).map(|_| std::net::TcpStream::connect(&addr).unwrap()).collect();
    std::thread::sleep(Duration::from_millis(400));
    for n in 0..10 {
        let mut s = std::net::TcpStream::connect(&addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        s.write_all(&READ_COILS).unwrap();
        let mut header = [0u8; 7];
        assert!(s.read_exact(&mut header).is_ok(), "client {n} is served");
    }
}
