//! The imported profile written as it is read (the points and the profile's text held
//! in memory took 20× a sheet of tiny rows). Each point's entry goes to a scratch file beside the
//! profile as the point comes (unlinked at once: nothing is left behind if the import is
//! killed), in blocks of 64 KiB; memory keeps the addresses taken (1 MiB, each holding the
//! offset of its point's record) and nothing per point. At the end the profile is its header
//! and the entries in address order, written to a new file, loaded back from that file a part
//! at a time, and only then put in place — never replacing a profile in silence, never writing
//! through a link.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::unix::fs::FileExt as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use mbtap_analysis::report::format::printable;
use mbtap_device::profile::import::{Clash, Ledger, Point, Problem, Sink, entry, header, load_back};

/// Scratch bytes at most (the entries of every address of the four tables with long names and
/// descriptions fit many times over).
const MAX_SCRATCH: u64 = 1 << 31;
/// Records are written to the scratch file in blocks of about this many bytes.
const PENDING_BLOCK: usize = 64 << 10;
/// A record's header: its name's, origin's and entry's lengths (u32 LE each), then the point's
/// first address (u16 LE).
const RECORD_HEAD: usize = 14;
/// A record's first read from the scratch file (most records are shorter).
const FIRST_READ: u64 = 512;
/// Problems said one by one; past them only counted (a sheet of 200 000 bad rows printed 2 GB).
const SAID_PROBLEMS: usize = 200;
/// Characters of one line said, at most (a problem quoting a 120 kB cell is cut there).
const SAID_CHARS: usize = 400;

/// Points and problems as they are read, written out.
pub struct ProfileFile<'e> {
    /// Entries as they come: per point a record of its name's and origin's lengths (u32 LE
    /// each), its name, its origin, then its `[[table]]` entry.
    scratch: File,
    /// Where the records end (those in `pending` included).
    end: u64,
    /// Records not yet written to `scratch`, from `end - pending.len()` on: written a block at a
    /// time, not a system call per point.
    pending: Vec<u8>,
    ledger: Ledger,
    text: String,
    /// The first write error (a sink cannot return one): said at the end.
    failed: Option<std::io::Error>,
    problems: usize,
    /// The source made the import produce past its budget: why (nothing is written).
    refused: Option<String>,
    /// Whether a problem asked for `--table`, or found no header row: the hint at the end.
    wanted_table: bool,
    wanted_header: bool,
    notes: Vec<String>,
    /// The source being read, for messages (`mbtap: FILE: skipped …`).
    source: String,
    /// Prefixed to each origin when several files are read.
    origin_prefix: Option<String>,
    err: &'e mut dyn Write,
}

impl<'e> ProfileFile<'e> {
    /// A sink whose scratch file is made in `dir` (the profile's directory: the entries are ~3×
    /// the sheet and belong on its disk, not in memory).
    pub fn new(dir: &Path, err: &'e mut dyn Write) -> anyhow::Result<Self> {
        let path = dir.join(format!(".mbtap-import-{}.scratch", std::process::id()));
        let scratch = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .with_context(|| format!("creating a scratch file {}", path.display()))?;
        // Unlinked at once: the open file stays ours, and nothing is left if the import dies.
        std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
        Ok(Self {
            scratch,
            end: 0,
            pending: Vec::with_capacity(PENDING_BLOCK),
            ledger: Ledger::default(),
            text: String::new(),
            failed: None,
            problems: 0,
            refused: None,
            wanted_table: false,
            wanted_header: false,
            notes: Vec::new(),
            source: String::new(),
            origin_prefix: None,
            err,
        })
    }

    /// What follows is read from `source` (prefixing each point's origin with it when `prefix`).
    pub fn reading(&mut self, source: &str, prefix: bool) {
        source.clone_into(&mut self.source);
        self.origin_prefix = prefix.then(|| source.to_owned());
    }

