//! Capture files as they come: classic pcap (µs and ns, both byte orders), pcapng with any
//! if_tsresol and several interfaces, and bad input — truncated and corrupt files, unknown
//! link types, zero-length and 70 kB packets, timestamps that go backwards. Each gets a clear
//! message and the rest of the file still replays.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_analysis::capture::{CaptureReader, Item, PcapNgWriter};
use mbtap_analysis::chunk::Timestamp;

/// MK4 §3.3 read request and response, RTU.
const REQ: &[u8] = &[0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4];
const RESP: &[u8] = &[0x01, 0x03, 0x06, 0x00, 0x00, 0x00, 0x00, 0x01, 0x90, 0x20, 0x89];

#[derive(Debug, PartialEq)]
enum Got {
    Packet(u8, u64, Vec<u8>),
    Interface(u8, u16),
    Warning(String),
}

fn read_all(bytes: &[u8]) -> Vec<Got> {
    let mut r = CaptureReader::new(bytes);
    let mut out = Vec::new();
    while let Some(item) = r.next_item().unwrap() {
        out.push(match item {
            Item::Packet { port, t, data } => Got::Packet(port.0, t.0, data.to_vec()),
            Item::Interface { port, interface } => Got::Interface(port.0, interface.linktype),
            Item::Warning(w) => Got::Warning(w),
        });
    }
    out
}

fn packets(got: &[Got]) -> Vec<(u8, u64, Vec<u8>)> {
    got.iter()
        .filter_map(|g| match g {
            Got::Packet(p, t, d) => Some((*p, *t, d.clone())),
            _ => None,
        })
        .collect()
}

fn warnings(got: &[Got]) -> Vec<&str> {
    got.iter()
        .filter_map(|g| match g {
            Got::Warning(w) => Some(w.as_str()),
            _ => None,
        })
        .collect()
}

/// A classic pcap file: magic, v2.4, zone 0, sigfigs 0, snaplen, linktype; then records.
fn pcap(big_endian: bool, nanos: bool, linktype: u32, records: &[(u32, u32, &[u8])]) -> Vec<u8> {
    let w32 = |v: u32| if big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
    let w16 = |v: u16| if big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
    let mut f = Vec::new();
    f.extend_from_slice(&w32(if nanos { 0xA1B2_3C4D } else { 0xA1B2_C3D4 }));
    f.extend_from_slice(&w16(2));
    f.extend_from_slice(&w16(4));
    f.extend_from_slice(&w32(0));
    f.extend_from_slice(&w32(0));
    f.extend_from_slice(&w32(65535));
    f.extend_from_slice(&w32(linktype));
    for (sec, frac, data) in records {
        let len = u32::try_from(data.len()).unwrap();
        for v in [*sec, *frac, len, len] {
            f.extend_from_slice(&w32(v));
        }
        f.extend_from_slice(data);
    }
    f
}

#[test]
fn classic_pcap_micro_and_nano_both_byte_orders() {
    for big in [false, true] {
        let us = read_all(&pcap(big, false, 147, &[(100, 250_000, REQ), (100, 260_000, RESP)]));
        assert_eq!(packets(&us), vec![(0, 100_250_000_000, REQ.to_vec()), (0, 100_260_000_000, RESP.to_vec())]);
        let ns = read_all(&pcap(big, true, 147, &[(100, 250_000_123, REQ)]));
        assert_eq!(packets(&ns), vec![(0, 100_250_000_123, REQ.to_vec())]);
    }
}

/// A hand-built pcapng block.
fn block(t: u32, body: &[u8]) -> Vec<u8> {
    let mut body = body.to_vec();
    while !body.len().is_multiple_of(4) {
        body.push(0);
    }
    let len = u32::try_from(body.len() + 12).unwrap();
    let mut b = t.to_le_bytes().to_vec();
    b.extend_from_slice(&len.to_le_bytes());
    b.extend_from_slice(&body);
    b.extend_from_slice(&len.to_le_bytes());
    b
}

fn shb() -> Vec<u8> {
    let mut body = 0x1A2B_3C4Du32.to_le_bytes().to_vec();
    body.extend_from_slice(&[1, 0, 0, 0]);
    body.extend_from_slice(&(-1i64).to_le_bytes());
    block(0x0A0D_0D0A, &body)
}

