//! Sources at the edge: live serial ports (tokio-serial) and the host clock. Everything here
//! produces [`Chunk`](mbtap_core::chunk::Chunk)s for the pure core.

pub mod serial;
