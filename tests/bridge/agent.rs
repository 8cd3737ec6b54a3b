//! Beyond the line's limit: identical reads from many clients go out once
//! (coalescing), and `--cache` answers covered reads from memory while fresh, forgets what a
//! write overlaps and never keeps an exception. Against `mbtap simulate --paced` on a real
//! pseudo-terminal at 9600 baud (a line that takes its time): `#[ignore]`d in a plain
//! `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::common;
use common::{BIN, Kill};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-agent-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn paced_line(link: &Path) -> Kill {
    common::simulate(link, &["--paced", "--baud", "9600", "--duration", "120"])
}

fn bridge(link: &Path, extra: &[&str]) -> (Kill, String, String) {
    let mut args = vec!["--serial", link.to_str().unwrap(), "--baud", "9600", "--listen", "127.0.0.1:0"];
    args.extend_from_slice(&["--metrics", "127.0.0.1:0"]);
    args.extend_from_slice(extra);
    let b = common::bridge(&args);
    (b.child, b.tcp.unwrap(), b.metrics.unwrap())
}

fn metric(addr: &str, series: &str) -> u64 {
    common::counter(addr, series.trim_end())
}

fn mbtap(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

/// MK4 input registers 430–433 (MAP v1.1b3 §6.4: 04, address 0x01AE, quantity 4).
const VOLTAGES: [u8; 5] = [0x04, 0x01, 0xAE, 0x00, 0x04];

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn sixteen_clients_reading_the_same_registers_share_the_line() {
    let d = dir("coalesce");
    let link = d.join("bus");
    let _sim = paced_line(&link);
    let (_bridge, tcp, m) = bridge(&link, &[]);
    let until = Instant::now() + Duration::from_secs(3);
    let threads: Vec<_> = (0..16)
        .map(|_| {
            let tcp = tcp.clone();
            std::thread::spawn(move || {
                let mut s = TcpStream::connect(&tcp).unwrap();
                let (mut n, mut tid) = (0u64, 0u16);
                while Instant::now() < until {
                    tid = tid.wrapping_add(1);
                    let answer = common::call(&mut s, tid, 1, &VOLTAGES);
                    assert_eq!(answer[0], 0x04, "a normal answer: {answer:02X?}");
                    n += 1;
                }
                n
            })
        })
        .collect();
    let answered: u64 = threads.into_iter().map(|t| t.join().unwrap()).sum();
    let on_line = metric(&m, "mbtap_bridge_requests_total{unit=\"1\"} ");
    let coalesced = metric(&m, "mbtap_bridge_coalesced_total ");
    assert!(coalesced > 0);
    // Every answer either went on the line or shared one that did.
    assert_eq!(on_line + coalesced, answered, "line {on_line} + coalesced {coalesced} = answered {answered}");
    assert!(on_line * 4 < answered, "16 clients, the line carried {on_line} of {answered}");
}

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn the_cache_answers_fresh_reads_forgets_writes_and_keeps_no_exception() {
    let d = dir("cache");
    let link = d.join("bus");
    let _sim = paced_line(&link);
    let (_bridge, tcp, m) = bridge(&link, &["--cache", "1:holding:100-109=30s", "--cache", "1:holding:9990-9999=30s"]);
    let read = |what: &[&str]| {
        let mut args = vec!["read", tcp.as_str(), "--unit", "1", "--format", "jsonl"];
        args.extend_from_slice(what);
        let o = mbtap(&args);
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let first = read(&["holding", "100..109"]);
    assert_eq!(metric(&m, "mbtap_bridge_cache_misses_total "), 1);
    let second = read(&["holding", "100..109"]);
    assert_eq!(second, first, "the same values from memory");
    assert_eq!(metric(&m, "mbtap_bridge_cache_hits_total "), 1);
    assert_eq!(metric(&m, "mbtap_bridge_requests_total{unit=\"1\"} "), 1, "the line was not used again");
    // A write through the bridge: what it overlaps is read from the device again.
    let o = mbtap(&["write", &tcp, "--unit", "1", "--format", "jsonl", "holding 105=777"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let after = read(&["holding", "105"]);
    assert!(after.contains("\"raw\":777"), "{after}");
    // An exception (holding 9999 is outside the MK4's map) goes to the line every time.
    read(&["holding", "9999"]);
    read(&["holding", "9999"]);
    let hits = metric(&m, "mbtap_bridge_cache_hits_total ");
    assert!(read(&["holding", "9999"]).contains("Illegal Data Address"));
    assert_eq!(metric(&m, "mbtap_bridge_cache_hits_total "), hits, "an exception is never answered from the cache");
}

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn agent_polling_keeps_the_cache_fresh_without_any_client() {
    let d = dir("poll");
    let link = d.join("bus");
    let _sim = paced_line(&link);
    let (_bridge, tcp, m) = bridge(&link, &["--poll", "1:holding:100-109@200ms"]);
    // The bridge polls on its own: requests on the line before any client asked.
    let start = Instant::now();
    while metric(&m, "mbtap_bridge_requests_total{unit=\"1\"} ") < 3 {
        assert!(start.elapsed() < Duration::from_secs(20), "the bridge never polled");
        std::thread::sleep(Duration::from_millis(100));
    }
    let mut s = TcpStream::connect(&tcp).unwrap();
    for tid in 1..=5 {
        let answer = common::call(&mut s, tid, 1, &[0x03, 0x00, 0x64, 0x00, 0x0A]);
        assert_eq!(answer[..2], [0x03, 20], "ten registers: {answer:02X?}");
    }
    assert_eq!(metric(&m, "mbtap_bridge_cache_hits_total "), 5, "every read from memory");
    assert_eq!(metric(&m, "mbtap_bridge_cache_misses_total "), 0);
}