/// An IDB with an optional if_tsresol option.
fn idb(linktype: u16, tsresol: Option<u8>) -> Vec<u8> {
    let mut body = linktype.to_le_bytes().to_vec();
    body.extend_from_slice(&[0, 0, 0, 0, 0, 0]);
    if let Some(r) = tsresol {
        body.extend_from_slice(&9u16.to_le_bytes());
        body.extend_from_slice(&1u16.to_le_bytes());
        body.extend_from_slice(&[r, 0, 0, 0]);
    }
    body.extend_from_slice(&[0, 0, 0, 0]);
    block(1, &body)
}

fn epb(iface: u32, ticks: u64, data: &[u8]) -> Vec<u8> {
    let mut body = iface.to_le_bytes().to_vec();
    body.extend_from_slice(&u32::try_from(ticks >> 32).unwrap().to_le_bytes());
    body.extend_from_slice(&u32::try_from(ticks & 0xFFFF_FFFF).unwrap().to_le_bytes());
    let len = u32::try_from(data.len()).unwrap();
    body.extend_from_slice(&len.to_le_bytes());
    body.extend_from_slice(&len.to_le_bytes());
    body.extend_from_slice(data);
    block(6, &body)
}

#[test]
fn pcapng_microsecond_resolution_is_honoured() {
    // No if_tsresol: the default is microseconds.
    let mut f = shb();
    f.extend(idb(147, None));
    f.extend(epb(0, 1_700_000_000_123_456, REQ));
    assert_eq!(packets(&read_all(&f)), vec![(0, 1_700_000_000_123_456_000, REQ.to_vec())]);
    // if_tsresol 6 said explicitly, and 2^-20 (binary).
    let mut f = shb();
    f.extend(idb(147, Some(6)));
    f.extend(idb(147, Some(0x80 | 0x14)));
    f.extend(epb(0, 2_000_001, REQ));
    f.extend(epb(1, 3 << 20, RESP));
    assert_eq!(packets(&read_all(&f)), vec![(0, 2_000_001_000, REQ.to_vec()), (1, 3_000_000_000, RESP.to_vec())]);
}

#[test]
fn our_writer_round_trips_with_nanoseconds() {
    let mut w = PcapNgWriter::new(Vec::new()).unwrap();
    w.add_serial_interface("a", "mbtap rtu 9600 8N1 latency_ns=0").unwrap();
    w.add_serial_interface("b", "mbtap rtu 9600 8N1 latency_ns=0").unwrap();
    w.write_packet(0, Timestamp(1_700_000_000_000_000_001), REQ).unwrap();
    w.write_packet(1, Timestamp(1_700_000_000_005_000_002), RESP).unwrap();
    let got = read_all(&w.into_inner());
    assert_eq!(
        packets(&got),
        vec![(0, 1_700_000_000_000_000_001, REQ.to_vec()), (1, 1_700_000_000_005_000_002, RESP.to_vec())]
    );
}

#[test]
fn truncated_file_warns_and_keeps_what_came_before() {
    let mut f = shb();
    f.extend(idb(147, Some(9)));
    f.extend(epb(0, 1000, REQ));
    f.extend(epb(0, 2000, RESP));
    let cut = f.len() - 7;
    let got = read_all(&f[..cut]);
    assert_eq!(packets(&got), vec![(0, 1000, REQ.to_vec())]);
    let w = warnings(&got);
    assert_eq!(w.len(), 1);
    assert!(w[0].contains("ends in the middle of a block"), "{w:?}");
}

#[test]
fn corrupt_block_is_skipped_and_the_rest_replays() {
    let mut f = shb();
    f.extend(idb(147, Some(9)));
    f.extend(epb(0, 1000, REQ));
    let bad_at = f.len();
    f.extend(epb(0, 2000, RESP));
    f[bad_at + 4] = 0xFF; // the block length no longer agrees with its trailer
    f.extend(epb(0, 3000, REQ));
    let got = read_all(&f);
    assert_eq!(packets(&got), vec![(0, 1000, REQ.to_vec()), (0, 3000, REQ.to_vec())]);
    assert!(warnings(&got)[0].contains(&format!("corrupt data at offset {bad_at}")), "{:?}", warnings(&got));
}

