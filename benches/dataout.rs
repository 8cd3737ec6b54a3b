//! Data out, end to end with the real binaries and real peers:
//! 1. `mbtap watch` against mbpoll on the same simulated MK4 (`mbtap simulate` on a
//!    pseudo-terminal, answering at once): reads per second with a 1 ms pause between polls,
//!    and watch's round latency (p50 / p99).
//! 2. Spy mode: `mbtap replay --serve` of the MK4 document's examples, 16 Modbus TCP clients
//!    back to back: answers per second, p50 / p99.
//! 3. MQTT: a replay of a generated capture published to a Mosquitto broker started here,
//!    counted by `mosquitto_sub`: messages per second end to end; and the replay's wall time with
//!    and without `--mqtt` (the analyzer must not slow down).
//!
//! Run: `cargo bench --bench dataout` (about a minute; needs mbpoll and mosquitto). Figures go
//! to BENCHMARKS.md.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::cast_precision_loss)]

use std::io::{BufRead, BufReader};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

mod support;
use support::{Kill, call, percentile};

const BIN: &str = env!("CARGO_BIN_EXE_mbtap");

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-bench-dataout-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn simulator(link: &Path) -> Kill {
    support::simulate(link, &["--turnaround-ms", "0"])
}

/// `watch` for `n` rounds at `interval` (start to start); its rate and round latency.
fn watch(link: &Path, n: usize, interval: &str) {
    let t = Instant::now();
    let out = Command::new(BIN)
        .args(["watch", link.to_str().unwrap(), "--device", "mk4", "--interval", interval, "--count", &n.to_string()])
        .args(["--format", "jsonl", "430..433"])
        .output()
        .unwrap();
    let secs = t.elapsed().as_secs_f64();
    assert!(out.status.success());
    let mut rounds: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|j| j["address"] == 430)
        .map(|j| j["round_ms"].as_f64().unwrap())
        .collect();
    assert_eq!(rounds.len(), n);
    println!(
        "watch  (interval {interval}): {:.0} reads/s over {n} (process start included); read p50 {:.3} ms, p99 {:.3} ms",
        n as f64 / secs,
        percentile(&mut rounds, 0.5),
        percentile(&mut rounds, 0.99)
    );
}

fn watch_vs_mbpoll(d: &Path) {
    let link = d.join("bus");
    let _sim = simulator(&link);
    watch(&link, 2000, "1ms");
    watch(&link, 500, "10ms");
    // mbpoll polls until killed, one poll every `-l` ms (10 at least, start to start): count
    // its answers over 5 s. It does not say how long each read took; BENCHMARKS.md compares
    // one read from the command line (mbpoll -1 against mbtap read) with benches/paired.sh.
    let mut child = Command::new("mbpoll")
        .args([
            "-m", "rtu", "-b", "19200", "-P", "even", "-a", "1", "-t", "3", "-r", "430", "-c", "4", "-0", "-l", "10",
        ])
        .arg(&link)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mbpoll");
    let count = Arc::new(AtomicU64::new(0));
    let (out, c) = (child.stdout.take().unwrap(), Arc::clone(&count));
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(Result::ok) {
            if l.starts_with("[430]") {
                c.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
    let mbpoll = Kill(child);
    std::thread::sleep(Duration::from_secs(1));
    let (c0, t0) = (count.load(Ordering::Relaxed), Instant::now());
    std::thread::sleep(Duration::from_secs(5));
    let polls = count.load(Ordering::Relaxed) - c0;
    let secs = t0.elapsed().as_secs_f64();
    drop(mbpoll);
    println!("mbpoll (-l 10): {:.0} reads/s over {polls}", polls as f64 / secs);
}

fn spy(_d: &Path) {
    let (_server, addr) = support::spy_replay("none");
    // Coils 0–7 of unit 1, heard in the capture (MAP v1.1b3 §6.1: 01, address 0, quantity 8).
    let pdu = [0x01, 0x00, 0x00, 0x00, 0x08];
    let until = Instant::now() + Duration::from_secs(3);
    let clients = 16;
    let threads: Vec<_> = (0..clients)
        .map(|_| {
            let addr = addr.clone();
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(&addr).unwrap();
                s.set_nodelay(true).unwrap();
                let mut rtts = Vec::new();
                let mut tid = 0u16;
                while Instant::now() < until {
                    tid = tid.wrapping_add(1);
                    let t = Instant::now();
                    let answer = call(&mut s, tid, 1, &pdu);
                    assert_eq!(answer[0], 0x01, "an answer, not an exception");
                    rtts.push(t.elapsed().as_secs_f64() * 1000.0);
                }
                rtts
            })
        })
        .collect();
    let mut all: Vec<f64> = threads.into_iter().flat_map(|t| t.join().unwrap()).collect();
    println!(
        "spy server, {clients} clients: {:.0} answers/s; p50 {:.3} ms, p99 {:.3} ms",
        all.len() as f64 / 3.0,
        percentile(&mut all, 0.5),
        percentile(&mut all, 0.99)
    );
}

