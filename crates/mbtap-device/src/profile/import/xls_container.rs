//! The compound file an XLS workbook lives in, read to find its workbook stream the way
//! Excel's readers (calamine 0.32 among them) find it: the first directory entry *in the
//! directory's order* named `Workbook` (else `Book`), linked into the directory tree or not.
//! The file is not trusted: a sector chain that loops, a length past the file, a sector number
//! past the allocation table or a mini sector outside the mini stream is refused, said (a
//! reader that trusts them loops forever, allocates the length given, or panics). The stream is not
//! gathered: [`parse_xls_stream`] says which pieces of the file it lies in, and
//! [`StreamReader`] reads them as one stream (`xls_rows.rs` reads the sheet from there), so the
//! import never holds the stream beside the file.
//!
//! Layout as [MS-CFB] lays it out: a 512-byte header (§2.2), sectors of 512 or 4 096 bytes
//! numbered from the one after the header, a FAT of next-sector numbers (§2.3) reached through
//! the DIFAT (§2.5), 128-byte directory entries (§2.6), a mini stream of 64-byte sectors for
//! streams under 4 096 bytes (§2.4).

use std::ops::Range;

pub use super::xls_stream::{StreamReader, WorkbookStream};

/// The header's signature ([MS-CFB] §2.2).
const MAGIC: [u8; 8] = [0xD0, 0xCF, 0x11, 0xE0, 0xA1, 0xB1, 0x1A, 0xE1];
/// Sector numbers from here up are markers, not sectors ([MS-CFB] §2.1): the reader follows the
/// DIFAT chain while below it.
const MAXREGSECT_END: u32 = 0xFFFF_FFFA;
/// `DIFSECT` ([MS-CFB] §2.1): the reader reads FAT sectors from DIFAT entries below it.
const DIFSECT: u32 = 0xFFFF_FFFC;
/// `ENDOFCHAIN` ([MS-CFB] §2.1).
const ENDOFCHAIN: u32 = 0xFFFF_FFFE;
/// A directory entry's size ([MS-CFB] §2.6.1).
const ENTRY: usize = 128;
/// Mini sectors are 64 bytes ([MS-CFB] §2.2, mini sector shift 6); a stream shorter than the
/// cutoff, 4 096 bytes, lives in the mini stream.
const MINI: usize = 64;
const MINI_CUTOFF: u64 = 4096;
/// What the reader reserves for the DIFAT, from bytes 62–65 of the header (it reads a field
/// there that straddles two others): more than this many entries is refused (64 MiB).
const MAX_DIFAT_RESERVE: u32 = 1 << 24;

/// Why the container cannot be read as the workbook reader would read it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ContainerError {
    #[error("not a compound file (no signature)")]
    NotCompound,
    #[error("the header's {field} is {value:#x}: {why}")]
    Header { field: &'static str, value: u64, why: &'static str },
    #[error("the {chain} chain {why} (at sector {sector})")]
    Chain { chain: &'static str, sector: u32, why: &'static str },
    #[error("directory entry {index} ({name:?}) says {len} bytes, more than the file's {file}")]
    Length { index: usize, name: String, len: u64, file: usize },
    #[error("no stream named Workbook or Book")]
    NoWorkbook,
}

/// One directory entry as the reader keeps it.
struct Entry {
    name: String,
    start: u32,
    len: u64,
}

/// The file's sectors.
struct Sectors<'a> {
    data: &'a [u8],
    size: usize,
    /// The highest sector number the reader accepts (the file's length over the sector size).
    max: u32,
}

