//! Pieces the end-to-end benches share: the tests' helpers (a child killed at the end, a
//! bridge started and its addresses, metrics), percentiles, a blocking Modbus TCP request.
#![allow(dead_code, clippy::unwrap_used, clippy::cast_precision_loss)]
#![allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // percentile indexes of short vectors

use std::io::{Read, Write};
use std::net::TcpStream;

// The tests' helpers (a killed-on-drop child, starting a bridge, reading its metrics), shared
// rather than written again.
#[path = "../../tests/common/mod.rs"]
mod common;
#[allow(unused_imports)] // each bench uses some of them
pub use common::{Kill, bridge, counter, simulate, spy_replay};

/// The `p` quantile (0..=1) of `v` (sorted in place).
pub fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * p).round() as usize;
    v[i]
}

/// One Modbus TCP request (MBAP header, Modbus Messaging on TCP/IP v1.0b §3.1.3) to `unit`;
/// the answer's PDU.
pub fn call(s: &mut TcpStream, tid: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = vec![0u8; 7];
    f[..2].copy_from_slice(&tid.to_be_bytes());
    f[4..6].copy_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    f[6] = unit;
    f.extend_from_slice(pdu);
    s.write_all(&f).unwrap();
    let mut head = [0u8; 7];
    s.read_exact(&mut head).unwrap();
    assert_eq!(head[..2], tid.to_be_bytes());
    let mut answer = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
    s.read_exact(&mut answer).unwrap();
    answer
}
