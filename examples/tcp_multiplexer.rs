//! The Modbus TCP multiplexer's throughput (issue 29): 16 clients back to back against one
//! Modbus TCP device (a pymodbus server, `tests/interop/pymodbus_tcp_server.py`) — directly,
//! each on its own connection; through `mbtap bridge --serial tcp://DEVICE` (one connection to
//! the device for everyone); and through modbus-proxy (PyPI), the tool people use for this —
//! in alternating rounds in one run, so the machine's drift hits all three alike.
//!
//! Run: `cargo build --release && cargo run --release --example tcp_multiplexer -- target/release/mbtap`
//! (needs python3 with pymodbus, and modbus-proxy on PATH). Prints transactions per second and
//! round-trip p50 / p99 per path and round.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::cast_precision_loss)]
#![allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // percentile indexes

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CLIENTS: usize = 16;
const SECONDS: f64 = 5.0;
const ROUNDS: usize = 3;

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn wait_port(port: u16) {
    let start = Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(start.elapsed() < Duration::from_secs(20), "nothing listens on {port}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Read holding registers `first`..`first + 3` of unit 1; true when the answer is the device's
/// (10 × each address). Each client reads its own four: identical reads from several clients
/// would be answered once by the bridge (coalescing), which is not what this measures.
fn call(s: &mut TcpStream, tid: u16, first: u8) -> bool {
    let mut f = Vec::with_capacity(12);
    f.extend_from_slice(&tid.to_be_bytes());
    f.extend_from_slice(&[0, 0, 0, 6, 1, 0x03, 0x00, first, 0x00, 0x04]);
    if s.write_all(&f).is_err() {
        return false;
    }
    let mut head = [0u8; 7];
    if s.read_exact(&mut head).is_err() || head[..2] != tid.to_be_bytes() {
        return false;
    }
    let mut pdu = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])).saturating_sub(1)];
    let want: Vec<u8> =
        [0x03, 8].into_iter().chain((0..4u16).flat_map(|i| ((u16::from(first) + i) * 10).to_be_bytes())).collect();
    s.read_exact(&mut pdu).is_ok() && pdu == want
}

/// 16 clients back to back for `SECONDS`: (transactions per second, p50 ms, p99 ms, failures).
fn load(port: u16) -> (f64, f64, f64, usize) {
    let start = Instant::now();
    let threads: Vec<_> = (0..CLIENTS)
        .map(|c| {
            let first = u8::try_from(c * 4).unwrap();
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
                s.set_nodelay(true).unwrap();
                s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
                let (mut rtts, mut failed, mut tid) = (Vec::new(), 0, 0u16);
                while start.elapsed().as_secs_f64() < SECONDS {
                    tid = tid.wrapping_add(1);
                    let t = Instant::now();
                    if call(&mut s, tid, first) {
                        rtts.push(t.elapsed().as_secs_f64() * 1000.0);
                    } else {
                        failed += 1;
                        s = TcpStream::connect(("127.0.0.1", port)).unwrap();
                    }
                }
                (rtts, failed)
            })
        })
        .collect();
    let (mut all, mut failed) = (Vec::new(), 0);
    for t in threads {
        let (r, f) = t.join().unwrap();
        all.extend(r);
        failed += f;
    }
    let took = start.elapsed().as_secs_f64();
    all.sort_by(f64::total_cmp);
    let pct = |p: f64| all.get(((all.len() as f64 - 1.0) * p).round() as usize).copied().unwrap_or(f64::NAN);
    (all.len() as f64 / took, pct(0.5), pct(0.99), failed)
}

fn main() {
    let bin = std::env::args().nth(1).expect("usage: tcp_multiplexer PATH/TO/mbtap");
    let root = env!("CARGO_MANIFEST_DIR");
    let device = free_port();
    let _device = Kill(
        Command::new("python3")
            .arg(format!("{root}/tests/interop/pymodbus_tcp_server.py"))
            .arg(device.to_string())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("python3 with pymodbus"),
    );
    wait_port(device);
    let mut bridge = Command::new(&bin)
        .args(["bridge", "--serial", &format!("tcp://127.0.0.1:{device}"), "--listen", "127.0.0.1:0"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(bridge.stderr.take().unwrap()).lines();
    let bridged = loop {
        let l = lines.next().expect("the bridge ended").unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: bridge listening on ") {
            break rest.split_whitespace().next().unwrap().rsplit(':').next().unwrap().parse::<u16>().unwrap();
        }
    };
    std::thread::spawn(move || for _ in lines {});
    let _bridge = Kill(bridge);
    let proxied = free_port();
    let _proxy = Kill(
        Command::new("modbus-proxy")
            .args(["-b", &format!("tcp://127.0.0.1:{proxied}"), "--modbus", &format!("tcp://127.0.0.1:{device}")])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("modbus-proxy (pip install modbus-proxy)"),
    );
    wait_port(bridged);
    wait_port(proxied);
    println!("{CLIENTS} clients back to back, {SECONDS} s per path per round, {ROUNDS} rounds");
    for round in 1..=ROUNDS {
        for (name, port) in [("direct", device), ("mbtap bridge", bridged), ("modbus-proxy", proxied)] {
            let (tps, p50, p99, failed) = load(port);
            println!(
                "round {round} {name:>13}: {tps:8.0} transactions/s, p50 {p50:.2} ms, p99 {p99:.2} ms, {failed} failed"
            );
        }
    }
}
