//! The synthetic traffic generator with ground truth, the observation models of real serial
//! hardware, and scoring against the truth. Deterministic for a seed; used by tests, benchmarks
//! and the accuracy report in BENCHMARKS.md.
//!
//! Modules: `rng` (a deterministic PRNG), `generate` (traffic with ground truth and real line
//! physics), `observe` (how serial hardware delivers it), `capture` (written as a line capture),
//! `score` (a framer scored against the truth, and the gap-cutting baseline).

pub mod capture;
pub mod generate;
pub mod observe;
pub mod rng;
pub mod score;

pub use generate::{TrafficConfig, Truth, TruthKind, Wire, generate};
pub use observe::{Observation, observe};
pub use score::{Decided, Score, run_framer, run_gap_cutter, score};