impl<'a> Sectors<'a> {
    /// Sector `id`'s bytes in the file: as the reader reads it (a last sector cut short by the
    /// end of the file is what there is of it); one starting past the end is refused (the
    /// reader panics).
    fn range(&self, id: u32, chain: &'static str) -> Result<Range<usize>, ContainerError> {
        let beyond = || ContainerError::Chain { chain, sector: id, why: "names a sector past the end of the file" };
        if id > self.max {
            return Err(beyond());
        }
        let start = (id as usize).checked_mul(self.size).ok_or_else(beyond)?;
        if start > self.data.len() {
            return Err(beyond());
        }
        // The sectors start after the header, one sector into the file.
        let end = start.saturating_add(self.size).min(self.data.len());
        Ok(start + self.size..end + self.size)
    }

    /// Sector `id`'s bytes (see [`Self::range`]).
    fn get(&self, id: u32, chain: &'static str) -> Result<&'a [u8], ContainerError> {
        let r = self.range(id, chain)?;
        Ok(self.data.get(r.start - self.size..r.end - self.size).unwrap_or_default())
    }
}

/// The pieces of a source the chain from `start` through `next` covers, cut to `len` when `len`
/// is not 0, as the reader reads it (each sector's place from `sector`). More steps than
/// `limit` — the sectors there are — is a loop (the reader never ends); a next sector outside
/// `next` panics the reader.
fn chain_pieces(
    start: u32,
    next: &[u32],
    len: u64,
    limit: usize,
    name: &'static str,
    sector: impl Fn(u32) -> Result<Range<usize>, ContainerError>,
) -> Result<Vec<Range<usize>>, ContainerError> {
    let mut out: Vec<Range<usize>> = Vec::new();
    let (mut id, mut steps) = (start, 0usize);
    while id != ENDOFCHAIN {
        steps += 1;
        if steps > limit {
            return Err(ContainerError::Chain { chain: name, sector: id, why: "loops" });
        }
        let r = sector(id)?;
        // Sectors one after another in the source make one piece.
        match out.last_mut() {
            Some(last) if last.end == r.start => last.end = r.end,
            _ => out.push(r),
        }
        id = *next.get(id as usize).ok_or(ContainerError::Chain {
            chain: name,
            sector: id,
            why: "runs past the allocation table",
        })?;
    }
    if len > 0 {
        let mut left = usize::try_from(len).unwrap_or(usize::MAX);
        out.retain_mut(|r| {
            let keep = left > 0;
            r.end = r.end.min(r.start.saturating_add(left));
            left -= r.len();
            keep
        });
    }
    Ok(out)
}

/// The bytes of `pieces` of `source`, one after another.
fn gather(source: &[u8], pieces: &[Range<usize>]) -> Vec<u8> {
    let mut out = Vec::with_capacity(pieces.iter().map(ExactSizeIterator::len).sum());
    for r in pieces {
        out.extend_from_slice(source.get(r.clone()).unwrap_or_default());
    }
    out
}

/// `b` as little-endian u32s; the reader asserts a whole number of them.
fn words(b: &[u8], chain: &'static str, sector: u32) -> Result<Vec<u32>, ContainerError> {
    if !b.len().is_multiple_of(4) {
        return Err(ContainerError::Chain { chain, sector, why: "ends inside a sector number" });
    }
    Ok(b.chunks_exact(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]])).collect())
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    b.get(at..at + 2).map_or(0, |w| u16::from_le_bytes([w[0], w[1]]))
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    b.get(at..at + 4).map_or(0, |w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
}

