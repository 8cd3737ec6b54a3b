//! The command line's faces of the gateway core's modes: `--echo` and `--timeout` as clap
//! value enums (the pure core names no argument parser), each turned into the core's own.

use mbtap_gateway::timeouts::TimeoutMode;
use mbtap_gateway::transaction::EchoMode;

/// `--echo`: whether the adapter hears its own transmission.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum EchoArg {
    /// Detect it from the first request whose answer cannot look like the request itself
    /// (not 05, 06 or 08, whose normal answers echo the request).
    #[default]
    Auto,
    /// The adapter echoes: consume exactly the frame sent before reading the answer; a
    /// difference is a collision (another driver on the line).
    On,
    /// No echo.
    Off,
}

impl From<EchoArg> for EchoMode {
    fn from(a: EchoArg) -> Self {
        match a {
            EchoArg::Auto => Self::Auto,
            EchoArg::On => Self::On,
            EchoArg::Off => Self::Off,
        }
    }
}

/// `--timeout`: how response timeouts are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum TimeoutArg {
    /// `--timeout-ms` for every unit (and `--unit-timeout` where given).
    #[default]
    Fixed,
    /// Learnt per unit from its answers: 3 × its slowest of the last 32 + 10 ms, within 20 ms
    /// and `--timeout-ms`; doubled after each timeout.
    Auto,
}

impl From<TimeoutArg> for TimeoutMode {
    fn from(a: TimeoutArg) -> Self {
        match a {
            TimeoutArg::Fixed => Self::Fixed,
            TimeoutArg::Auto => Self::Auto,
        }
    }
}
