//! A client that gave up on a request (its own timeout shorter than the bridge's) and asked
//! again: libmodbus's `unit-test-client` through the bridge failed every test after line 717 in
//! cascade, each late 0x0B meeting the next test's request (21 failed assertions where the
//! floor is 5). Against the real binary and a Modbus TCP device thread (no pty): plain
//! `cargo test`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::io::{Read, Write};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use super::one_path::{READ_TWO, bridge_to, connect, device, honest};
use crate::common::{call, counter};

/// Requests the device was sent for unit 9, the unit that never answers.
static ASKED_OF_9: AtomicUsize = AtomicUsize::new(0);

/// Unit 9 is silent; every other unit answers honestly.
fn unit_9_silent(unit: u8, pdu: &[u8]) -> Option<(u8, Vec<u8>)> {
    if unit == 9 {
        ASKED_OF_9.fetch_add(1, Ordering::SeqCst);
        return None;
    }
    Some((unit, honest(pdu)))
}

/// An MBAP request, not waited for.
fn send(s: &mut std::net::TcpStream, tid: u16, unit: u8, pdu: &[u8]) {
    let mut f = tid.to_be_bytes().to_vec();
    f.extend_from_slice(&[0, 0]);
    f.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    f.push(unit);
    f.extend_from_slice(pdu);
    s.write_all(&f).unwrap();
}

#[test]
fn a_client_that_gave_up_never_gets_the_late_answer_under_its_next_request() {
    let dev = device(unit_9_silent);
    let b = bridge_to(&dev, &["--timeout-ms", "800"]);
    let addr = b.tcp.as_deref().unwrap();
    let (mut holder, mut quitter) = (connect(addr), connect(addr));
    // The holder keeps the line 800 ms on unit 9; the quitter's own request to unit 9 waits
    // behind it. The quitter gives up after 300 ms (its timeout) and asks unit 1.
    send(&mut holder, 1, 9, &READ_TWO);
    std::thread::sleep(Duration::from_millis(20));
    send(&mut quitter, 1, 9, &READ_TWO);
    std::thread::sleep(Duration::from_millis(300));
    let answer = call(&mut quitter, 2, 1, &READ_TWO);
    assert_eq!(answer, honest(&READ_TWO), "its own answer, not the given-up request's 0x0B");
    // The holder never gave up: its 0x0B comes.
    let mut back = [0u8; 9];
    holder.read_exact(&mut back).unwrap();
    assert_eq!(back[7..], [0x83, 0x0B]);
    // The given-up request never took line time: unit 9 was asked once, by the holder.
    assert_eq!(ASKED_OF_9.load(Ordering::SeqCst), 1);
    assert_eq!(counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total"), 1);
}

/// A client that pipelines (MODBUS Messaging on TCP/IP v1.0b §4.2) keeps every answer, in
/// order, however long the first takes.
#[test]
fn a_pipelining_client_keeps_every_answer() {
    let dev = device(|unit, pdu| (unit != 9).then(|| (unit, honest(pdu))));
    let b = bridge_to(&dev, &["--timeout-ms", "400"]);
    let mut c = connect(b.tcp.as_deref().unwrap());
    send(&mut c, 1, 9, &READ_TWO);
    send(&mut c, 2, 1, &READ_TWO);
    std::thread::sleep(Duration::from_millis(200));
    send(&mut c, 3, 1, &READ_TWO);
    let mut first = [0u8; 9];
    c.read_exact(&mut first).unwrap();
    assert_eq!((&first[..2], &first[7..]), (&[0u8, 1][..], &[0x83u8, 0x0B][..]));
    for tid in [2u8, 3] {
        let mut head = [0u8; 7];
        c.read_exact(&mut head).unwrap();
        let mut pdu = vec![0u8; usize::from(head[5]) - 1];
        c.read_exact(&mut pdu).unwrap();
        assert_eq!((head[1], pdu), (tid, honest(&READ_TWO)));
    }
    assert_eq!(counter(b.metrics.as_deref().unwrap(), "mbtap_bridge_abandoned_total"), 0);
}
