//! Writing line captures: pcapng, link type 147 (LINKTYPE_USER0), nanosecond timestamps
//! (if_tsresol = 9), one packet per received chunk, the line settings in each interface's
//! description so a replay picks them up. Flushed on request (the recorder flushes at least
//! once a second, so a killed process loses at most the last second).

use std::io::{self, Write};

use super::LINKTYPE_USER0;
use super::format::{BYTE_ORDER_MAGIC, EPB, IDB, IF_DESCRIPTION, IF_NAME, IF_TSRESOL, ISB, OPT_COMMENT, OPT_END, SHB};
use crate::chunk::Timestamp;

/// A pcapng writer for raw serial chunks.
#[derive(Debug)]
pub struct PcapNgWriter<W: Write> {
    out: W,
    interfaces: u32,
    block: Vec<u8>,
}

fn push_option(b: &mut Vec<u8>, code: u16, value: &[u8]) {
    b.extend_from_slice(&code.to_le_bytes());
    b.extend_from_slice(&u16::try_from(value.len()).unwrap_or(u16::MAX).to_le_bytes());
    b.extend_from_slice(&value[..value.len().min(usize::from(u16::MAX))]);
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
}

impl<W: Write> PcapNgWriter<W> {
    /// Starts a file: writes the section header.
    ///
    /// # Errors
    /// I/O errors.
    pub fn new(mut out: W) -> io::Result<Self> {
        let mut b = Vec::with_capacity(64);
        b.extend_from_slice(&BYTE_ORDER_MAGIC.to_le_bytes());
        b.extend_from_slice(&1u16.to_le_bytes()); // major version
        b.extend_from_slice(&0u16.to_le_bytes()); // minor version
        b.extend_from_slice(&(-1i64).to_le_bytes()); // section length: unknown
        push_option(&mut b, 4, b"mbtap"); // shb_userappl
        push_option(&mut b, OPT_END, &[]);
        write_block(&mut out, SHB, &b)?;
        Ok(Self { out, interfaces: 0, block: Vec::with_capacity(512) })
    }

    /// Describes the next interface (port); returns its id. `description` should carry the
    /// line settings, e.g. `mbtap rtu 19200 8E1 latency_ns=0`.
    ///
    /// # Errors
    /// I/O errors.
    pub fn add_interface(&mut self, linktype: u16, name: &str, description: &str) -> io::Result<u32> {
        let mut b = Vec::with_capacity(128);
        b.extend_from_slice(&linktype.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes()); // snaplen: no limit
        push_option(&mut b, IF_NAME, name.as_bytes());
        push_option(&mut b, IF_DESCRIPTION, description.as_bytes());
        push_option(&mut b, IF_TSRESOL, &[9]);
        push_option(&mut b, OPT_END, &[]);
        write_block(&mut self.out, IDB, &b)?;
        self.interfaces += 1;
        Ok(self.interfaces - 1)
    }

    /// A serial-capture interface (link type 147).
    ///
    /// # Errors
    /// I/O errors.
    pub fn add_serial_interface(&mut self, name: &str, description: &str) -> io::Result<u32> {
        self.add_interface(u16::try_from(LINKTYPE_USER0).unwrap_or(147), name, description)
    }

    /// Writes one packet.
    ///
    /// # Errors
    /// I/O errors.
    pub fn write_packet(&mut self, interface: u32, t: Timestamp, data: &[u8]) -> io::Result<()> {
        let b = &mut self.block;
        b.clear();
        b.extend_from_slice(&interface.to_le_bytes());
        b.extend_from_slice(&u32::try_from(t.0 >> 32).unwrap_or(0).to_le_bytes());
        b.extend_from_slice(&u32::try_from(t.0 & 0xFFFF_FFFF).unwrap_or(0).to_le_bytes());
        let len = u32::try_from(data.len()).unwrap_or(u32::MAX);
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(data);
        while !b.len().is_multiple_of(4) {
            b.push(0);
        }
        write_block(&mut self.out, EPB, b)
    }

    /// Writes an interface statistics block for `interface` at time `t` carrying `comment`
    /// (mbtap's `mbtap observer latency_ns=…`: what the framer learned about the port's reads,
    /// known only at the end; Wireshark shows it among the capture file's properties).
    ///
    /// # Errors
    /// I/O errors.
    pub fn write_statistics_comment(&mut self, interface: u32, t: Timestamp, comment: &str) -> io::Result<()> {
        let mut b = Vec::with_capacity(32 + comment.len());
        b.extend_from_slice(&interface.to_le_bytes());
        b.extend_from_slice(&u32::try_from(t.0 >> 32).unwrap_or(0).to_le_bytes());
        b.extend_from_slice(&u32::try_from(t.0 & 0xFFFF_FFFF).unwrap_or(0).to_le_bytes());
        push_option(&mut b, OPT_COMMENT, comment.as_bytes());
        push_option(&mut b, OPT_END, &[]);
        write_block(&mut self.out, ISB, &b)
    }

    /// Flushes buffered output.
    ///
    /// # Errors
    /// I/O errors.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// The underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}

fn write_block<W: Write>(out: &mut W, block_type: u32, body: &[u8]) -> io::Result<()> {
    let len =
        u32::try_from(body.len() + 12).map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "block too large"))?;
    out.write_all(&block_type.to_le_bytes())?;
    out.write_all(&len.to_le_bytes())?;
    out.write_all(body)?;
    out.write_all(&len.to_le_bytes())
}