    /// Says `line` on standard error; a failure to say it is kept for the end.
    fn say(&mut self, line: &str) {
        let shown: String = if line.chars().count() > SAID_CHARS {
            line.chars().take(SAID_CHARS).chain("…".chars()).collect()
        } else {
            line.to_owned()
        };
        if let Err(e) = writeln!(self.err, "mbtap: {}: {}", self.source, printable(&shown))
            && self.failed.is_none()
        {
            self.failed = Some(e);
        }
    }

    /// The record keyed `key` (its offset) into `buf`: from the scratch file, or from the block
    /// not yet written (blocks are written whole records at a time: a record is on disk or
    /// pending, never split).
    fn record(&self, key: u32, buf: &mut Vec<u8>) -> std::io::Result<()> {
        let damaged = || std::io::Error::other("a damaged entry");
        let from = u64::from(key);
        let written = self.end - self.pending.len() as u64;
        buf.clear();
        if let Some(at) = from.checked_sub(written) {
            let at = usize::try_from(at).map_err(std::io::Error::other)?;
            let len = self.pending.get(at..).and_then(Self::record_len).ok_or_else(damaged)?;
            buf.extend_from_slice(self.pending.get(at..at + len).ok_or_else(damaged)?);
            return Ok(());
        }
        // One read holds most records whole; a longer one takes a second.
        let first = usize::try_from((written - from).min(FIRST_READ)).map_err(std::io::Error::other)?;
        buf.resize(first, 0);
        self.scratch.read_exact_at(buf, from)?;
        let len = Self::record_len(buf).ok_or_else(damaged)?;
        if len > first {
            buf.resize(len, 0);
            self.scratch.read_exact_at(&mut buf[first..], from + first as u64)?;
        } else {
            buf.truncate(len);
        }
        Ok(())
    }

    /// The lengths a record's header gives: its name's, origin's and entry's.
    fn head(record: &[u8]) -> Option<[usize; 3]> {
        let len = |at: usize| -> Option<usize> {
            Some(u32::from_le_bytes(record.get(at..at + 4)?.try_into().ok()?) as usize)
        };
        Some([len(0)?, len(4)?, len(8)?])
    }

    /// The length of the record `record` starts with, from its header.
    fn record_len(record: &[u8]) -> Option<usize> {
        let [n, o, e] = Self::head(record)?;
        RECORD_HEAD.checked_add(n)?.checked_add(o)?.checked_add(e)
    }

    /// A record split: name, origin, first address, entry.
    fn parts(record: &[u8]) -> Option<(&str, &str, u16, &[u8])> {
        let [n, o, e] = Self::head(record)?;
        let address = u16::from_le_bytes(record.get(12..14)?.try_into().ok()?);
        let h = RECORD_HEAD;
        let name = std::str::from_utf8(record.get(h..h + n)?).ok()?;
        let origin = std::str::from_utf8(record.get(h + n..h + n + o)?).ok()?;
        Some((name, origin, address, record.get(h + n + o..h + n + o + e)?))
    }

    /// Writes the pending block to the scratch file.
    fn flush(&mut self) -> std::io::Result<()> {
        let written = self.end - self.pending.len() as u64;
        self.scratch.write_all_at(&self.pending, written)?;
        self.pending.clear();
        Ok(())
    }

    /// Appends `p`'s record (keyed by where it starts: [`Self::end`] before the call).
    fn append(&mut self, p: &Point) -> std::io::Result<()> {
        self.text.clear();
        entry(&mut self.text, p);
        let lens = |s: &str| u32::try_from(s.len()).map_err(std::io::Error::other).map(u32::to_le_bytes);
        let len = RECORD_HEAD + p.name.len() + p.origin.len() + self.text.len();
        let len = u64::try_from(len).map_err(std::io::Error::other)?;
        if self.end + len > MAX_SCRATCH {
            return Err(std::io::Error::other(format!("over {MAX_SCRATCH} bytes of profile entries")));
        }
        let record = &mut self.pending;
        record.extend_from_slice(&lens(&p.name)?);
        record.extend_from_slice(&lens(&p.origin)?);
        record.extend_from_slice(&lens(&self.text)?);
        record.extend_from_slice(&p.address.to_le_bytes());
        record.extend_from_slice(p.name.as_bytes());
        record.extend_from_slice(p.origin.as_bytes());
        record.extend_from_slice(self.text.as_bytes());
        self.end += len;
        if self.pending.len() >= PENDING_BLOCK {
            self.flush()?;
        }
        Ok(())
    }