fn mqtt(d: &Path) {
    let capture = d.join("big.pcapng");
    let g = Command::new(BIN)
        .args(["generate", capture.to_str().unwrap(), "--transactions", "200000", "--force"])
        .output()
        .unwrap();
    assert!(g.status.success());
    let (_broker, port) = broker(d, "mqtt");
    let replay = |mqtt: bool| {
        let mut c = Command::new(BIN);
        c.args(["replay", capture.to_str().unwrap(), "--format", "summary"]);
        if mqtt {
            c.args(["--mqtt", &format!("mqtt://127.0.0.1:{port}"), "--mqtt-interval", "0", "--mqtt-queue", "10000000"]);
        }
        let t = Instant::now();
        let o = c.output().unwrap();
        assert!(o.status.success());
        (t.elapsed().as_secs_f64(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // A subscriber counting what arrives.
    let counter = Counter::start(port, "mbtap/#");
    let start = Instant::now();
    let (secs, err) = replay(true);
    let (got, end) = counter.settled(start);
    let queued = err.lines().find(|l| l.contains("queued for the broker")).unwrap_or("").to_owned();
    println!(
        "mqtt: replay with --mqtt {secs:.2} s; {got} messages received by mosquitto_sub in {end:.2} s = {:.0} msg/s ({queued})",
        got as f64 / end
    );
    let mut on = Vec::new();
    let mut off = Vec::new();
    for _ in 0..3 {
        off.push(replay(false).0);
        on.push(replay(true).0);
    }
    println!(
        "replay wall time, median of 3: without --mqtt {:.3} s, with {:.3} s",
        percentile(&mut off, 0.5),
        percentile(&mut on, 0.5)
    );
}

/// A subscriber counting the messages that arrive on a topic filter (one line each: `-F %t`
/// prints topics only, as payloads may be binary) and when the last one came.
struct Counter {
    _sub: Kill,
    count: Arc<AtomicU64>,
    last: Arc<std::sync::Mutex<Instant>>,
}

impl Counter {
    fn start(port: u16, filter: &str) -> Self {
        let mut sub = Command::new("mosquitto_sub")
            .args(["-h", "127.0.0.1", "-p", &port.to_string(), "-t", filter, "-F", "%t"])
            .stdout(Stdio::piped())
            .spawn()
            .expect("mosquitto_sub");
        let count = Arc::new(AtomicU64::new(0));
        let last = Arc::new(std::sync::Mutex::new(Instant::now()));
        let (out, c, l) = (sub.stdout.take().unwrap(), Arc::clone(&count), Arc::clone(&last));
        std::thread::spawn(move || {
            for _ in BufReader::new(out).lines().map_while(Result::ok) {
                c.fetch_add(1, Ordering::Relaxed);
                *l.lock().unwrap() = Instant::now();
            }
        });
        std::thread::sleep(Duration::from_millis(500));
        Self { _sub: Kill(sub), count, last }
    }

    /// Once nothing has arrived for a second: how many arrived, and the seconds from `start` to
    /// the last.
    fn settled(&self, start: Instant) -> (u64, f64) {
        loop {
            std::thread::sleep(Duration::from_millis(200));
            if self.last.lock().unwrap().elapsed() > Duration::from_secs(1) {
                break;
            }
        }
        (self.count.load(Ordering::Relaxed), (*self.last.lock().unwrap() - start).as_secs_f64())
    }
}

/// A Mosquitto broker on a free loopback port (no persistence, no queue limit).
fn broker(d: &Path, name: &str) -> (Kill, u16) {
    let port = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let conf = d.join(format!("mosquitto-{name}.conf"));
    std::fs::write(
        &conf,
        format!("listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\nmax_queued_messages 0\n"),
    )
    .unwrap();
    let mosquitto = if Path::new("/usr/sbin/mosquitto").exists() { "/usr/sbin/mosquitto" } else { "mosquitto" };
    let b = Kill(Command::new(mosquitto).arg("-c").arg(&conf).stderr(Stdio::null()).spawn().expect("mosquitto"));
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        std::thread::sleep(Duration::from_millis(50));
    }
    (b, port)
}

/// Sparkplug B messages per second from a replayed capture (counted by a subscriber
/// printing topics only: the payloads are binary), and the store-and-forward rates — holding a
/// replay's messages on disk with no broker, then forwarding them when one is there.
fn sparkplug(d: &Path) {
    let capture = d.join("big.pcapng");
    if !capture.exists() {
        let g = Command::new(BIN)
            .args(["generate", capture.to_str().unwrap(), "--transactions", "200000"])
            .output()
            .unwrap();
        assert!(g.status.success());
    }
    let (_broker, port) = broker(d, "sparkplug");
    let counter = Counter::start(port, "spBv1.0/#");
    let url = format!("mqtt://127.0.0.1:{port}");
    let start = Instant::now();
    let o = Command::new(BIN)
        .args(["replay", capture.to_str().unwrap(), "--format", "summary", "--mqtt", &url])
        .args(["--sparkplug", "bench/node", "--mqtt-queue", "10000000"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let secs = start.elapsed().as_secs_f64();
    let (got, end) = counter.settled(start);
    println!("sparkplug: replay {secs:.2} s; {got} messages received in {end:.2} s = {:.0} msg/s", got as f64 / end);
    // Held: the same replay with the broker's port closed, every message to the disk buffer.
    let held = d.join("held");
    let _ = std::fs::remove_dir_all(&held);
    let closed = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let start = Instant::now();
    let o = Command::new(BIN)
        .args(["replay", capture.to_str().unwrap(), "--format", "summary"])
        .args(["--mqtt", &format!("mqtt://127.0.0.1:{closed}"), "--sparkplug", "bench/node"])
        .args(["--mqtt-buffer", held.to_str().unwrap(), "--mqtt-buffer-max", "4GB"])
        .output()
        .unwrap();
    let secs = start.elapsed().as_secs_f64();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    let line = err.lines().find(|l| l.contains("held on disk")).unwrap_or("").to_owned();
    println!("store: replay with the broker away {secs:.2} s: {line}");
    // Forwarded: a quiet run (the demo for a while) sends what is held, then says its rate.
    let o = Command::new(BIN)
        .args(["demo", "--format", "summary", "--speed", "1", "--duration", "60"])
        .args(["--mqtt", &url, "--sparkplug", "bench/node", "--mqtt-buffer", held.to_str().unwrap()])
        .args(["--mqtt-queue", "10000000"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    let line = err.lines().find(|l| l.contains("forwarded")).unwrap_or("(not all forwarded within 60 s)").to_owned();
    println!("forward: {line}");
}

fn main() {
    let d = dir();
    // `cargo bench --bench dataout -- sparkplug`: that part alone.
    if std::env::args().any(|a| a == "sparkplug") {
        sparkplug(&d);
        return;
    }
    watch_vs_mbpoll(&d);
    spy(&d);
    mqtt(&d);
    sparkplug(&d);
}
