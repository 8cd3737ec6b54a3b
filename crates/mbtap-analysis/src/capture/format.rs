//! Zero-copy parsers for the blocks of classic pcap and pcapng files.
//!
//! Contract of every `parse_*` here: `Ok(Step::Item(value, consumed))` — one item from the
//! front of the input; `Ok(Step::NeedMore(n))` — at least `n` bytes in total are needed;
//! `Err(FormatError)` — the bytes cannot be this structure. Lengths are checked before use.
//!
//! References: pcap — draft-ietf-opsawg-pcap; pcapng — draft-ietf-opsawg-pcapng (section
//! header 0x0A0D0D0A, interface description 1, simple packet 3, enhanced packet 6, option
//! if_tsresol 9).

use nom::Parser;
use nom::number::Endianness;
use nom::number::complete::u32 as nu32;
use thiserror::Error;

/// One step of parsing from the front of a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step<T> {
    NeedMore(usize),
    Item(T, usize),
}

/// Bytes that cannot be the structure expected.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FormatError {
    #[error("not a pcap or pcapng file (first four bytes {0:02x?})")]
    UnknownMagic([u8; 4]),
    #[error("pcapng block length {len} is invalid (must be a multiple of 4, at least 12, at most {max})")]
    BlockLength { len: u32, max: u32 },
    #[error("pcapng block length {start} at the start disagrees with {end} at the end")]
    BlockLengthMismatch { start: u32, end: u32 },
    #[error("pcap record of {len} bytes is larger than {max}")]
    RecordLength { len: u32, max: u32 },
    #[error("{what} is too short for its fields")]
    Short { what: &'static str },
    #[error("section header byte-order magic {0:#010x} is neither 0x1A2B3C4D nor its reverse")]
    ByteOrder(u32),
}

/// The largest block or record accepted: far above any serial chunk (a 70 kB packet is
/// fine), low enough that a corrupt length cannot make us allocate gigabytes.
pub const MAX_BLOCK: u32 = 16 * 1024 * 1024;

/// pcap magic, microsecond timestamps.
pub const PCAP_MAGIC_US: u32 = 0xA1B2_C3D4;
/// pcap magic, nanosecond timestamps.
pub const PCAP_MAGIC_NS: u32 = 0xA1B2_3C4D;
/// pcapng section header block type.
pub const SHB: u32 = 0x0A0D_0D0A;
/// pcapng byte-order magic.
pub const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;
pub const IDB: u32 = 1;
pub const SPB: u32 = 3;
/// Interface statistics block: mbtap writes what it learned about a port's reads into its
/// comment at the end of a recording.
pub const ISB: u32 = 5;
pub const EPB: u32 = 6;
/// Option codes: end of options, comment, if_name, if_description, if_tsresol.
pub const OPT_END: u16 = 0;
pub const OPT_COMMENT: u16 = 1;
pub const IF_NAME: u16 = 2;
pub const IF_DESCRIPTION: u16 = 3;
pub const IF_TSRESOL: u16 = 9;

/// The kind of file, from its first bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    Pcap { endian: Endianness, nanos: bool, linktype: u32, snaplen: u32 },
    PcapNg,
}

/// Parses the start of a file: a pcap global header (24 bytes) or a pcapng SHB (left unconsumed).
pub fn parse_file_kind(input: &[u8]) -> Result<Step<FileKind>, FormatError> {
    let Some(magic) = input.get(..4) else { return Ok(Step::NeedMore(4)) };
    let m = [magic[0], magic[1], magic[2], magic[3]];
    if u32::from_le_bytes(m) == SHB {
        return Ok(Step::Item(FileKind::PcapNg, 0));
    }
    let (endian, nanos) = match (u32::from_le_bytes(m), u32::from_be_bytes(m)) {
        (PCAP_MAGIC_US, _) => (Endianness::Little, false),
        (PCAP_MAGIC_NS, _) => (Endianness::Little, true),
        (_, PCAP_MAGIC_US) => (Endianness::Big, false),
        (_, PCAP_MAGIC_NS) => (Endianness::Big, true),
        _ => return Err(FormatError::UnknownMagic(m)),
    };
    let Some(h) = input.get(..24) else { return Ok(Step::NeedMore(24)) };
    let r: nom::IResult<&[u8], (u32, u32)> = (nu32(endian), nu32(endian)).parse(&h[16..24]);
    let (_, (snaplen, linktype)) = r.map_err(|_| FormatError::Short { what: "pcap header" })?;
    Ok(Step::Item(FileKind::Pcap { endian, nanos, linktype, snaplen }, 24))
}

