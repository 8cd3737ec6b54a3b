//! mbtap — a Modbus RTU/ASCII bus analyzer and TCP bridge.
//!
//! Module map (dependencies point down, never up):
//! - [`proto`] — the pure protocol core: frames and PDUs of every function code, parse and encode.
//! - [`report`] — rendering decoded frames and transactions as text and JSON lines.
//! - [`decode_cmd`] — the `mbtap decode` command: frames given by a user, explained.
//! - [`hexinput`] — reading the hex and ASCII frames users paste.

pub mod analyzer;
pub mod capture;
pub mod chunk;
pub mod cli;
pub mod decode_cmd;
pub mod framer;
pub mod fuzzing;
pub mod generate_cmd;
pub mod hexinput;
pub mod line_args;
pub mod pairing;
pub mod play_cmd;
pub mod profile;
pub mod proto;
pub mod replay_cmd;
pub mod report;
pub mod sniff_cmd;
pub mod source;
pub mod tap_cmd;
pub mod traffic;
