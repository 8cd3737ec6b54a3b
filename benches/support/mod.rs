//! Pieces the end-to-end benches share: the tests' helpers (a child killed at the end, a
//! bridge started and its addresses, metrics, a blocking Modbus TCP request) and percentiles.
#![allow(dead_code, clippy::unwrap_used, clippy::cast_precision_loss)]
#![allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // percentile indexes of short vectors

// The tests' helpers (a killed-on-drop child, starting a bridge, reading its metrics), shared
// rather than written again.
#[path = "../../tests/common/mod.rs"]
mod common;
#[allow(unused_imports)] // each bench uses some of them
pub use common::{Kill, bridge, call, counter, simulate, spy_replay};

/// The `p` quantile (0..=1) of `v` (sorted in place).
pub fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * p).round() as usize;
    v[i]
}
