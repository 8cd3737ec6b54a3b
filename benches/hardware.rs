//! The bridge on RS-485 line physics, end to end with the real binaries on a paced
//! 9600 8E1 line (`mbtap simulate --paced --baud 9600`, which takes each frame's line time):
//! 1. `--echo on` against an echoing adapter (`simulate --echo`) vs `--echo off` against a
//!    plain one: one client back to back, transactions per second and latency p50 / p99;
//! 2. `--timeout auto` vs a fixed 1000 ms when one of three polled units dies (the simulator is
//!    restarted without it, the bridge reopens the port): line time lost waiting for the dead
//!    unit, and the live units' answers per second.
//!
//! Run: `cargo bench --bench hardware` (about a minute). Figures go to BENCHMARKS.md.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::cast_precision_loss)]

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

mod support;
use support::{Kill, call, percentile};

/// Read input registers 430–433 (MAP v1.1b3 §6.4): the MK4's voltages, the Display's
/// registers…
const PDU: [u8; 5] = [0x04, 0x01, 0xAE, 0x00, 0x04];
/// …read holding registers 50–52 (§6.3): the MKZP's currents (it has no function 04).
const PDU_MKZP: [u8; 5] = [0x03, 0x00, 0x32, 0x00, 0x03];

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-bench-hw-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn simulator(link: &Path, extra: &[&str]) -> Kill {
    support::simulate(link, &[&["--paced", "--baud", "9600", "--turnaround-ms", "2"][..], extra].concat())
}

fn bridge(link: &Path, extra: &[&str]) -> (Kill, String, String) {
    let mut args = vec!["--serial", link.to_str().unwrap(), "--listen", "127.0.0.1:0", "--metrics", "127.0.0.1:0"];
    args.extend_from_slice(&["--baud", "9600"]);
    args.extend_from_slice(extra);
    let b = support::bridge(&args);
    (b.child, b.tcp.unwrap(), b.metrics.unwrap())
}

fn metric(addr: &str, name: &str, unit: u8) -> f64 {
    support::counter(addr, &format!("{name}{{unit=\"{unit}\"}}")) as f64
}

/// One client back to back for `secs`: (answers, latencies ms).
fn load(tcp: &str, unit: u8, secs: f64) -> (usize, Vec<f64>) {
    let mut s = TcpStream::connect(tcp).unwrap();
    s.set_nodelay(true).unwrap();
    let until = Instant::now() + Duration::from_secs_f64(secs);
    let (mut ok, mut lat, mut tid) = (0, Vec::new(), 0u16);
    while Instant::now() < until {
        tid = tid.wrapping_add(1);
        let t = Instant::now();
        let pdu: &[u8] = if unit == 17 { &PDU_MKZP } else { &PDU };
        let answer = call(&mut s, tid, unit, pdu);
        if answer.first() == pdu.first() {
            ok += 1;
            lat.push(t.elapsed().as_secs_f64() * 1000.0);
        }
    }
    (ok, lat)
}

fn echo(d: &Path) {
    for (name, sim_extra, bridge_extra) in [
        ("--echo off, plain adapter", &[][..], &["--echo", "off"][..]),
        ("--echo on, echoing adapter", &["--echo"][..], &["--echo", "on"][..]),
    ] {
        let link = d.join("echo-bus");
        let _sim = simulator(&link, sim_extra);
        let (_bridge, tcp, _) = bridge(&link, bridge_extra);
        let _ = load(&tcp, 1, 1.0);
        let (ok, mut lat) = load(&tcp, 1, 5.0);
        println!(
            "{name}: {:.1} transactions/s; p50 {:.2} ms, p99 {:.2} ms",
            ok as f64 / 5.0,
            percentile(&mut lat, 0.5),
            percentile(&mut lat, 0.99)
        );
    }
}

fn dead_unit(d: &Path) {
    for (name, extra) in [("fixed 1000 ms", &[][..]), ("--timeout auto", &["--timeout", "auto"][..])] {
        let link = d.join("dead-bus");
        let sim = simulator(&link, &[]);
        let (_bridge, tcp, m) = bridge(&link, extra);
        // Phase 1: all three units answer; auto learns.
        let clients = |secs: f64| {
            let threads: Vec<_> = [1u8, 5, 17]
                .into_iter()
                .map(|u| {
                    let tcp = tcp.clone();
                    std::thread::spawn(move || load(&tcp, u, secs).0)
                })
                .collect();
            threads.into_iter().map(|t| t.join().unwrap()).collect::<Vec<_>>()
        };
        clients(3.0);
        // Unit 5 dies: the line comes back without it.
        drop(sim);
        let _sim = simulator(&link, &["--device", "mk4@1", "--device", "mkzp@17"]);
        std::thread::sleep(Duration::from_secs(2));
        let wasted_before = metric(&m, "mbtap_bridge_timeout_wait_seconds_total", 5);
        let answered = clients(10.0);
        let wasted = metric(&m, "mbtap_bridge_timeout_wait_seconds_total", 5) - wasted_before;
        println!(
            "{name}: over 10 s with unit 5 dead, {wasted:.2} s of line time waiting for it; units 1 and 17 answered {:.1} and {:.1} /s",
            answered[0] as f64 / 10.0,
            answered[2] as f64 / 10.0
        );
    }
}

fn main() {
    let d = dir();
    echo(&d);
    dead_unit(&d);
}
