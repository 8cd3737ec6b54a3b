//! Reading line captures (pcap or pcapng, link type 147) as a stream of chunks, with memory
//! bounded by the largest block, whatever the file's length.
//!
//! Bad input never stops a replay early if anything after it can be read: a corrupt block is
//! reported with its offset and skipped by searching for the next plausible block; a
//! truncated file ends with a warning; packets of other link types are skipped with one
//! warning per interface; timestamps that go backwards or jump are reported, and the times
//! handed on never run backwards (see [`super::clock`]).
//!
//! Its `blocks` module holds the two formats' blocks as the reader walks them.

use std::io::{self, Read};

use nom::number::Endianness;
use thiserror::Error;

use super::LINKTYPE_USER0;
use super::clock::{Clock, StampOrder};
use super::format::{
    EPB, FileKind, FormatError, IDB, Interface, MAX_BLOCK, SHB, SPB, Step, parse_block, parse_file_kind,
    parse_pcap_record,
};
use crate::chunk::{PortId, Timestamp};

mod blocks;

/// Errors that end reading.
#[derive(Debug, Error)]
pub enum CaptureError {
    // Transparent: the caller says what it was doing ("reading the capture"); the cause is said
    // once, not again as this error's source.
    #[error(transparent)]
    Io(#[from] io::Error),
    #[error(transparent)]
    Format(#[from] FormatError),
    /// Every interface had a link type that is not raw serial bytes: nothing could be read.
    #[error(
        "no interface holds raw serial bytes: link type {linktype} is not one mbtap reads (147–162, LINKTYPE_USER0–15, as serial sniffers write them); if its packets are raw serial bytes, say so with --link-type {linktype}"
    )]
    UnknownLinkType { linktype: u16 },
    /// Fewer bytes than any capture's header: an empty file, or a recording that never began.
    #[error("the file holds {0} byte(s), less than a pcap or pcapng header: it is empty, nothing was recorded")]
    TooShort(usize),
}

/// One thing read from a capture.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Item<'a> {
    /// A received chunk.
    Packet { port: PortId, t: Timestamp, data: &'a [u8] },
    /// An interface (port) was described; its description may carry line settings.
    /// Boxed, so that an item (one per packet) stays small to move.
    Interface { port: PortId, interface: Box<Interface> },
    /// Something was wrong; reading goes on.
    Warning(String),
}

const READ_SIZE: usize = 1 << 20;
/// The most of one packet handed on: a serial read is never this long (a USB adapter's is 62
/// bytes, a UART FIFO's 14; a gap-cutting sniffer's one frame, 256). Longer ones are cut, and
/// said — the framer's memory per byte must not follow a hostile file.
pub const MAX_SERIAL_READ: usize = 256 * 1024;
/// Interfaces kept (port ids are one byte); more are said once and their packets skipped.
const MAX_INTERFACES: usize = 256;
/// An interface's name and description kept (line settings fit in a fraction of it).
const MAX_DESCRIPTION: usize = 1024;
/// Backwards-timestamp warnings shown before they are only counted.
const MAX_TIME_WARNINGS: u32 = 5;

/// A streaming capture reader.
#[derive(Debug)]
pub struct CaptureReader<R> {
    src: R,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    eof: bool,
    /// File offset of `buf[start]`.
    offset: u64,
    kind: Option<FileKind>,
    endian: Endianness,
    interfaces: Vec<Interface>,
    warned_linktype: Vec<bool>,
    /// A link type to read as raw serial bytes besides 147–162.
    extra_linktype: Option<u16>,
    /// Interfaces described beyond [`MAX_INTERFACES`].
    dropped_interfaces: u64,
    /// Packets cut to [`MAX_SERIAL_READ`], and the warning about the last one, said next.
    cut_packets: u64,
    queued_warning: Option<String>,
    /// Packets delivered, and the first link type skipped (for the verdict at the end).
    pub packets: u64,
    pub skipped_linktype: Option<u16>,
    /// What the recording session learned about each interface's reads (`mbtap observer
    /// latency_ns=…` in an interface statistics block's comment): (interface, latency ns).
    pub recorded_latency: Vec<(u32, u64)>,
    /// Each interface's clock, and where its last packet ended (to name a bad one).
    clocks: Vec<(Clock, u64)>,
    time_warnings: u32,
    /// A corrupt region being searched through: where it began and what was wrong there.
    corrupt_from: Option<(u64, String)>,
    /// Packets that named an interface never described (the first is said, the rest counted).
    undescribed_packets: u64,
    /// The summary of what was only counted has been said (at the end of the file).
    summarised: bool,
    /// A packet to deliver right after the warning about its timestamp.
    pending_packet: Option<(u32, u64, usize, usize)>,
}