/// Where the workbook stream the reader will read lies in `file` (a whole XLS file): the first
/// entry named `Workbook`, else — also when that one cannot be read — the first named `Book`.
///
/// Contract: any bytes; work linear in the file (each chain visits a sector once at most, a
/// chain that comes back is refused); the pieces found lie inside the file.
///
/// # Errors
/// Whatever would make the reader loop, panic, allocate past the file, or read another stream.
#[allow(clippy::too_many_lines)]
pub fn parse_xls_stream(file: &[u8]) -> Result<WorkbookStream, ContainerError> {
    let header = file.get(..512).ok_or(ContainerError::NotCompound)?;
    if header.get(..8) != Some(&MAGIC[..]) {
        return Err(ContainerError::NotCompound);
    }
    let shift = u16_at(header, 30);
    let size = match shift {
        0x0009 => 512,
        0x000C => 4096,
        s => {
            return Err(ContainerError::Header {
                field: "sector shift",
                value: u64::from(s),
                why: "not 9 or 12 (512- or 4096-byte sectors)",
            });
        }
    };
    if u16_at(header, 32) != 6 {
        return Err(ContainerError::Header {
            field: "mini sector shift",
            value: u64::from(u16_at(header, 32)),
            why: "not 6 (64-byte mini sectors)",
        });
    }
    let version = u16_at(header, 26);
    let dir_len = u64::from(u32_at(header, 40));
    let dir_start = u32_at(header, 48);
    let mini_fat_start = u32_at(header, 60);
    let mini_fat_len = u64::from(u32_at(header, 64));
    let difat_start = u32_at(header, 68);
    let reserve = u32_at(header, 62);
    if reserve > MAX_DIFAT_RESERVE {
        return Err(ContainerError::Header {
            field: "bytes 62–65 (the reader reserves that many DIFAT entries)",
            value: u64::from(reserve),
            why: "more than a file has",
        });
    }
    let data = file.get(size..).ok_or(ContainerError::Header {
        field: "sector shift",
        value: u64::from(shift),
        why: "the file is shorter than its header",
    })?;
    let sectors = Sectors { data, size, max: u32::try_from(file.len() / size).unwrap_or(u32::MAX) };
    let too_long = |what: &'static str, len: u64| {
        (len > file.len() as u64).then_some(ContainerError::Header {
            field: what,
            value: len,
            why: "longer than the file",
        })
    };

    // The DIFAT: 109 entries in the header, then a chain through each sector's last entry.
    let mut difat = words(header.get(76..512).unwrap_or_default(), "DIFAT", 0)?;
    let (mut id, mut steps) = (difat_start, 0u32);
    while id < MAXREGSECT_END {
        steps += 1;
        if steps > sectors.max.saturating_add(1) {
            return Err(ContainerError::Chain { chain: "DIFAT", sector: id, why: "loops" });
        }
        difat.extend(words(sectors.get(id, "DIFAT")?, "DIFAT", id)?);
        id = difat.pop().ok_or(ContainerError::Chain { chain: "DIFAT", sector: id, why: "is empty" })?;
    }
    // The FAT: every DIFAT entry below DIFSECT is a FAT sector, read as listed.
    let fat_sectors: Vec<u32> = difat.into_iter().filter(|&id| id < DIFSECT).collect();
    if fat_sectors.len() > sectors.max as usize + 1 {
        return Err(ContainerError::Chain {
            chain: "FAT",
            sector: fat_sectors.first().copied().unwrap_or(0),
            why: "has more sectors than the file",
        });
    }
    let mut fat = Vec::new();
    for id in fat_sectors {
        fat.extend(words(sectors.get(id, "FAT")?, "FAT", id)?);
    }
    let sectors = &sectors;
    let regular = |name: &'static str| move |id: u32| sectors.range(id, name);
    // A chain visits each sector once at most: more steps than sectors is a loop.
    let limit = sectors.max as usize + 1;

    // The directory, in the order the reader searches it.
    let dir_bytes = dir_len.saturating_mul(size as u64);
    if let Some(e) = too_long("directory length", dir_bytes) {
        return Err(e);
    }
    let dirs = gather(file, &chain_pieces(dir_start, &fat, dir_bytes, limit, "directory", regular("directory"))?);
    let mut entries = Vec::new();
    for raw in dirs.chunks(ENTRY) {
        if raw.len() < 124 + if size == 512 { 0 } else { 4 } {
            return Err(ContainerError::Chain { chain: "directory", sector: dir_start, why: "ends inside an entry" });
        }
        let units: Vec<u16> =
            raw.get(..64).unwrap_or_default().chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
        let mut name = String::from_utf16_lossy(&units);
        if let Some(nul) = name.find('\0') {
            name.truncate(nul);
        }
        let len = if size == 512 {
            u64::from(u32_at(raw, 120))
        } else {
            raw.get(120..128).map_or(0, |b| u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
        };
        entries.push(Entry { name, start: u32_at(raw, 116), len });
    }
    let root =
        entries.first().ok_or(ContainerError::Chain { chain: "directory", sector: dir_start, why: "is empty" })?;
    if version != 3 && root.start == ENDOFCHAIN {
        return Err(ContainerError::Chain { chain: "directory", sector: dir_start, why: "has no root storage" });
    }

    // The mini stream and its allocation table, when the header says there is one.
    let (mini_fat, ministream) = if mini_fat_len > 0 {
        if root.len > file.len() as u64 {
            return Err(ContainerError::Length { index: 0, name: root.name.clone(), len: root.len, file: file.len() });
        }
        let ministream =
            gather(file, &chain_pieces(root.start, &fat, root.len, limit, "mini stream", regular("mini stream"))?);
        let mini_fat_bytes = mini_fat_len.saturating_mul(size as u64);
        if let Some(e) = too_long("mini FAT length", mini_fat_bytes) {
            return Err(e);
        }
        let raw =
            gather(file, &chain_pieces(mini_fat_start, &fat, mini_fat_bytes, limit, "mini FAT", regular("mini FAT"))?);
        (words(&raw, "mini FAT", mini_fat_start)?, ministream)
    } else {
        (Vec::new(), Vec::new())
    };
    let mini_max = sectors.max.saturating_mul(8);
    let mini_sector = |id: u32| -> Result<Range<usize>, ContainerError> {
        let outside = ContainerError::Chain {
            chain: "mini stream",
            sector: id,
            why: "names a mini sector outside the mini stream",
        };
        if id > mini_max {
            return Err(outside);
        }
        let start = (id as usize) * MINI;
        // Past the mini stream the reader reads whatever the file holds next: refused.
        if start + MINI > ministream.len() {
            return Err(outside);
        }
        Ok(start..start + MINI)
    };

    // The stream, as the reader finds it: by name, in the directory's order.
    let stream = |name: &str| -> Result<WorkbookStream, ContainerError> {
        let (index, e) = entries.iter().enumerate().find(|(_, e)| e.name == name).ok_or(ContainerError::NoWorkbook)?;
        if e.len > file.len() as u64 {
            return Err(ContainerError::Length { index, name: e.name.clone(), len: e.len, file: file.len() });
        }
        if e.len < MINI_CUTOFF {
            let pieces =
                chain_pieces(e.start, &mini_fat, e.len, ministream.len() / MINI, "workbook (mini)", mini_sector)?;
            Ok(WorkbookStream::Held(gather(&ministream, &pieces)))
        } else {
            let pieces = chain_pieces(e.start, &fat, e.len, limit, "workbook", regular("workbook"))?;
            Ok(WorkbookStream::InFile(pieces.into_iter().map(|r| r.start as u64..r.end as u64).collect()))
        }
    };
    stream("Workbook").or_else(|first| match stream("Book") {
        Err(ContainerError::NoWorkbook) => Err(first),
        other => other,
    })
}

/// The workbook stream the reader will read from `file` (a whole XLS file), gathered: see
/// [`parse_xls_stream`].
///
/// # Errors
/// As [`parse_xls_stream`].
pub fn parse_xls_container(file: &[u8]) -> Result<Vec<u8>, ContainerError> {
    Ok(match parse_xls_stream(file)? {
        WorkbookStream::Held(b) => b,
        WorkbookStream::InFile(pieces) => {
            let at = |p: u64| usize::try_from(p).unwrap_or(usize::MAX);
            let pieces: Vec<Range<usize>> = pieces.into_iter().map(|r| at(r.start)..at(r.end)).collect();
            gather(file, &pieces)
        }
    })
}