    /// Points per table: holding, input, coils, discrete.
    pub fn counts(&self) -> [usize; 4] {
        let [coils, discrete, holding, input] = self.ledger.counts();
        [holding, input, coils, discrete]
    }

    /// Problems said.
    /// Why the import is refused (a budget passed), if it is.
    #[must_use]
    pub fn refused(&self) -> Option<&str> {
        self.refused.as_deref()
    }

    /// Problems past those said one by one, for the end (`… and N more problems`).
    #[must_use]
    pub fn unsaid(&self) -> usize {
        self.problems.saturating_sub(SAID_PROBLEMS)
    }

    pub fn problems(&self) -> usize {
        self.problems
    }

    /// When nothing was imported: the fix the problems point to ("check the header
    /// row or give --columns" where every row wanted --table).
    pub fn hint(&self) -> Option<&'static str> {
        (self.ledger.is_empty()).then_some(if self.wanted_table {
            "the sheet does not say which table: give --table holding|input|coils|discrete"
        } else if self.wanted_header {
            "give the columns with --columns address=B,name=A,…"
        } else {
            "fix the rows named above, or give --columns, --table, --type"
        })
    }

    /// Writes the profile named `name` for `device` from `sources` to `tmp` (a new file): the
    /// header, then the entries in address order; then loads it back from there.
    pub fn write(&mut self, tmp: &Path, name: &str, device: &str, sources: &str) -> anyhow::Result<()> {
        if let Some(e) = self.failed.take() {
            return Err(e).context("writing the profile's entries");
        }
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(tmp)
            .with_context(|| format!("creating {}", tmp.display()))?;
        let mut out = BufWriter::new(file);
        let wrote = (|| -> std::io::Result<File> {
            out.write_all(header(name, device, sources, &self.notes, self.problems).as_bytes())?;
            let mut record = Vec::new();
            for n in self.ledger.in_order() {
                self.record(n, &mut record)?;
                let (_, _, _, entry) = Self::parts(&record).ok_or_else(|| std::io::Error::other("a damaged entry"))?;
                out.write_all(entry)?;
            }
            let file = out.into_inner().map_err(std::io::IntoInnerError::into_error)?;
            file.sync_all()?;
            Ok(file)
        })();
        wrote.with_context(|| format!("writing {}", tmp.display()))?;
        // What is written must load like a hand-written profile: checked before it is kept.
        let back = File::open(tmp).with_context(|| format!("reading back {}", tmp.display()))?;
        load_back(name, std::io::BufReader::new(back))
            .context("the imported profile does not load (a bug: please report it with the sheet)")
    }
}

impl Sink for ProfileFile<'_> {
    fn point(&mut self, mut p: Point) {
        if let Some(prefix) = &self.origin_prefix {
            p.origin = format!("{prefix}, {}", p.origin);
        }
        // The key is where the point's record will start (under MAX_SCRATCH: it fits).
        let key = u32::try_from(self.end).unwrap_or(u32::MAX);
        match self.ledger.take(&p, key) {
            Ok(()) => {
                if let Err(e) = self.append(&p)
                    && self.failed.is_none()
                {
                    self.failed = Some(e);
                }
            }
            Err(clash) => {
                let mut buf = Vec::new();
                let record = match clash {
                    Clash::Overlaps(key) => self.record(key, &mut buf).ok().map(|()| buf.as_slice()),
                    Clash::PastEnd | Clash::NoKey => None,
                };
                let other = record.and_then(Self::parts).map(|(name, origin, address, _)| (name, origin, address));
                let problem = Ledger::problem(&p, clash, other);
                self.problem(problem);
            }
        }
    }

    fn problem(&mut self, p: Problem) {
        self.problems += 1;
        self.wanted_table |= p.why.contains("give --table");
        self.wanted_header |= p.why.contains("no header row");
        // Bounded by what is printed, not by what the sheet holds: the first problems in full
        // (each line at most SAID_CHARS), then only counted, said once at the end.
        if self.problems <= SAID_PROBLEMS {
            self.say(&format!("skipped {p}"));
        }
    }

    fn over_budget(&mut self, p: Problem) {
        self.say(&format!("refused {p}"));
        self.refused = Some(p.to_string());
    }

    fn note(&mut self, n: String) {
        self.say(&n);
        self.notes.push(format!("{}: {n}", self.source));
    }
}