enum Next {
    Packet {
        port: u32,
        t: u64,
        at: usize,
        len: usize,
    },
    /// Boxed: an interface comes once a port, a packet millions of times, and every step moves
    /// the whole enum.
    Interface(u32, Box<Interface>),
    Warning(String),
    Continue,
    End,
}

impl<R: Read> CaptureReader<R> {
    /// Also reads interfaces of link type `linktype` as raw serial bytes (`--link-type`).
    #[must_use]
    pub fn with_link_type(mut self, linktype: Option<u16>) -> Self {
        self.extra_linktype = linktype;
        self
    }

    #[must_use]
    pub fn new(src: R) -> Self {
        Self {
            src,
            buf: vec![0; READ_SIZE],
            start: 0,
            end: 0,
            eof: false,
            offset: 0,
            kind: None,
            endian: Endianness::Little,
            interfaces: Vec::new(),
            warned_linktype: Vec::new(),
            extra_linktype: None,
            dropped_interfaces: 0,
            cut_packets: 0,
            queued_warning: None,
            packets: 0,
            skipped_linktype: None,
            recorded_latency: Vec::new(),
            clocks: Vec::new(),
            time_warnings: 0,
            pending_packet: None,
            corrupt_from: None,
            undescribed_packets: 0,
            summarised: false,
        }
    }

    /// Makes at least `n` bytes available from `start`, unless the file ends first.
    fn fill(&mut self, n: usize) -> io::Result<()> {
        if self.end - self.start >= n || self.eof {
            return Ok(());
        }
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        if self.buf.len() < n {
            self.buf.resize(n.max(READ_SIZE), 0);
        }
        while self.end < n && !self.eof {
            let got = self.src.read(&mut self.buf[self.end..])?;
            if got == 0 {
                self.eof = true;
            }
            self.end += got;
        }
        Ok(())
    }

    fn consume(&mut self, n: usize) {
        self.start += n;
        self.offset += n as u64;
    }

