//! Beyond the line's limit, end to end on a paced 9600 8E1 line (`mbtap simulate
//! --paced --baud 9600`): 64 Modbus TCP clients each reading the same 10 MK4 holding
//! registers once a second (their starts spread over the second), with and without
//! `--cache 1:holding:100-109=1s`, and with agent polling (`--poll …@500ms`, values kept 1 s);
//! and 16 clients back to back on the same range (coalescing).
//! The line's load is the bridge's own count of requests it put on the line.
//!
//! Run: `cargo bench --bench agent` (about 40 s). Figures go to BENCHMARKS.md.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::cast_precision_loss)]

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

mod support;
use support::{Kill, call, percentile};

/// Holding registers 100–109 (MAP v1.1b3 §6.3: 03, address 100, quantity 10).
const PDU: [u8; 5] = [0x03, 0x00, 0x64, 0x00, 0x0A];

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-bench-agent-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn line(link: &Path) -> Kill {
    support::simulate(link, &["--paced", "--baud", "9600"])
}

fn bridge(link: &Path, extra: &[&str]) -> (Kill, String, String) {
    let mut args = vec!["--serial", link.to_str().unwrap(), "--baud", "9600", "--listen", "127.0.0.1:0"];
    args.extend_from_slice(&["--metrics", "127.0.0.1:0", "--max-connections", "100"]);
    args.extend_from_slice(extra);
    let b = support::bridge(&args);
    (b.child, b.tcp.unwrap(), b.metrics.unwrap())
}

fn metric(addr: &str, series: &str) -> f64 {
    support::counter(addr, series.trim_end()) as f64
}

/// `clients` clients for `secs`, each every `period` (None: back to back); (answers, latencies
/// ms of normal answers, exception answers).
fn clients(tcp: &str, clients: usize, secs: f64, period: Option<Duration>) -> (usize, Vec<f64>, usize) {
    let until = Instant::now() + Duration::from_secs_f64(secs);
    let threads: Vec<_> = (0..clients)
        .map(|i| {
            let tcp = tcp.to_owned();
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(&tcp).unwrap();
                s.set_nodelay(true).unwrap();
                if let Some(p) = period {
                    // Starts spread over the period, as independent pollers are.
                    std::thread::sleep(p.mul_f64(i as f64 / clients as f64));
                }
                let (mut lat, mut exc, mut tid) = (Vec::new(), 0, 0u16);
                while Instant::now() < until {
                    let t = Instant::now();
                    tid = tid.wrapping_add(1);
                    let answer = call(&mut s, tid, 1, &PDU);
                    if answer[0] == 0x03 {
                        lat.push(t.elapsed().as_secs_f64() * 1000.0);
                    } else {
                        exc += 1;
                    }
                    if let Some(p) = period {
                        std::thread::sleep(p.saturating_sub(t.elapsed()));
                    }
                }
                (lat, exc)
            })
        })
        .collect();
    let (mut all, mut exc) = (Vec::new(), 0);
    for t in threads {
        let (l, e) = t.join().unwrap();
        all.extend(l);
        exc += e;
    }
    (all.len() + exc, all, exc)
}

/// Eight clients reading one holding register each (different ones: nothing to coalesce) back
/// to back for 10 s, and one writing holding 105 every 200 ms: the writes' round trips (ms) and
/// how many reads the historians got.
fn historian_and_control(tcp: &str) -> (Vec<f64>, usize) {
    let until = Instant::now() + Duration::from_secs(10);
    let readers: Vec<_> = (0..8u16)
        .map(|i| {
            let tcp = tcp.to_owned();
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(&tcp).unwrap();
                s.set_nodelay(true).unwrap();
                let pdu = [0x03, 0x00, u8::try_from(100 + i).unwrap(), 0x00, 0x01];
                let (mut n, mut tid) = (0usize, 0u16);
                while Instant::now() < until {
                    tid = tid.wrapping_add(1);
                    call(&mut s, tid, 1, &pdu);
                    n += 1;
                }
                n
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let mut s = TcpStream::connect(tcp).unwrap();
    s.set_nodelay(true).unwrap();
    let mut lat = Vec::new();
    let mut tid = 0u16;
    while Instant::now() + Duration::from_millis(500) < until {
        tid = tid.wrapping_add(1);
        let t = Instant::now();
        // Holding 105 (Level 2 set point) = 150: MAP v1.1b3 §6.6.
        let answer = call(&mut s, tid, 1, &[0x06, 0x00, 0x69, 0x00, 0x96]);
        assert_eq!(answer[0], 0x06, "{answer:02X?}");
        lat.push(t.elapsed().as_secs_f64() * 1000.0);
        std::thread::sleep(Duration::from_millis(200).saturating_sub(t.elapsed()));
    }
    let reads = readers.into_iter().map(|t| t.join().unwrap()).sum();
    (lat, reads)
}

fn main() {
    let d = dir();
    let link = d.join("bus");
    for (name, extra) in [
        ("no cache", &[][..]),
        ("--cache 1:holding:100-109=1s", &["--cache", "1:holding:100-109=1s"][..]),
        ("--poll 1:holding:100-109@500ms", &["--poll", "1:holding:100-109@500ms"][..]),
    ] {
        let _sim = line(&link);
        let (_bridge, tcp, m) = bridge(&link, extra);
        let secs = 10.0;
        let (n, mut lat, exc) = clients(&tcp, 64, secs, Some(Duration::from_secs(1)));
        let on_line = metric(&m, "mbtap_bridge_requests_total{unit=\"1\"} ");
        let hits = metric(&m, "mbtap_bridge_cache_hits_total ");
        let coalesced = metric(&m, "mbtap_bridge_coalesced_total ");
        println!(
            "64 clients × 1/s, {name}: {:.1} answered/s ({exc} exceptions), p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; line {:.1} requests/s; cache hits {hits}, coalesced {coalesced}",
            n as f64 / secs,
            percentile(&mut lat, 0.5),
            percentile(&mut lat, 0.99),
            percentile(&mut lat, 1.0),
            on_line / secs
        );
    }
    for (name, extra) in [("no priority", &[][..]), ("--priority high=fc:6", &["--priority", "high=fc:6"][..])] {
        let _sim = line(&link);
        let (_bridge, tcp, _) = bridge(&link, extra);
        let (mut write_ms, historian) = historian_and_control(&tcp);
        println!(
            "8 historians back to back + a control-room write every 200 ms, {name}: write p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; historian reads {historian}",
            percentile(&mut write_ms, 0.5),
            percentile(&mut write_ms, 0.99),
            percentile(&mut write_ms, 1.0)
        );
    }
    let _sim = line(&link);
    let (_bridge, tcp, m) = bridge(&link, &[]);
    let (n, _, _) = clients(&tcp, 16, 5.0, None);
    let on_line = metric(&m, "mbtap_bridge_requests_total{unit=\"1\"} ");
    println!(
        "16 clients back to back, no cache: {n} answered, {on_line} on the line ({:.3} of requests)",
        on_line / n as f64
    );
}