/// Where the profile goes: `output`, else `NAME.toml` in the user profile directory.
pub fn destination(output: Option<&Path>, name: &str) -> anyhow::Result<PathBuf> {
    if let Some(o) = output {
        return Ok(o.to_owned());
    }
    let dir = crate::config::devices::user_profile_dir()
        .context("no user profile directory (set MBTAP_PROFILE_DIR or HOME), give -o")?;
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir.join(format!("{name}.toml")))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mbtap_device::profile::Table;
    use mbtap_device::profile::format::{Access, ValueType, WordOrder};

    /// A u16 holding register at `address` named `name`.
    fn point(address: u16, name: &str) -> Point {
        Point {
            table: Table::HoldingRegisters,
            address,
            name: name.to_owned(),
            value_type: ValueType::U16,
            word_order: WordOrder::HighFirst,
            scale: None,
            unit: None,
            access: Access::Read,
            length: None,
            description: None,
            origin: format!("row {address}"),
        }
    }

    /// Records go to the scratch file in 64 KiB blocks and the ledger keeps
    /// their offsets, nothing per point. A clash names the other point whether its record is
    /// still in the block, on disk, or on disk and longer than one read; the profile lists every
    /// point in address order.
    #[test]
    fn a_clash_names_the_other_point_from_the_block_or_the_disk() {
        let dir = std::env::temp_dir().join(format!("mbtap-profile-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut err = Vec::new();
        let mut sink = ProfileFile::new(&dir, &mut err).unwrap();
        sink.reading("regs.csv", false);
        let long = "L".repeat(700);
        sink.point(point(1, &long));
        // Enough points, added from the top down, for several blocks to be written.
        for a in (2..3000u16).rev() {
            sink.point(point(a * 2, &format!("reg{a}")));
        }
        assert!(sink.end - sink.pending.len() as u64 > 2 * PENDING_BLOCK as u64, "blocks were written");
        sink.point(point(1, "again")); // the long one, on disk
        sink.point(point(5998, "again")); // the first of the loop, on disk
        sink.point(point(4, "again")); // the last of the loop, in the block
        assert_eq!(sink.counts(), [2999, 0, 0, 0]);
        let tmp = dir.join("out.toml");
        sink.write(&tmp, "regs", "dev", "regs.csv").unwrap();
        drop(sink);
        let said = String::from_utf8(err).unwrap();
        let text = std::fs::read_to_string(&tmp).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        // The 700-character name is read whole from disk (past one read: the profile has it);
        // the line that says the clash is cut at SAID_CHARS.
        assert!(said.contains(&format!("overlaps \"{}", "L".repeat(300))) && said.contains('…'), "{said}");
        assert!(said.contains("overlaps \"reg2999\" (row 5998, address 5998)"), "{said}");
        assert!(said.contains("overlaps \"reg2\" (row 4, address 4)"), "{said}");
        let at = |name: &str| text.find(&format!("name = \"{name}\"")).unwrap();
        assert!(at(&long) < at("reg2") && at("reg2") < at("reg3") && at("reg1000") < at("reg2999"));
        assert_eq!(text.matches("[[holding_registers]]").count(), 2999);
    }
}
