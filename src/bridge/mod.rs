//! The bridge: Modbus TCP clients (or raw RTU over TCP) reaching devices on serial lines.
//!
//! Pure parts: [`queue`] (fair per-client queues), [`timing`] (per-unit timeouts, fixed or
//! learnt) and `mbtap_core::proto::answer_end` (where a slave's answer ends). At the edge: [`line`] (the serial master, one transaction at a time, reopening a
//! lost port), [`server`] (the TCP side, each connection on its own), [`metrics`] (Prometheus
//! text); [`udp`] (Modbus UDP clients, through the same checks as TCP's); [`reverse`] (an RTU slave on the serial side, a Modbus TCP client behind).

pub mod cache;
pub mod config;
pub mod line;
pub mod metrics;
pub mod parse;
pub mod queue;
pub mod reverse;
pub mod rules;
pub mod run;
pub mod server;
pub mod timing;
pub mod tls;
pub mod udp;
