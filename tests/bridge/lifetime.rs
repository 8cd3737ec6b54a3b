//! One transaction lifetime for every front (`mbtap_gateway::lifetime`), against the real binary:
//! which answers each kind of client gets when its requests overlap a slow line. The line is
//! a Modbus TCP device thread of the test that answers after a set delay (std sockets on
//! loopback, port 0); the serial front's master is the test itself on a pty (socat).
//!
//! The table: a client with ids (MBAP) pipelining at 50/150/250/500 ms on a 300/600 ms line, a
//! write then a read, a timer-driven client under another client's load — every request
//! answered under its own id; a client shown sequential that asks again unanswered, an
//! RTU-over-TCP client that asks again before its answer, a serial master with a timeout
//! shorter than the line — the given-up answer never written, never an answer under another
//! request. `mbtap_bridge_abandoned_total` counts what clients without ids gave up,
//! `mbtap_bridge_withheld_sequential_total` what a sequential client with ids did.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use super::one_path::{READ_TWO, connect, device_after, honest};
use crate::common::{self, call, counter};

/// Write single register 10 = 25 (MAP v1.1b3 §6.6): function 06, address 000A, value 0019.
const WRITE_10: [u8; 5] = [0x06, 0x00, 0x0A, 0x00, 0x19];

/// A read of holding registers `addr`, `addr + 1` (MAP v1.1b3 §6.3): function 03, address,
/// quantity 0002.
fn read_two_at(addr: u16) -> [u8; 5] {
    let a = addr.to_be_bytes();
    [0x03, a[0], a[1], 0x00, 0x02]
}

/// Requests the test devices were sent, by unit: the tests run at once, so each counts on units
/// of its own.
static ASKED: [AtomicUsize; 256] = [const { AtomicUsize::new(0) }; 256];

fn asked(unit: u8) -> usize {
    ASKED[usize::from(unit)].load(Ordering::SeqCst)
}

/// What the slow device answers: reads honestly, writes by echo (§6.6), units 9 and 19 never.
fn answer_of(unit: u8, pdu: &[u8]) -> Option<(u8, Vec<u8>)> {
    ASKED[usize::from(unit)].fetch_add(1, Ordering::SeqCst);
    match (unit, pdu.first()) {
        (9 | 19, _) => None,
        (_, Some(0x06)) => Some((unit, pdu.to_vec())),
        _ => Some((unit, honest(pdu))),
    }
}

/// A Modbus TCP device on a free loopback port that answers each request `delay` after it read
/// it, one at a time.
fn slow_device(delay: Duration) -> String {
    device_after(delay, answer_of)
}

/// The bridge in front of `device`, with Modbus TCP, RTU over TCP and metrics on free ports.
fn bridge(device: &str, extra: &[&str]) -> common::Bridge {
    let serial = format!("tcp://{device}");
    let mut args = vec![
        "--serial",
        serial.as_str(),
        "--listen",
        "127.0.0.1:0",
        "--listen-rtu",
        "127.0.0.1:0",
        "--metrics",
        "127.0.0.1:0",
        "--timeout-ms",
        "2000",
    ];
    args.extend_from_slice(extra);
    common::bridge(&args)
}

/// An MBAP request, not waited for.
fn send(s: &mut TcpStream, tid: u16, unit: u8, pdu: &[u8]) {
    let mut f = tid.to_be_bytes().to_vec();
    f.extend_from_slice(&[0, 0]);
    f.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    f.push(unit);
    f.extend_from_slice(pdu);
    s.write_all(&f).unwrap();
}

/// The next MBAP answer: its transaction id and PDU.
fn receive(s: &mut TcpStream) -> (u16, Vec<u8>) {
    let mut head = [0u8; 7];
    s.read_exact(&mut head).unwrap();
    let mut pdu = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
    s.read_exact(&mut pdu).unwrap();
    (u16::from_be_bytes([head[0], head[1]]), pdu)
}

/// Whether anything more comes on `s` within `wait`.
fn silent_for(s: &mut TcpStream, wait: Duration) -> bool {
    s.set_read_timeout(Some(wait)).unwrap();
    let mut b = [0u8; 1];
    let quiet = matches!(s.read(&mut b), Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut));
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    quiet
}

