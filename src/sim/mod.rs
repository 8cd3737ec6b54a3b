//! Simulated slaves for the virtual bus: devices that answer requests the way their profile
//! (and the document behind it) says. Pure like the rest of the core: a request PDU in, a
//! response PDU (or silence) out; pacing, the pseudo-terminal and value movement sit at the edge.

pub mod slave;

pub use slave::Slave;