    /// The next item, `None` at the end of the file.
    ///
    /// # Errors
    /// I/O errors, and a file that is neither pcap nor pcapng.
    pub fn next_item(&mut self) -> Result<Option<Item<'_>>, CaptureError> {
        loop {
            match self.step()? {
                Next::Packet { port, t, at, len } => {
                    return Ok(Some(Item::Packet {
                        port: PortId(u8::try_from(port).unwrap_or(u8::MAX)),
                        t: Timestamp(t),
                        data: &self.buf[at..at + len],
                    }));
                }
                Next::Interface(id, interface) => {
                    return Ok(Some(Item::Interface { port: PortId(u8::try_from(id).unwrap_or(u8::MAX)), interface }));
                }
                Next::Warning(w) => return Ok(Some(Item::Warning(w))),
                Next::Continue => {}
                Next::End => return Ok(None),
            }
        }
    }

    fn step(&mut self) -> Result<Next, CaptureError> {
        if let Some((port, t, at, len)) = self.pending_packet.take() {
            return Ok(Next::Packet { port, t, at, len });
        }
        if let Some(w) = self.queued_warning.take() {
            return Ok(Next::Warning(w));
        }
        let Some(kind) = self.kind else {
            self.fill(24)?;
            return match parse_file_kind(&self.buf[self.start..self.end])? {
                Step::Item(k, used) => {
                    self.kind = Some(k);
                    if let FileKind::Pcap { endian, linktype, .. } = k {
                        self.endian = endian;
                        self.consume(used);
                        let iface = Interface {
                            linktype: u16::try_from(linktype).unwrap_or(0),
                            ticks_per_sec: 0,
                            name: None,
                            description: None,
                        };
                        return Ok(self.add_interface(iface));
                    }
                    Ok(Next::Continue)
                }
                Step::NeedMore(_) => Err(CaptureError::TooShort(self.end - self.start)),
            };
        };
        let avail = self.end - self.start;
        if avail == 0 {
            self.fill(1)?;
            if self.end == self.start {
                return Ok(self.end_summary().map_or(Next::End, Next::Warning));
            }
        }
        let parsed = match kind {
            FileKind::Pcap { endian, nanos, .. } => self.pcap_step(endian, nanos),
            FileKind::PcapNg => self.pcapng_step(),
        };
        match parsed {
            Ok(n) => Ok(n),
            Err(e) => Ok(self.resync(&e)),
        }
    }

    fn need(&mut self, n: usize) -> Result<bool, CaptureError> {
        self.fill(n)?;
        Ok(self.end - self.start >= n)
    }

    /// The block or record here claims more bytes than the file has left. Either the file was
    /// cut short, or its length field is damaged (one flipped bit claims a megabyte): when a
    /// readable block or record follows, it was the length — skip to that one and read on.
    fn truncated(&mut self) -> Next {
        let left = self.end - self.start;
        let at = self.offset;
        let window = &self.buf[self.start..self.end];
        if let Some(skip) = (1..window.len()).find(|&i| self.plausible_at(&window[i..])) {
            self.consume(skip);
            return Next::Warning(format!(
                "the block at offset {at} claims more bytes than the file holds (a damaged length): skipped {skip} bytes to the next readable one at offset {}",
                at + skip as u64
            ));
        }
        self.consume(left);
        Next::Warning(format!(
            "the file ends in the middle of a block at offset {at}: its last {left} bytes are ignored"
        ))
    }

    fn packet(&mut self, interface: u32, t: u64, at: usize, len: usize) -> Next {
        let i = interface as usize;
        let Some(iface) = self.interfaces.get(i) else { return Next::Continue };
        // The user DLTs 147–162 (LINKTYPE_USER0–15): serial sniffers write raw bytes under any
        // of them.
        let raw = (LINKTYPE_USER0..=LINKTYPE_USER0 + 15).contains(&u32::from(iface.linktype))
            || self.extra_linktype == Some(iface.linktype);
        if !raw {
            self.skipped_linktype.get_or_insert(iface.linktype);
            if !self.warned_linktype[i] {
                self.warned_linktype[i] = true;
                return Next::Warning(format!(
                    "interface {i} has link type {}, not raw serial bytes (147–162, LINKTYPE_USER0–15): its packets are skipped (--link-type {} reads them as raw serial bytes)",
                    iface.linktype, iface.linktype
                ));
            }
            return Next::Continue;
        }
        self.packets += 1;
        let len = if len > MAX_SERIAL_READ {
            self.cut_packets += 1;
            if self.cut_packets <= 3 {
                self.queued_warning = Some(format!(
                    "the packet before offset {} holds {len} bytes; no serial read is that long: only its first {MAX_SERIAL_READ} were read{}",
                    self.offset,
                    if self.cut_packets == 3 { " (further ones are only cut)" } else { "" }
                ));
            }
            MAX_SERIAL_READ
        } else {
            len
        };
        let (clock, bad_before) = &mut self.clocks[i];
        let (t, verdict) = clock.stamp(t);
        let prev_end = std::mem::replace(bad_before, self.offset);
        let w = match verdict {
            StampOrder::InOrder => None,
            StampOrder::Backwards { by_ns } => Some(format!(
                "timestamp goes backwards by {} µs at offset {} (interface {i}); held at the previous value, later packets keep their own spacing",
                by_ns / 1000,
                self.offset
            )),
            StampOrder::LoneJump { off_ns, ahead } => Some(format!(
                "the timestamp of the packet before offset {prev_end} (interface {i}) is {}.{:03} s {} both neighbours: a lone bad timestamp, the packets after it are timed from its neighbours",
                off_ns / 1_000_000_000,
                off_ns / 1_000_000 % 1000,
                if ahead { "ahead of" } else { "behind" }
            )),
        };
        if let Some(w) = w {
            self.time_warnings += 1;
            if self.time_warnings <= MAX_TIME_WARNINGS {
                let more = if self.time_warnings == MAX_TIME_WARNINGS {
                    " (further timestamp problems are only counted)"
                } else {
                    ""
                };
                // The packet itself is still delivered, on the next call.
                self.pending_packet = Some((interface, t, at, len));
                return Next::Warning(format!("{w}{more}"));
            }
        }
        Next::Packet { port: interface, t, at, len }
    }

    /// After a format error: report it and look for the next plausible block or record.
    fn resync(&mut self, e: &FormatError) -> Next {
        // One corrupt region is one warning, however many buffers its search takes.
        let (from, what) = self.corrupt_from.take().unwrap_or_else(|| (self.offset, e.to_string()));
        let window = &self.buf[self.start..self.end];
        let found = (1..window.len()).find(|&i| self.plausible_at(&window[i..]));
        self.consume(found.unwrap_or(window.len()));
        if found.is_none() && !self.eof {
            // Nothing plausible in the buffer: the next fill brings more to search.
            self.corrupt_from = Some((from, what));
            return Next::Continue;
        }
        let skipped = self.offset - from;
        Next::Warning(format!(
            "corrupt data at offset {from} ({what}): skipped {skipped} bytes to the next readable block"
        ))
    }

    /// What was only counted, said once at the end of the file.
    fn end_summary(&mut self) -> Option<String> {
        if let Some((from, what)) = self.corrupt_from.take() {
            let skipped = self.offset - from;
            return Some(format!(
                "corrupt data at offset {from} ({what}): skipped {skipped} bytes, to the end of the file (no readable block after it)"
            ));
        }
        if self.summarised {
            return None;
        }
        self.summarised = true;
        let mut said = Vec::new();
        if self.undescribed_packets > 1 {
            said.push(format!("{} packets named interfaces never described (skipped)", self.undescribed_packets));
        }
        if self.time_warnings > MAX_TIME_WARNINGS {
            said.push(format!("{} timestamp problems (the first {MAX_TIME_WARNINGS} said above)", self.time_warnings));
        }
        if self.cut_packets > 3 {
            said.push(format!("{} packets cut to {MAX_SERIAL_READ} bytes", self.cut_packets));
        }
        if self.dropped_interfaces > 0 {
            said.push(format!("{} interfaces beyond the first {MAX_INTERFACES} not kept", self.dropped_interfaces));
        }
        (!said.is_empty()).then(|| format!("in all: {}", said.join("; ")))
    }

    fn plausible_at(&self, b: &[u8]) -> bool {
        match self.kind {
            Some(FileKind::PcapNg) => match parse_block(b, self.endian) {
                Ok(Step::Item(block, _)) => matches!(block.block_type, IDB | EPB | SPB | SHB | 2 | 4 | 5),
                _ => false,
            },
            Some(FileKind::Pcap { endian, .. }) => match parse_pcap_record(b, endian) {
                Ok(Step::Item(r, used)) => {
                    let last_sec = self.clocks.first().and_then(|(c, _)| c.last_raw()).unwrap_or(0) / 1_000_000_000;
                    r.orig_len as usize >= r.data.len()
                        && r.data.len() <= MAX_BLOCK as usize
                        && (last_sec == 0 || u64::from(r.ts_sec).abs_diff(last_sec) < 86_400)
                        && matches!(parse_pcap_record(&b[used..], endian), Ok(Step::Item(..) | Step::NeedMore(_)))
                }
                _ => false,
            },
            None => false,
        }
    }
}