#[test]
fn unknown_link_type_is_named_once_and_skipped() {
    let mut f = shb();
    f.extend(idb(1, Some(9)));
    f.extend(idb(147, Some(9)));
    f.extend(epb(0, 1000, b"ethernet"));
    f.extend(epb(0, 1001, b"ethernet"));
    f.extend(epb(1, 1002, REQ));
    let got = read_all(&f);
    assert_eq!(packets(&got), vec![(1, 1002, REQ.to_vec())]);
    let w = warnings(&got);
    assert_eq!(w.len(), 1);
    assert!(w[0].contains("link type 1"), "{w:?}");
}

#[test]
fn zero_length_and_70kb_packets() {
    let big = vec![0xAB; 70_000];
    let got = read_all(&pcap(false, true, 147, &[(1, 0, &[]), (1, 1, &big), (1, 2, REQ)]));
    let p = packets(&got);
    assert_eq!(p.len(), 3);
    assert!(p[0].2.is_empty());
    assert_eq!(p[1].2.len(), 70_000);
}

#[test]
fn backwards_timestamps_are_reported_and_held() {
    let got = read_all(&pcap(false, true, 147, &[(10, 0, REQ), (9, 0, RESP), (11, 0, REQ)]));
    assert_eq!(
        packets(&got),
        vec![(0, 10_000_000_000, REQ.to_vec()), (0, 10_000_000_000, RESP.to_vec()), (0, 11_000_000_000, REQ.to_vec())]
    );
    assert!(warnings(&got)[0].contains("goes backwards by 1000000 µs"), "{:?}", warnings(&got));
}

#[test]
fn not_a_capture_is_an_error() {
    let mut r = CaptureReader::new(&b"hello world, not a capture"[..]);
    let e = r.next_item().unwrap_err().to_string();
    assert!(e.contains("not a pcap or pcapng file"), "{e}");
}

#[test]
fn corrupt_pcap_record_is_skipped() {
    let mut f = pcap(false, false, 147, &[(5, 0, REQ)]);
    let bad_at = f.len();
    f.extend_from_slice(&[5, 0, 0, 0, 1, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0xFF, 0xFF, 0x7F]);
    f.extend(pcap(false, false, 147, &[(6, 0, RESP)])[24..].iter().copied());
    let got = read_all(&f);
    assert_eq!(packets(&got), vec![(0, 5_000_000_000, REQ.to_vec()), (0, 6_000_000_000, RESP.to_vec())]);
    assert!(warnings(&got)[0].contains(&format!("offset {bad_at}")), "{:?}", warnings(&got));
}

/// 200 000 packets naming an undescribed interface give one warning, then one count at the end (not
/// 200 000 identical warnings).
#[test]
fn packets_of_an_undescribed_interface_are_said_once_then_counted() {
    let mut f = shb();
    f.extend(idb(147, Some(9)));
    for t in 0..1000 {
        f.extend(epb(5, t, REQ));
    }
    f.extend(epb(0, 2000, REQ));
    let got = read_all(&f);
    assert_eq!(packets(&got), vec![(0, 2000, REQ.to_vec())]);
    let w = warnings(&got);
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(w[0].contains("names interface 5, which was never described"), "{w:?}");
    assert!(w[1].contains("1000 packets named interfaces never described"), "{w:?}");
}

/// One corrupt region longer than the read buffer (1 MiB) is one warning with where it began and
/// how much was skipped, not a "still searching" line per buffer (2 048 for 2 GB).
#[test]
fn one_corrupt_region_is_one_warning_however_long() {
    let mut f = shb();
    f.extend(idb(147, Some(9)));
    f.extend(epb(0, 1000, REQ));
    let bad_at = f.len();
    // 5 MB that is no block: every 4-byte word 0xFFFFFFFF (never a valid block length).
    f.extend(std::iter::repeat_n(0xFF, 5_000_000));
    f.extend(epb(0, 3000, RESP));
    let got = read_all(&f);
    assert_eq!(packets(&got), vec![(0, 1000, REQ.to_vec()), (0, 3000, RESP.to_vec())]);
    let w = warnings(&got);
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains(&format!("corrupt data at offset {bad_at}")) && w[0].contains("skipped 5000000 bytes"),
        "{w:?}"
    );
}
