//! Sources at the edge: live serial ports (tokio-serial), pseudo-terminals and the host clock —
//! the I/O loops of `sniff`, `tap`, `scan`, `play`, `simulate` and `demo`. Everything here
//! produces [`Chunk`](mbtap_analysis::chunk::Chunk)s for the pure core (or, for `play` and
//! `simulate`, writes bytes a peer reads).

pub mod demo;
pub mod emulate_from;
pub mod emulated;
pub mod image_file;
pub mod link;
pub mod listen;
pub mod pace;
pub mod play;
pub mod pty;
pub mod record;
pub mod rs485;
pub mod scan;
pub mod serial;
pub mod session;
pub mod simulate;
pub mod sniff;
pub mod stream;
pub mod tap;
