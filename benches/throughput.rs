//! Throughput of the protocol core: CRC-16 (bytes/s) and frame parsing (frames/s).
//! Run: `cargo bench --bench throughput`. Figures go to BENCHMARKS.md with the machine.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use divan::counter::{BytesCount, ItemsCount};
use divan::{Bencher, black_box};
use mbtap_proto::{DirectionHint, checksum, decode_pdu, parse_request, parse_response, parse_rtu};

fn main() {
    divan::main();
}

/// A pseudo-random buffer, the same every run.
fn buffer(len: usize) -> Vec<u8> {
    let mut x: u32 = 0x1234_5678;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x.to_le_bytes()[0]
        })
        .collect()
}

#[divan::bench(args = [8, 256, 65536])]
fn crc16_table(bencher: Bencher, len: usize) {
    let data = buffer(len);
    bencher.counter(BytesCount::new(len)).bench(|| checksum::crc16(black_box(&data)));
}

#[divan::bench(args = [256, 65536])]
fn crc16_bitwise_reference(bencher: Bencher, len: usize) {
    let data = buffer(len);
    bencher.counter(BytesCount::new(len)).bench(|| checksum::crc16_bitwise(black_box(&data)));
}

/// 1 024 RTU read requests (8 bytes each), as a sniffer sees on a polled bus.
const FRAMES: usize = 1024;

fn frames(wire: &[u8]) -> Vec<Vec<u8>> {
    (0..FRAMES)
        .map(|i| {
            let mut pdu = wire.to_vec();
            // Vary the address so the CRC differs frame to frame.
            pdu[3] = u8::try_from(i % 256).unwrap_or(0);
            let mut out = Vec::new();
            mbtap_proto::encode_rtu(1, &pdu[1..], &mut out);
            out
        })
        .collect()
}

/// Unit 1, 03 Read Holding Registers, address 0x00xx, quantity 3 (the CRC is recomputed).
const READ_REQUEST: &[u8] = &[0x01, 0x03, 0x00, 0x00, 0x00, 0x03];
/// Unit 1, 03 response, 3 registers.
const READ_RESPONSE: &[u8] = &[0x01, 0x03, 0x06, 0x00, 0x00, 0x00, 0x00, 0x01, 0x90];

#[divan::bench]
fn parse_rtu_read_request(bencher: Bencher) {
    let fs = frames(READ_REQUEST);
    bencher.counter(ItemsCount::new(FRAMES)).bench(|| {
        let mut ok = 0usize;
        for f in &fs {
            let frame = parse_rtu(black_box(f)).ok();
            if let Some(frame) = frame
                && frame.check_ok()
                && parse_request(frame.pdu).is_ok()
            {
                ok += 1;
            }
        }
        ok
    });
}

#[divan::bench]
fn parse_rtu_read_response(bencher: Bencher) {
    let fs = frames(READ_RESPONSE);
    bencher.counter(ItemsCount::new(FRAMES)).bench(|| {
        let mut ok = 0usize;
        for f in &fs {
            if let Ok(frame) = parse_rtu(black_box(f))
                && frame.check_ok()
                && parse_response(frame.pdu).is_ok()
            {
                ok += 1;
            }
        }
        ok
    });
}

/// Direction unknown: both readings plus findings, as `decode` does.
#[divan::bench]
fn decode_rtu_unknown_direction(bencher: Bencher) {
    let fs = frames(READ_REQUEST);
    bencher.counter(ItemsCount::new(FRAMES)).bench(|| {
        let mut n = 0usize;
        for f in &fs {
            if let Ok(frame) = parse_rtu(black_box(f)) {
                n += usize::from(matches!(
                    decode_pdu(frame.pdu, DirectionHint::Unknown),
                    mbtap_proto::PduDecode::One(_)
                ));
            }
        }
        n
    });
}

/// What `bytes` would save the bridge: the one copy of a request PDU (at most 253 bytes, MAP
/// v1.1b3 §4.1) out of the connection's read buffer into the job that crosses to the line's task.
#[divan::bench(args = [5, 253])]
fn pdu_copy_to_owned(bencher: Bencher, len: usize) {
    let data = buffer(len);
    bencher.counter(ItemsCount::new(1usize)).bench(|| black_box(&data[..]).to_vec());
}
