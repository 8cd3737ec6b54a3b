//! The ports and transports every command reaches a line or a peer through, and the clock they
//! are timed by — apart from what analyses the bytes (`source`), bridges them (`bridge`) or asks
//! devices (`master`):
//! - [`serial`] — live serial ports opened with line settings, the adapter's latency timer, the
//!   host clock that stamps each read;
//! - [`rs485`] — direction control (the kernel's RS-485 mode, or RTS around each frame);
//! - [`stream`] — what a line is reached through: a serial port, a serial server's raw TCP
//!   stream, RFC 2217, or (for the bridge) a Modbus TCP device;
//! - [`pty`] and [`link`] — the pseudo-terminal offered to an application and the path it opens;
//! - [`listen`] — listening addresses as users type them;
//! - [`pace`] — waiting for a moment more finely than the runtime's 1 ms timer;
//! - [`signals`] — Ctrl-C, SIGTERM and the UI's `q`: one stop for every loop.

pub mod link;
pub mod listen;
pub mod pace;
pub mod pty;
pub mod rs485;
pub mod serial;
pub mod signals;
pub mod stream;
