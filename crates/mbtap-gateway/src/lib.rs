//! The gateway core: every decision the bridge makes, without sockets, serial ports or a clock.
//!
//! Time is an input ([`std::time::Duration`] since an origin the caller picks: the I/O shell's
//! start, or zero in a test's virtual clock) and bytes are inputs; what to do is the output.
//! The bridge in the binary (`src/bridge/`) keeps only what touches the world: listeners and
//! TLS, the serial port, timers and the metrics export.
//!
//! - [`parse`]: option values (routes, units, function codes, unit maps), each error naming the
//!   value.
//! - [`answer`]: the one answer check every back puts each answer through.
//! - [`admit`]: may this client do this — allow-lists, read-only, roles, broadcast rules, rate
//!   limit, routes — a route or a typed [`admit::Refusal`].
//! - [`clients`]: the queue id of every asker, handed out here.
//! - [`queue`]: the fair per-client queue with a priority class and coalescing of twins.
//! - [`cache`]: answers from memory and the polling plan (agent mode).
//! - [`line`]: what one line decides around each request, whatever its back (a serial line, a
//!   Modbus TCP device, emulated devices): breaker, cache fill, quiet time, each unit's gap
//!   (`--unit-gap`), line-time class.
//! - [`breaker`]: a dead unit answered at once between probes; [`timeouts`]: how long to wait
//!   for each unit.
//! - [`transaction`]: one serial request with its echo, answer, retries and late answers, as a
//!   state machine fed bytes and time.
//! - [`lifetime`]: whether a request's asker still waits for it, and what its answer becomes
//!   (delivered or withheld): one rule for clients with ids (MBAP) and without (RTU framing).
//! - [`seats`]: which open connection gives up its seat to a newcomer.
//! - [`rules`]: the read-only allow-list and the exceptions the gateway answers with.
//! - [`audit`]: what a request changes (the audit of writes records it) and its ending in words.
//! - [`tcp_device`]: a Modbus TCP device as a line's back — its transaction ids and framing.
//! - [`fuzzing`]: the fuzz targets' bodies.
//!
//! Specs: MODBUS Application Protocol v1.1b3 (MAP), MODBUS over Serial Line v1.02, MODBUS
//! Messaging on TCP/IP v1.0b, MODBUS/TCP Security.

pub mod admit;
pub mod answer;
pub mod audit;
pub mod breaker;
pub mod cache;
pub mod clients;
pub mod fuzzing;
pub mod lifetime;
pub mod line;
pub mod parse;
pub mod queue;
pub mod rules;
pub mod seats;
pub mod tcp_device;
pub mod timeouts;
pub mod transaction;

/// An option value the gateway cannot take. The message names the option, the value as given
/// and what is expected instead.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BadValue(pub String);
