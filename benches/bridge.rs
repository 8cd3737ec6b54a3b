//! The bridge under load, end to end with the real binaries: `mbtap simulate` on a pseudo-
//! terminal (answering at once: `--turnaround-ms 0`), `mbtap bridge` in front of it, and Modbus
//! TCP clients here. Measures
//! 1. the forwarding overhead: one client pausing past t3.5 between requests, its round trip
//!    through the bridge against a direct RTU master's round trip on the same simulator;
//! 2. throughput and latency (p50 / p99, queueing included) with 1, 4, 16 and 64 clients
//!    sending back to back.
//!
//! 3. on a line paced at 9600 baud (the simulator takes each request's and answer's line time,
//!    `simulate --paced`), 16 clients back to back, heard by mbtap's own tap between the bridge
//!    and the line: the idle time between each answer and the next request, and the share of
//!    line time in use.
//!
//! Run: `cargo bench --bench bridge` (about two minutes). Figures go to BENCHMARKS.md.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::cast_precision_loss)]
#![allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // percentile indexes of short vectors

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_mbtap");
/// MK4 phase voltages (unit 1, input registers 430–433).
const PDU: [u8; 5] = [0x04, 0x01, 0xAE, 0x00, 0x04];
const BAUD: &str = "115200";

mod support;
use support::{Kill, percentile};

fn simulator(link: &Path) -> Kill {
    support::simulate(link, &["--turnaround-ms", "0", "--baud", BAUD])
}

fn rtu(pdu: &[u8]) -> Vec<u8> {
    let mut f = vec![1u8];
    f.extend_from_slice(pdu);
    let crc = mbtap_proto::crc16(&f);
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// A direct RTU master on the pseudo-terminal: round trips in ms, pausing `pause` between.
fn direct(link: &Path, n: usize, pause: Duration) -> Vec<f64> {
    use std::os::unix::fs::OpenOptionsExt;
    let mut port = std::fs::OpenOptions::new().read(true).write(true).custom_flags(0o400).open(link).unwrap();
    // Raw mode, as a serial master sets it.
    let _ = Command::new("stty").args(["-F", link.to_str().unwrap(), "raw", "-echo"]).status();
    let frame = rtu(&PDU);
    let mut out = Vec::with_capacity(n);
    let mut buf = [0u8; 64];
    for _ in 0..n {
        std::thread::sleep(pause);
        let t = Instant::now();
        port.write_all(&frame).unwrap();
        let mut got = 0;
        // 13 bytes: unit, fc, count, 8 data, CRC.
        while got < 13 {
            got += port.read(&mut buf[got..]).unwrap();
        }
        out.push(t.elapsed().as_secs_f64() * 1000.0);
    }
    out
}

fn bridge(link: &Path) -> (Kill, String) {
    let mut child = Command::new(BIN)
        .args(["bridge", "--serial", link.to_str().unwrap(), "--listen", "127.0.0.1:0", "--baud", BAUD])
        .args(["--queue-per-client", "4"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let addr = loop {
        let l = lines.next().unwrap().unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: bridge listening on ") {
            break rest.split_whitespace().next().unwrap().to_owned();
        }
    };
    std::thread::spawn(move || for _ in lines {});
    (Kill(child), addr)
}

/// One request; whether the answer was a normal one (not an exception).
fn call(s: &mut TcpStream, tid: u16) -> bool {
    support::call(s, tid, 1, &PDU)[0] == 0x04
}

/// `clients` clients for `seconds`, each pausing `pause` between requests; (round trips ms of
/// normal answers, total answers). Exceptions are counted and reported.
fn through_bridge(addr: &str, clients: usize, seconds: f64, pause: Duration) -> (Vec<f64>, usize) {
    let until = Instant::now() + Duration::from_secs_f64(seconds);
    let threads: Vec<_> = (0..clients)
        .map(|_| {
            let addr = addr.to_owned();
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(&addr).unwrap();
                s.set_nodelay(true).unwrap();
                let mut rtts = Vec::new();
                let mut tid = 0u16;
                while Instant::now() < until {
                    std::thread::sleep(pause);
                    tid = tid.wrapping_add(1);
                    let t = Instant::now();
                    if call(&mut s, tid) {
                        rtts.push(t.elapsed().as_secs_f64() * 1000.0);
                    } else {
                        eprintln!("an exception instead of an answer");
                    }
                }
                rtts
            })
        })
        .collect();
    let mut all = Vec::new();
    for t in threads {
        all.extend(t.join().unwrap());
    }
    let n = all.len();
    (all, n)
}