/// A classic pcap record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PcapRecord<'a> {
    pub ts_sec: u32,
    /// Microseconds or nanoseconds, per the file's magic.
    pub ts_frac: u32,
    pub orig_len: u32,
    pub data: &'a [u8],
}

/// Parses one pcap record (16-byte header + data).
pub fn parse_pcap_record(input: &[u8], endian: Endianness) -> Result<Step<PcapRecord<'_>>, FormatError> {
    let Some(h) = input.get(..16) else { return Ok(Step::NeedMore(16)) };
    let r: nom::IResult<&[u8], (u32, u32, u32, u32)> =
        (nu32(endian), nu32(endian), nu32(endian), nu32(endian)).parse(h);
    let (_, (ts_sec, ts_frac, incl, orig_len)) = r.map_err(|_| FormatError::Short { what: "pcap record header" })?;
    if incl > MAX_BLOCK {
        return Err(FormatError::RecordLength { len: incl, max: MAX_BLOCK });
    }
    let total = 16 + incl as usize;
    match input.get(16..total) {
        Some(data) => Ok(Step::Item(PcapRecord { ts_sec, ts_frac, orig_len, data }, total)),
        None => Ok(Step::NeedMore(total)),
    }
}

/// A pcapng block: its type and body (between the length fields).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Block<'a> {
    pub block_type: u32,
    pub body: &'a [u8],
}

/// Parses one pcapng block with the section's byte order. A section header block carries its
/// own byte order: use [`parse_shb`] for it.
pub fn parse_block(input: &[u8], endian: Endianness) -> Result<Step<Block<'_>>, FormatError> {
    let Some(head) = input.first_chunk::<8>() else { return Ok(Step::NeedMore(8)) };
    let block_type = word_of([head[0], head[1], head[2], head[3]], endian);
    let len = word_of([head[4], head[5], head[6], head[7]], endian);
    if len < 12 || !len.is_multiple_of(4) || len > MAX_BLOCK {
        return Err(FormatError::BlockLength { len, max: MAX_BLOCK });
    }
    let total = len as usize;
    let Some(b) = input.get(..total) else { return Ok(Step::NeedMore(total)) };
    let Some((body, trailer)) = b[8..].split_last_chunk::<4>() else {
        return Err(FormatError::Short { what: "block trailer" });
    };
    let end = word_of(*trailer, endian);
    if end != len {
        return Err(FormatError::BlockLengthMismatch { start: len, end });
    }
    Ok(Step::Item(Block { block_type, body }, total))
}

/// The byte order a section header block declares (its byte-order magic is the first field).
pub fn parse_shb_endian(input: &[u8]) -> Result<Step<Endianness>, FormatError> {
    let Some(m) = input.get(8..12) else { return Ok(Step::NeedMore(12)) };
    let m = [m[0], m[1], m[2], m[3]];
    if u32::from_le_bytes(m) == BYTE_ORDER_MAGIC {
        Ok(Step::Item(Endianness::Little, 0))
    } else if u32::from_be_bytes(m) == BYTE_ORDER_MAGIC {
        Ok(Step::Item(Endianness::Big, 0))
    } else {
        Err(FormatError::ByteOrder(u32::from_le_bytes(m)))
    }
}

/// An interface description.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Interface {
    pub linktype: u16,
    /// Timestamp units per second (if_tsresol; default 10^6).
    pub ticks_per_sec: u64,
    pub name: Option<String>,
    pub description: Option<String>,
}

fn u16_at(b: &[u8], at: usize, e: Endianness) -> Option<u16> {
    let s = b.get(at..at + 2)?;
    Some(if e == Endianness::Big { u16::from_be_bytes([s[0], s[1]]) } else { u16::from_le_bytes([s[0], s[1]]) })
}

#[inline]
fn u32_at(b: &[u8], at: usize, e: Endianness) -> Option<u32> {
    let s = b.get(at..at.checked_add(4)?)?;
    Some(word_of([s[0], s[1], s[2], s[3]], e))
}

#[inline]
fn word_of(a: [u8; 4], e: Endianness) -> u32 {
    if e == Endianness::Big { u32::from_be_bytes(a) } else { u32::from_le_bytes(a) }
}

/// Walks an options list: (code, value) pairs until opt_endofopt or the end.
fn options(mut b: &[u8], e: Endianness) -> impl Iterator<Item = (u16, &[u8])> {
    std::iter::from_fn(move || {
        let code = u16_at(b, 0, e)?;
        let len = usize::from(u16_at(b, 2, e)?);
        if code == OPT_END {
            return None;
        }
        let value = b.get(4..4 + len)?;
        b = b.get(4 + len.div_ceil(4) * 4..).unwrap_or(&[]);
        Some((code, value))
    })
}