/// Pipelining: 8 reads `gap_ms` apart on a line answering in `line_ms`; the (id, PDU) pairs
/// that came back, in order.
fn pipelined(gap_ms: u64, line_ms: u64) -> Vec<(u16, Vec<u8>)> {
    let dev = slow_device(Duration::from_millis(line_ms));
    let b = bridge(&dev, &[]);
    let mut c = connect(b.tcp.as_deref().unwrap());
    let mut expected = Vec::new();
    for tid in 1..=8u16 {
        let pdu = read_two_at(tid * 10);
        send(&mut c, tid, 1, &pdu);
        expected.push((tid, honest(&pdu)));
        std::thread::sleep(Duration::from_millis(gap_ms));
    }
    let got: Vec<_> = (0..8).map(|_| receive(&mut c)).collect();
    assert_eq!(counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total"), 0);
    assert_eq!(got, expected, "gap {gap_ms} ms, line {line_ms} ms");
    got
}

#[test]
fn a_client_with_ids_gets_every_pipelined_answer_at_any_spacing() {
    // Each case on its own bridge and device, at once: the cases wait, they do not compute.
    let cases: Vec<_> = [50, 150, 250, 500]
        .into_iter()
        .flat_map(|gap| [300, 600].map(move |line| (gap, line)))
        .map(|(gap, line)| std::thread::spawn(move || pipelined(gap, line)))
        .collect();
    for c in cases {
        assert_eq!(c.join().unwrap().len(), 8);
    }
}

#[test]
fn a_writes_answer_is_sent_though_a_read_follows_it() {
    let dev = slow_device(Duration::from_millis(300));
    let b = bridge(&dev, &[]);
    let mut c = connect(b.tcp.as_deref().unwrap());
    send(&mut c, 1, 3, &WRITE_10);
    std::thread::sleep(Duration::from_millis(150));
    send(&mut c, 2, 3, &READ_TWO);
    assert_eq!(receive(&mut c), (1, WRITE_10.to_vec()), "the write's echo, under its id");
    assert_eq!(receive(&mut c), (2, honest(&READ_TWO)));
    assert_eq!(asked(3), 2);
    assert_eq!(counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total"), 0);
}

/// Client A reads every 150 ms on a timer; client B keeps 8 reads queued on a 100 ms line, so
/// A's turn comes every 200 ms. A's answers are late (the line is shared), never gone.
#[test]
fn another_clients_load_makes_no_answer_vanish() {
    let dev = slow_device(Duration::from_millis(100));
    let b = bridge(&dev, &["--queue-per-client", "32"]);
    let addr = b.tcp.clone().unwrap();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let load = {
        let (addr, stop) = (addr.clone(), std::sync::Arc::clone(&stop));
        std::thread::spawn(move || {
            let mut c = connect(&addr);
            let mut tid = 0u16;
            for _ in 0..8 {
                tid += 1;
                send(&mut c, tid, 1, &READ_TWO);
            }
            while !stop.load(Ordering::SeqCst) {
                receive(&mut c);
                tid = tid.wrapping_add(1);
                send(&mut c, tid, 1, &READ_TWO);
            }
        })
    };
    std::thread::sleep(Duration::from_millis(200));
    let mut a = connect(&addr);
    let reader = {
        let mut a = a.try_clone().unwrap();
        std::thread::spawn(move || (0..20).map(|_| receive(&mut a)).collect::<Vec<_>>())
    };
    let start = Instant::now();
    for tid in 1..=20u16 {
        send(&mut a, tid, 1, &read_two_at(tid));
        let next = Duration::from_millis(150 * u64::from(tid));
        std::thread::sleep(next.saturating_sub(start.elapsed()));
    }
    let got = reader.join().unwrap();
    stop.store(true, Ordering::SeqCst);
    let expected: Vec<_> = (1..=20u16).map(|tid| (tid, honest(&read_two_at(tid)))).collect();
    assert_eq!(got, expected);
    load.join().unwrap();
    assert_eq!(counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total"), 0);
}

/// libmodbus's way: each request right after the previous answer; then one the line cannot
/// answer within its 0.5 s, and the next request 0.555 s later. The late 0x0B never meets it;
/// the given-up request took line time once.
#[test]
fn a_client_shown_sequential_never_gets_the_late_answer_under_its_next_request() {
    let dev = slow_device(Duration::from_millis(5));
    let b = bridge(&dev, &["--timeout-ms", "800"]);
    let mut c = connect(b.tcp.as_deref().unwrap());
    for tid in 1..=4u16 {
        assert_eq!(call(&mut c, tid, 5, &READ_TWO), honest(&READ_TWO));
    }
    send(&mut c, 5, 19, &READ_TWO);
    std::thread::sleep(Duration::from_millis(555));
    assert_eq!(call(&mut c, 6, 5, &READ_TWO), honest(&READ_TWO), "its own answer, under its id");
    assert!(silent_for(&mut c, Duration::from_millis(600)), "the given-up request's 0x0B is never written");
    assert_eq!((asked(5), asked(19)), (5, 1), "the given-up request took line time once");
    let metrics = b.metrics.as_deref().unwrap();
    assert_eq!(counter(metrics, "mbtap_bridge_withheld_sequential_total"), 1);
    assert_eq!(counter(metrics, "mbtap_bridge_abandoned_total"), 0, "counts clients without ids only");
}

/// A client with ids that has not shown it waits for answers gets the 0x0B of a dead unit under
/// that request's id, then its next answer: nothing is taken from it because it asked again.
#[test]
fn a_client_not_shown_sequential_gets_the_dead_units_exception_under_its_id() {
    let dev = slow_device(Duration::from_millis(5));
    let b = bridge(&dev, &["--timeout-ms", "400"]);
    let mut c = connect(b.tcp.as_deref().unwrap());
    send(&mut c, 1, 9, &READ_TWO);
    std::thread::sleep(Duration::from_millis(300));
    send(&mut c, 2, 1, &READ_TWO);
    assert_eq!(receive(&mut c), (1, vec![0x83, 0x0B]));
    assert_eq!(receive(&mut c), (2, honest(&READ_TWO)));
    assert_eq!(counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total"), 0);
}

/// An RTU frame (address, PDU, CRC low byte first: Serial Line v1.02 §2.5.1).
fn rtu(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    mbtap_proto::encode_rtu(unit, pdu, &mut out);
    out
}

/// RTU over TCP has no ids: a request sent before the last one's answer means the client gave
/// up on it, whatever the spacing; that answer never comes, the next one does.
#[test]
fn an_rtu_over_tcp_client_asking_again_never_gets_the_earlier_answer() {
    for gap in [20, 150] {
        let dev = slow_device(Duration::from_millis(300));
        let b = bridge(&dev, &[]);
        let mut c = connect(b.rtu.as_deref().unwrap());
        c.write_all(&rtu(1, &read_two_at(100))).unwrap();
        std::thread::sleep(Duration::from_millis(gap));
        c.write_all(&rtu(1, &read_two_at(1000))).unwrap();
        let expected = rtu(1, &honest(&read_two_at(1000)));
        let mut got = vec![0u8; expected.len()];
        c.read_exact(&mut got).unwrap();
        assert_eq!(got, expected, "gap {gap} ms: the second request's answer, not the first's");
        assert!(silent_for(&mut c, Duration::from_millis(500)), "gap {gap} ms: nothing more");
        assert_eq!(counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total"), 1, "gap {gap} ms");
    }
}

/// A serial master on `--listen-serial` with a timeout of `timeout_ms`, asking the registers at
/// 100 and 1000 in turn, `n` times, each request right after the last answer or the timeout;
/// (right, wrong, silent).
fn serial_master(port: &std::path::Path, timeout_ms: u64, n: usize) -> (usize, usize, usize) {
    use std::os::unix::fs::OpenOptionsExt as _;
    let mut p = std::fs::OpenOptions::new().read(true).write(true).custom_flags(libc_nonblock()).open(port).unwrap();
    let (mut right, mut wrong, mut silent) = (0, 0, 0);
    for i in 0..n {
        let addr = if i % 2 == 0 { 100 } else { 1000 };
        let pdu = read_two_at(addr);
        p.write_all(&rtu(1, &pdu)).unwrap();
        let expected = rtu(1, &honest(&pdu));
        let deadline = Instant::now() + Duration::from_millis(timeout_ms);
        let mut got = Vec::new();
        while Instant::now() < deadline && got.len() < expected.len() {
            let mut b = [0u8; 64];
            match p.read(&mut b) {
                Ok(n) if n > 0 => got.extend_from_slice(&b[..n]),
                _ => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        match (got.is_empty(), got == expected) {
            (true, _) => silent += 1,
            (false, true) => right += 1,
            (false, false) => wrong += 1,
        }
    }
    (right, wrong, silent)
}

/// `O_NONBLOCK` (Linux): the test's master polls the pty with its own deadline.
const fn libc_nonblock() -> i32 {
    0o4000
}

/// The serial front's master with a 200 ms timeout, a unit answering in 300 ms: never another
/// read's values. With a 60 ms unit and one TCP client keeping 8 reads queued ahead of it: never
/// another read's values either.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn a_serial_master_with_a_short_timeout_never_gets_another_reads_values() {
    for (line_ms, timeout_ms, load) in [(300, 200, false), (60, 100, false), (60, 100, true)] {
        let d = std::env::temp_dir().join(format!("mbtap-lifetime-{}-{line_ms}-{load}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let (_socat, front, master) = common::socat_pair(&d);
        let dev = slow_device(Duration::from_millis(line_ms));
        let b = bridge(&dev, &["--listen-serial", front.to_str().unwrap()]);
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let loader = load.then(|| {
            let (addr, stop) = (b.tcp.clone().unwrap(), std::sync::Arc::clone(&stop));
            std::thread::spawn(move || {
                let mut c = connect(&addr);
                for tid in 0..8u16 {
                    send(&mut c, tid, 1, &READ_TWO);
                }
                let mut tid = 8u16;
                while !stop.load(Ordering::SeqCst) {
                    receive(&mut c);
                    send(&mut c, tid, 1, &READ_TWO);
                    tid = tid.wrapping_add(1);
                }
            })
        });
        std::thread::sleep(Duration::from_millis(300));
        let (right, wrong, silent) = serial_master(&master, timeout_ms, 12);
        stop.store(true, Ordering::SeqCst);
        if let Some(l) = loader {
            l.join().unwrap();
        }
        assert_eq!(wrong, 0, "line {line_ms} ms, timeout {timeout_ms} ms, load {load}: {right} right, {silent} silent");
        assert_eq!(right + silent, 12);
        if line_ms < timeout_ms && !load {
            assert_eq!(right, 12, "a unit faster than the master's timeout: every answer");
        }
        if line_ms > timeout_ms {
            let abandoned = counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total");
            assert!(abandoned >= 11, "each request given up at the next one: {abandoned}");
        }
        std::fs::remove_dir_all(&d).ok();
    }
}

/// A master on the serial front that sends without waiting (500 requests at once to a 300 ms
/// line): it gave up on all but its last; the front keeps a bounded few, never queues the burst
/// on the line, and answers the next request a waiting master sends.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn a_serial_master_flooding_requests_is_held_to_a_bounded_few() {
    let d = std::env::temp_dir().join(format!("mbtap-lifetime-flood-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let (_socat, front, master) = common::socat_pair(&d);
    let b = bridge(&slow_device(Duration::from_millis(300)), &["--listen-serial", front.to_str().unwrap()]);
    std::thread::sleep(Duration::from_millis(300));
    {
        let mut p = std::fs::OpenOptions::new().write(true).open(&master).unwrap();
        let burst: Vec<u8> = (0..500u16).flat_map(|a| rtu(1, &read_two_at(a))).collect();
        p.write_all(&burst).unwrap();
    }
    std::thread::sleep(Duration::from_secs(3));
    let abandoned = counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total");
    assert!(abandoned >= 480, "the burst's older requests given up, not queued: {abandoned}");
    // The answer to the burst's last request is on the line for whoever reads it; a master that
    // waits (clearing its input first, as masters do) is answered.
    std::thread::sleep(Duration::from_secs(1));
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        let mut p = std::fs::OpenOptions::new().read(true).custom_flags(libc_nonblock()).open(&master).unwrap();
        let mut sink = [0u8; 4096];
        while matches!(p.read(&mut sink), Ok(n) if n > 0) {}
    }
    let (right, wrong, _) = serial_master(&master, 1_000, 2);
    assert_eq!((right, wrong), (2, 0));
    std::fs::remove_dir_all(&d).ok();
}
