//! Sources at the edge: live serial ports (tokio-serial) and the host clock. Everything here
//! produces [`Chunk`](crate::chunk::Chunk)s for the pure core.

pub mod serial;