fn main() {
    let dir = std::env::temp_dir().join(format!("mbtap-bench-bridge-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("bus");
    // t3.5 at 115200 is fixed at 1.75 ms (Serial Line v1.02 §2.5.1.1); pause past it.
    let pause = Duration::from_millis(3);

    if std::env::var("MBTAP_BENCH_ONLY").as_deref() == Ok("9600") {
        line_at_9600(&dir);
        return;
    }
    if std::env::var("MBTAP_BENCH_ONLY").as_deref() == Ok("attackers") {
        attackers(&dir);
        return;
    }
    let sim = simulator(&link);
    let mut d = direct(&link, 2000, pause);
    drop(sim);
    let (d50, d99) = (percentile(&mut d, 0.5), percentile(&mut d, 0.99));
    println!("direct RTU master, {} round trips: p50 {d50:.3} ms, p99 {d99:.3} ms", d.len());

    let sim = simulator(&link);
    let (bridge_process, addr) = bridge(&link);
    let (mut b, _) = through_bridge(&addr, 1, 6.0, pause);
    let (b50, b99) = (percentile(&mut b, 0.5), percentile(&mut b, 0.99));
    println!(
        "through the bridge, 1 client pausing 3 ms, {} round trips: p50 {b50:.3} ms, p99 {b99:.3} ms → added p50 {:.3} ms, p99 {:.3} ms",
        b.len(),
        b50 - d50,
        b99 - d99
    );
    for clients in [1, 4, 16, 64] {
        let seconds = 8.0;
        let (mut rtts, n) = through_bridge(&addr, clients, seconds, Duration::ZERO);
        println!(
            "{clients:>2} clients back to back: {:.0} transactions/s, round trip p50 {:.2} ms, p99 {:.2} ms",
            n as f64 / seconds,
            percentile(&mut rtts, 0.5),
            percentile(&mut rtts, 0.99)
        );
    }
    drop(bridge_process);
    drop(sim);
    line_at_9600(&dir);
    let _ = std::fs::remove_dir_all(&dir);
}

/// 16 clients through the bridge onto a paced 9600 8E1 line, heard by `mbtap tap`.
fn line_at_9600(dir: &Path) {
    let bus = dir.join("bus9600");
    let app = dir.join("app9600");
    let _sim = support::simulate(&bus, &["--paced", "--baud", "9600"]);
    // The tap's output goes to a file: a pipe nobody reads until the end would fill and stall it.
    let tap_out = dir.join("tap9600.jsonl");
    let mut tap = Command::new(BIN)
        .args(["tap", bus.to_str().unwrap(), "--link", app.to_str().unwrap(), "--baud", "9600", "--format", "jsonl"])
        .stdout(std::fs::File::create(&tap_out).unwrap())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    while !app.exists() {
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut child = Command::new(BIN)
        .args(["bridge", "--serial", app.to_str().unwrap(), "--listen", "127.0.0.1:0", "--baud", "9600"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let addr = loop {
        let l = lines.next().unwrap().unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: bridge listening on ") {
            break rest.split_whitespace().next().unwrap().to_owned();
        }
    };
    std::thread::spawn(move || {
        for l in lines.map_while(Result::ok) {
            eprintln!("bridge: {l}");
        }
    });
    let bridge = Kill(child);
    let seconds = 20.0;
    let (_, n) = through_bridge(&addr, 16, seconds, Duration::ZERO);
    drop(bridge);
    let _ = Command::new("kill").args(["-INT", &tap.id().to_string()]).status();
    let _ = tap.wait();
    let out = std::fs::read_to_string(&tap_out).unwrap();
    // Frames in order: (port, arrival of the last byte, bytes).
    let frames: Vec<(u64, u64, usize)> = out
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|j| j["event"] == "frame" && j["check_ok"] == true)
        .map(|j| (j["port"].as_u64().unwrap(), j["t_end_ns"].as_u64().unwrap(), j["hex"].as_str().unwrap().len() / 2))
        .collect();
    // Idle: from an answer's last byte to the next request's arrival (the bridge writes a
    // request at once; on a real line it would start crossing then).
    let mut idle: Vec<f64> = frames
        .windows(2)
        .filter(|w| w[0].0 == 1 && w[1].0 == 0)
        .map(|w| (w[1].1.saturating_sub(w[0].1)) as f64 / 1e6)
        .collect();
    let char_ns = 11.0 * 1e9 / 9600.0;
    let (first, last) = (frames.first().map_or(0, |f| f.1), frames.last().map_or(0, |f| f.1));
    let busy: f64 = frames.iter().map(|f| f.2 as f64 * char_ns).sum();
    let t35 = 3.5 * char_ns / 1e6;
    let over = idle.iter().filter(|&&g| g > t35 + 0.5).count();
    println!(
        "9600 8E1 paced line, 16 clients, {seconds} s: {:.1} transactions/s through the bridge; line in use {:.1} % of the time; \
         idle between answer and next request over {} gaps: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms (t3.5 = {t35:.2} ms; {over} gaps over t3.5 + 0.5 ms)",
        n as f64 / seconds,
        busy / (last - first) as f64 * 100.0,
        idle.len(),
        percentile(&mut idle, 0.5),
        percentile(&mut idle, 0.99),
        percentile(&mut idle, 1.0),
    );
}

/// The bridge with `extra` options; its Modbus TCP address and the other addresses it printed
/// (RTU over TCP, then metrics), in that order.
fn bridge_with(link: &Path, extra: &[&str]) -> (Kill, String, Vec<String>) {
    let mut child = Command::new(BIN)
        .args(["bridge", "--serial", link.to_str().unwrap(), "--listen", "127.0.0.1:0", "--baud", BAUD])
        .args(extra)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let (mut tcp, mut rtu, mut metrics) = (None, None, None);
    while tcp.is_none() || rtu.is_none() || metrics.is_none() {
        let l = lines.next().unwrap().unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: bridge listening on ") {
            let addr = rest.split_whitespace().next().unwrap().to_owned();
            if rest.contains("(Modbus TCP)") { tcp = Some(addr) } else { rtu = Some(addr) }
        } else if let Some(rest) = l.strip_prefix("mbtap: metrics at http://") {
            metrics = Some(rest.trim_end_matches("/metrics").to_owned());
        }
    }
    std::thread::spawn(move || for _ in lines {});
    (Kill(child), tcp.unwrap(), vec![rtu.unwrap(), metrics.unwrap()])
}

/// An attacker: started with a stop flag, its threads returned to be joined.
type Attack = Box<dyn Fn(std::sync::Arc<std::sync::atomic::AtomicBool>) -> Vec<std::thread::JoinHandle<()>>>;

/// A well-behaved client's round trips (one client pausing 3 ms) with each attacker of issue
/// 15 running at once, against the quiet figure.
fn attackers(dir: &Path) {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let link = dir.join("bus-attack");
    let _sim = simulator(&link);
    let (_bridge, addr, others) =
        bridge_with(&link, &["--listen-rtu", "127.0.0.1:0", "--metrics", "127.0.0.1:0", "--timeout-ms", "1000"]);
    let (rtu_addr, metrics_addr) = (others[0].clone(), others[1].clone());
    let pause = Duration::from_millis(3);
    let seconds = 6.0;
    let report = |name: &str, rtts: &mut Vec<f64>| {
        println!(
            "{name:<58} {:>5} answers  p50 {:.3} ms  p99 {:.3} ms  max {:.3} ms",
            rtts.len(),
            percentile(rtts, 0.5),
            percentile(rtts, 0.99),
            percentile(rtts, 1.0)
        );
    };
    let (mut quiet, _) = through_bridge(&addr, 1, seconds, pause);
    report("quiet", &mut quiet);
    let attacks: Vec<(&str, Attack)> = vec![
        ("RTU-over-TCP garbage stream at full speed (reconnecting)", {
            let a = rtu_addr.clone();
            Box::new(move |stop: Arc<AtomicBool>| {
                let a = a.clone();
                vec![std::thread::spawn(move || {
                    let junk = [0x41u8; 4096];
                    while !stop.load(Ordering::Relaxed) {
                        if let Ok(mut s) = TcpStream::connect(&a) {
                            while !stop.load(Ordering::Relaxed) && s.write_all(&junk).is_ok() {}
                        }
                    }
                })]
            })
        }),
        ("2 000 idle sockets opened (held, reconnecting)", {
            let a = addr.clone();
            Box::new(move |stop: Arc<AtomicBool>| {
                let a = a.clone();
                vec![std::thread::spawn(move || {
                    let mut held = Vec::new();
                    while !stop.load(Ordering::Relaxed) {
                        for _ in 0..2000 {
                            if let Ok(s) = TcpStream::connect(&a) {
                                held.push(s);
                            }
                        }
                        std::thread::sleep(Duration::from_millis(500));
                        held.clear();
                    }
                })]
            })
        }),
        ("slowloris: 64 connections, a header byte each 300 ms", {
            let a = addr.clone();
            Box::new(move |stop: Arc<AtomicBool>| {
                (0..64)
                    .map(|_| {
                        let (a, stop) = (a.clone(), Arc::clone(&stop));
                        std::thread::spawn(move || {
                            while !stop.load(Ordering::Relaxed) {
                                let Ok(mut s) = TcpStream::connect(&a) else { continue };
                                while !stop.load(Ordering::Relaxed) && s.write_all(&[0x00]).is_ok() {
                                    std::thread::sleep(Duration::from_millis(300));
                                }
                            }
                        })
                    })
                    .collect()
            })
        }),
        ("metrics flood: connections opened as fast as possible", {
            let a = metrics_addr.clone();
            Box::new(move |stop: Arc<AtomicBool>| {
                (0..4)
                    .map(|_| {
                        let (a, stop) = (a.clone(), Arc::clone(&stop));
                        std::thread::spawn(move || {
                            let mut held = std::collections::VecDeque::new();
                            while !stop.load(Ordering::Relaxed) {
                                if let Ok(s) = TcpStream::connect(&a) {
                                    held.push_back(s);
                                }
                                if held.len() > 200 {
                                    held.pop_front();
                                }
                            }
                        })
                    })
                    .collect()
            })
        }),
        ("8 clients hammering a unit that never answers", {
            let a = addr.clone();
            Box::new(move |stop: Arc<AtomicBool>| {
                (0..8)
                    .map(|_| {
                        let (a, stop) = (a.clone(), Arc::clone(&stop));
                        std::thread::spawn(move || {
                            let mut s = TcpStream::connect(&a).unwrap();
                            let mut tid = 0u16;
                            while !stop.load(Ordering::Relaxed) {
                                tid = tid.wrapping_add(1);
                                // Unit 9: nobody there.
                                let mut f = vec![0u8; 7];
                                f[..2].copy_from_slice(&tid.to_be_bytes());
                                f[5] = 6;
                                f[6] = 9;
                                f.extend_from_slice(&PDU);
                                if s.write_all(&f).is_err() {
                                    return;
                                }
                                let mut answer = [0u8; 9];
                                if s.read_exact(&mut answer).is_err() {
                                    return;
                                }
                            }
                        })
                    })
                    .collect()
            })
        }),
    ];
    for (name, attack) in attacks {
        let stop = Arc::new(AtomicBool::new(false));
        let threads = attack(Arc::clone(&stop));
        std::thread::sleep(Duration::from_millis(500));
        let (mut rtts, _) = through_bridge(&addr, 1, seconds, pause);
        stop.store(true, Ordering::Relaxed);
        for t in threads {
            let _ = t.join();
        }
        report(name, &mut rtts);
    }
}
