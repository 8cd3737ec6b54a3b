//! Simulated slaves for the virtual bus: devices that answer requests the way their profile
//! (and the document behind it) says. Pure like the rest of the core: a request PDU in, a
//! response PDU (or silence) out, time an input; the pseudo-terminal sits at the edge
//! (`simulate_cmd`).

pub mod ascii_requests;
pub mod bus;
pub mod rtu_requests;
pub mod slave;
pub mod uart;
pub mod world;

pub use ascii_requests::AsciiRequestAssembler;
pub use rtu_requests::{RequestAssembler, RequestFrame};
pub use slave::Slave;
