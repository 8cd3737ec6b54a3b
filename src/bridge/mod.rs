//! The bridge's I/O shells: Modbus TCP clients (or raw RTU over TCP, or UDP) reaching devices
//! on serial lines. Every decision — admission, queueing, caching, breakers, timeouts, the
//! serial transaction — is the gateway core's (`mbtap_gateway`); these files touch the world.
//!
//! [`line`] (the serial master: drives the core's transaction machine), [`port`] (the serial
//! port and its settings, reopened when lost),
//! [`shared`] (what the line and the connections share: queue, cache, pending writes),
//! [`server`] (the TCP listeners: accepting, limits, eviction), [`watched`] (a socket noting when
//! it last brought bytes in, for eviction), [`connection`] (one TCP client,
//! on its own), [`request`] (each request through admission, cache and queue), [`udp`] (Modbus
//! UDP clients), [`emulated`] (devices emulated in this process in place of a line),
//! [`tls`] (Modbus/TCP Security), [`metrics`] (Prometheus text, and the web view's figures),
//! [`web`] (`--web`: the live page and `/api/state`), [`client_book`] (who asks, for the web
//! view), [`serial_front`] (a serial
//! port on which the bridge is the slave: `--listen-serial`, and reverse mode with a `tcp://`
//! line behind it), [`slave_port`] (that port's request framing and answers), [`device`] (a
//! Modbus TCP device as a line's back), [`run`] (starts them all), [`config`] (the
//! configuration file), [`modes`] (the command line's enums), [`broker`] (writes from the MQTT
//! broker through the same admission); the audit of writes is `crate::output::audit`.

pub mod broker;
pub mod client_book;
pub mod config;
pub mod connection;
pub mod device;
pub mod emulated;
pub mod line;
pub mod metrics;
pub mod modes;
pub mod port;
pub mod request;
pub mod run;
pub mod serial_front;
pub mod server;
pub mod shared;
pub mod slave_port;
pub mod tls;
pub mod udp;
pub mod watched;
pub mod web;