/// Parses an interface description block body.
pub fn parse_idb(body: &[u8], e: Endianness) -> Result<Interface, FormatError> {
    let linktype = u16_at(body, 0, e).ok_or(FormatError::Short { what: "interface description block" })?;
    let mut iface = Interface { linktype, ticks_per_sec: 1_000_000, name: None, description: None };
    for (code, value) in options(body.get(8..).unwrap_or(&[]), e) {
        match code {
            IF_TSRESOL => {
                if let Some(&r) = value.first() {
                    // MSB clear: 10^-r seconds; set: 2^-(r & 0x7F).
                    let exp = u32::from(r & 0x7F);
                    iface.ticks_per_sec = if r & 0x80 == 0 { 10u64.checked_pow(exp) } else { 1u64.checked_shl(exp) }
                        .unwrap_or(1_000_000)
                        .max(1);
                }
            }
            IF_NAME => iface.name = Some(String::from_utf8_lossy(value).into_owned()),
            IF_DESCRIPTION => iface.description = Some(String::from_utf8_lossy(value).into_owned()),
            _ => {}
        }
    }
    Ok(iface)
}

/// The interface and comments of an interface statistics block body (pcapng: interface id,
/// timestamp high and low, options).
pub fn parse_isb(body: &[u8], e: Endianness) -> Result<(u32, Vec<String>), FormatError> {
    let interface = u32_at(body, 0, e).ok_or(FormatError::Short { what: "interface statistics block" })?;
    let comments = options(body.get(12..).unwrap_or(&[]), e)
        .filter(|(code, _)| *code == OPT_COMMENT)
        .map(|(_, v)| String::from_utf8_lossy(v).into_owned())
        .collect();
    Ok((interface, comments))
}

/// An enhanced (or simple) packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Packet<'a> {
    pub interface: u32,
    /// Raw timestamp in the interface's units (`None` for a simple packet block).
    pub ticks: Option<u64>,
    pub orig_len: u32,
    pub data: &'a [u8],
}

/// Parses an enhanced packet block body.
///
/// The 20 bytes of fixed fields are taken as one array: their offsets need no bounds check
/// each (a replay reads one of these per serial read, millions in a per-byte capture).
pub fn parse_epb(body: &[u8], e: Endianness) -> Result<Packet<'_>, FormatError> {
    const SHORT: FormatError = FormatError::Short { what: "enhanced packet block" };
    let Some((head, rest)) = body.split_first_chunk::<20>() else { return Err(SHORT) };
    let word = |i: usize| word_of([head[i], head[i + 1], head[i + 2], head[i + 3]], e);
    let (interface, hi, lo, cap, orig_len) = (word(0), word(4), word(8), word(12), word(16));
    let data = rest.get(..cap as usize).ok_or(SHORT)?;
    Ok(Packet { interface, ticks: Some((u64::from(hi) << 32) | u64::from(lo)), orig_len, data })
}

/// Parses a simple packet block body (interface 0, no timestamp).
pub fn parse_spb(body: &[u8], e: Endianness) -> Result<Packet<'_>, FormatError> {
    let orig_len = u32_at(body, 0, e).ok_or(FormatError::Short { what: "simple packet block" })?;
    let data = body.get(4..4 + (orig_len as usize).min(body.len().saturating_sub(4))).unwrap_or(&[]);
    Ok(Packet { interface: 0, ticks: None, orig_len, data })
}

/// Converts interface ticks to nanoseconds, without overflow.
#[must_use]
pub fn ticks_to_ns(ticks: u64, ticks_per_sec: u64) -> u64 {
    // The two resolutions nearly every file uses, without a 128-bit division per packet.
    match ticks_per_sec {
        1_000_000_000 => return ticks,
        1_000_000 => return ticks.saturating_mul(1000),
        _ => {}
    }
    let ns = u128::from(ticks) * 1_000_000_000 / u128::from(ticks_per_sec.max(1));
    u64::try_from(ns).unwrap_or(u64::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tsresol_variants() {
        assert_eq!(ticks_to_ns(1_500_000, 1_000_000), 1_500_000_000);
        assert_eq!(ticks_to_ns(3, 1_000_000_000), 3);
        assert_eq!(ticks_to_ns(1 << 20, 1 << 20), 1_000_000_000);
    }

    #[test]
    fn bad_block_length_is_an_error_not_a_panic() {
        let b = [6, 0, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0];
        assert_eq!(parse_block(&b, Endianness::Little), Err(FormatError::BlockLength { len: 7, max: MAX_BLOCK }));
        let b = [6, 0, 0, 0, 12, 0, 0, 0, 16, 0, 0, 0];
        assert_eq!(parse_block(&b, Endianness::Little), Err(FormatError::BlockLengthMismatch { start: 12, end: 16 }));
    }
}
