//! The imported profile written as it is read (issue 39: the points and the profile's text held
//! in memory took 20× a sheet of tiny rows). Each point's entry goes to a scratch file beside the
//! profile as the point comes (unlinked at once: nothing is left behind if the import is
//! killed); memory keeps the addresses taken (1 MiB) and 8 bytes per point. At the end the
//! profile is its header and the entries in address order, written to a new file, loaded back
//! from that file a part at a time, and only then put in place — never replacing a profile in
//! silence, never writing through a link.

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
    /// Each point's record's offset in `scratch`.
    offsets: Vec<u64>,
    ledger: Ledger,
    text: String,
    /// The first write error (a sink cannot return one): said at the end.
    failed: Option<std::io::Error>,
    problems: usize,
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
            offsets: Vec::new(),
            ledger: Ledger::default(),
            text: String::new(),
            failed: None,
            problems: 0,
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
        if let Err(e) = writeln!(self.err, "mbtap: {}: {}", self.source, printable(line))
            && self.failed.is_none()
        {
            self.failed = Some(e);
        }
    }

    /// Record `n`'s bytes into `buf` (from the scratch file, or from the block not yet written).
    fn record(&self, n: u32, buf: &mut Vec<u8>) -> std::io::Result<()> {
        let i = n as usize;
        let (Some(&from), to) = (self.offsets.get(i), self.offsets.get(i + 1).copied().unwrap_or(self.end)) else {
            return Err(std::io::Error::other("no such point"));
        };
        let len = usize::try_from(to - from).map_err(std::io::Error::other)?;
        buf.clear();
        // Blocks are written whole records at a time: a record is on disk or pending, not split.
        let written = self.end - self.pending.len() as u64;
        if let Some(at) = from.checked_sub(written) {
            let at = usize::try_from(at).map_err(std::io::Error::other)?;
            buf.extend_from_slice(
                self.pending.get(at..at + len).ok_or_else(|| std::io::Error::other("no such point"))?,
            );
            return Ok(());
        }
        buf.resize(len, 0);
        self.scratch.read_exact_at(buf, from)
    }

    /// Writes the pending block to the scratch file.
    fn flush(&mut self) -> std::io::Result<()> {
        let written = self.end - self.pending.len() as u64;
        self.scratch.write_all_at(&self.pending, written)?;
        self.pending.clear();
        Ok(())
    }

    /// Record `n` split: name, origin, entry.
    fn parts(record: &[u8]) -> Option<(&str, &str, &[u8])> {
        let len = |at: usize| -> Option<usize> {
            Some(u32::from_le_bytes(record.get(at..at + 4)?.try_into().ok()?) as usize)
        };
        let (n, o) = (len(0)?, len(4)?);
        let name = std::str::from_utf8(record.get(8..8 + n)?).ok()?;
        let origin = std::str::from_utf8(record.get(8 + n..8 + n + o)?).ok()?;
        Some((name, origin, record.get(8 + n + o..)?))
    }

    fn append(&mut self, p: &Point) -> std::io::Result<()> {
        self.text.clear();
        entry(&mut self.text, p);
        let lens = |s: &str| u32::try_from(s.len()).map_err(std::io::Error::other).map(u32::to_le_bytes);
        let len = 8 + p.name.len() + p.origin.len() + self.text.len();
        let len = u64::try_from(len).map_err(std::io::Error::other)?;
        if self.end + len > MAX_SCRATCH {
            return Err(std::io::Error::other(format!("over {MAX_SCRATCH} bytes of profile entries")));
        }
        let record = &mut self.pending;
        record.extend_from_slice(&lens(&p.name)?);
        record.extend_from_slice(&lens(&p.origin)?);
        record.extend_from_slice(p.name.as_bytes());
        record.extend_from_slice(p.origin.as_bytes());
        record.extend_from_slice(self.text.as_bytes());
        self.offsets.push(self.end);
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
    pub fn problems(&self) -> usize {
        self.problems
    }

    /// When nothing was imported: the fix the problems point to (issue 42: "check the header
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
                let (_, _, entry) = Self::parts(&record).ok_or_else(|| std::io::Error::other("a damaged entry"))?;
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
        match self.ledger.take(&p) {
            Ok(_) => {
                if let Err(e) = self.append(&p)
                    && self.failed.is_none()
                {
                    self.failed = Some(e);
                }
            }
            Err(clash) => {
                let mut buf = Vec::new();
                let record = match clash {
                    Clash::Overlaps(n) => self.record(n, &mut buf).ok().map(|()| buf.as_slice()),
                    Clash::PastEnd => None,
                };
                let other = record.and_then(Self::parts).map(|(name, origin, _)| (name, origin));
                let problem = self.ledger.problem(&p, clash, other);
                self.problem(problem);
            }
        }
    }

    fn problem(&mut self, p: Problem) {
        self.problems += 1;
        self.wanted_table |= p.why.contains("give --table");
        self.wanted_header |= p.why.contains("no header row");
        self.say(&format!("skipped {p}"));
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
