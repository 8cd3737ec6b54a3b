//! Captures: reading pcap/pcapng line captures (link type 147, one packet per received chunk)
//! and writing them, with the timing kept; and the Wireshark export.
//!
//! Modules: `format` (zero-copy parsers of pcap and pcapng blocks), `reader` (a capture as a stream
//! of chunks, memory bounded by the largest block), `clock` (one interface's times made safe for
//! the framer), `writer` (pcapng out, line settings in each interface).

pub mod clock;
pub mod export;
pub mod format;
pub mod reader;
pub mod writer;

pub use reader::{CaptureError, CaptureReader, Item};
pub use writer::PcapNgWriter;

/// LINKTYPE_USER0: raw serial bytes, as mbtap and other open sniffers write them.
pub const LINKTYPE_USER0: u32 = 147;
/// LINKTYPE_WIRESHARK_UPPER_PDU: PDUs tagged with the dissector that decodes them.
pub const LINKTYPE_WIRESHARK_UPPER_PDU: u32 = 252;
