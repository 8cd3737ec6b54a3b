//! Store-and-forward on disk (`--mqtt-buffer [DIR]`): while the broker (or the Sparkplug
//! primary host) is away, messages are appended to segment files of records
//! (`mbtap_publish::spool`); when it is back, they are forwarded oldest first and each segment is
//! deleted once all its records are handed to the connection.
//!
//! Bounded by `--mqtt-buffer-max`: beyond it the oldest segment goes, its records counted as
//! dropped and said. Durability: appends are flushed to the file at once and `fsync`ed at most
//! once a second and at the end — a power cut loses at most the last second of held messages,
//! and a record torn by it is skipped on reading, never the file. Forwarding is at least once:
//! a segment cut off mid-forward (the broker gone again, mbtap stopped) is forwarded whole next
//! time.

use std::fs::{File, OpenOptions};
use std::io::{Read as _, Write as _};
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use mbtap_publish::spool::{HEADER, Kind, MAX_BODY, encode_record, parse_records};
use nix::fcntl::OFlag;

/// A segment is closed and a new one begun beyond this size.
const SEGMENT_BYTES: u64 = 256 * 1024;
/// The largest segment mbtap writes: one record may start just below [`SEGMENT_BYTES`]. A file
/// larger than this is not one of ours (or was damaged): it is left where it is, never read whole.
const SEGMENT_LIMIT: u64 = SEGMENT_BYTES + (MAX_BODY + HEADER) as u64;
/// How often appended records are forced to the disk.
const SYNC_EVERY: Duration = Duration::from_secs(1);

/// One held record: its kind and body.
pub type Record = (Kind, Vec<u8>);

/// The on-disk buffer of one publisher.
#[derive(Debug)]
pub struct Spool {
    dir: PathBuf,
    max_bytes: u64,
    /// Segment numbers on disk, oldest first, with their sizes.
    segments: std::collections::VecDeque<(u64, u64)>,
    /// Their sizes' sum, kept as they change (asked on every append and forwarding turn).
    total: u64,
    /// The number the next new segment gets: above every numbered file in the directory, ours
    /// or not, so a file left aside is never appended to.
    next: u64,
    /// The segment being appended to (the newest), open.
    current: Option<File>,
    synced_at: Instant,
    unsynced: bool,
    /// Records dropped because the buffer was full (oldest first), since start.
    pub dropped: u64,
    /// Records skipped as torn or damaged when read back.
    pub damaged: u64,
    /// Segments left in place unread (not a regular file, too large, unreadable), since start.
    pub aside: u64,
    /// Messages that could not be written to the buffer (a full disk, a read-only directory).
    pub unwritable: u64,
    /// Why the last append failed, while appends fail (said once per streak).
    failing: Option<String>,
}

fn segment_path(dir: &Path, n: u64) -> PathBuf {
    dir.join(format!("{n:012}.spool"))
}

/// Opens a segment to read without following a link and without blocking on a FIFO
/// (`O_NOFOLLOW | O_NONBLOCK`), then insists on a regular file no larger than any segment
/// mbtap writes. The error says what the file is instead.
fn open_segment(path: &Path) -> Result<(File, u64), String> {
    let meta = std::fs::symlink_metadata(path).map_err(|e| format!("cannot be examined: {e}"))?;
    let kind = meta.file_type();
    if !kind.is_file() {
        let what = if kind.is_symlink() {
            "a symbolic link"
        } else if kind.is_dir() {
            "a directory"
        } else {
            "not a regular file (a FIFO, socket or device)"
        };
        return Err(format!("is {what}, not a segment mbtap wrote"));
    }
    let f = OpenOptions::new()
        .read(true)
        .custom_flags((OFlag::O_NOFOLLOW | OFlag::O_NONBLOCK).bits())
        .open(path)
        .map_err(|e| format!("cannot be read: {e}"))?;
    let meta = f.metadata().map_err(|e| format!("cannot be examined: {e}"))?;
    if !meta.is_file() {
        return Err("is not a regular file".into());
    }
    if meta.len() > SEGMENT_LIMIT {
        return Err(format!(
            "holds {} bytes, more than any segment mbtap writes ({SEGMENT_LIMIT}): not read",
            meta.len()
        ));
    }
    Ok((f, meta.len()))
}

/// A segment's bytes, at most [`SEGMENT_LIMIT`] of them whatever the file does meanwhile.
fn read_segment(path: &Path) -> Result<Vec<u8>, String> {
    let (f, len) = open_segment(path)?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    f.take(SEGMENT_LIMIT + 1).read_to_end(&mut bytes).map_err(|e| format!("cannot be read: {e}"))?;
    if bytes.len() as u64 > SEGMENT_LIMIT {
        return Err(format!("grew past {SEGMENT_LIMIT} bytes while read: not one mbtap writes"));
    }
    Ok(bytes)
}

impl Spool {
    /// Opens (creating) the buffer in `dir`, keeping what an earlier run left there. Numbered
    /// files that are not segments mbtap can read (links, directories, FIFOs, files too large or
    /// unreadable) are said and left in place: never read, never deleted.
    ///
    /// # Errors
    /// The directory cannot be made or read.
    pub fn open(dir: &Path, max_bytes: u64) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("--mqtt-buffer {}: cannot create it", dir.display()))?;
        let mut segments = Vec::new();
        let (mut next, mut aside) = (1, 0);
        for e in std::fs::read_dir(dir).with_context(|| format!("--mqtt-buffer {}: cannot read it", dir.display()))? {
            let e = e?;
            let name = e.file_name();
            let Some(n) = name.to_str().and_then(|n| n.strip_suffix(".spool")).and_then(|n| n.parse::<u64>().ok())
            else {
                continue;
            };
            next = next.max(n.saturating_add(1));
            match open_segment(&e.path()) {
                Ok((_, len)) => segments.push((n, len)),
                Err(why) => {
                    aside += 1;
                    eprintln!(
                        "mbtap: mqtt: {} skipped: it {why}; left in place, not forwarded (move it away or remove it)",
                        e.path().display()
                    );
                }
            }
        }
        segments.sort_unstable();
        Ok(Self {
            dir: dir.to_owned(),
            max_bytes: max_bytes.max(SEGMENT_BYTES),
            total: segments.iter().map(|(_, b)| b).sum(),
            segments: segments.into(),
            next,
            current: None,
            synced_at: Instant::now(),
            unsynced: false,
            dropped: 0,
            damaged: 0,
            aside,
            unwritable: 0,
            failing: None,
        })
    }

    /// Bytes held.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        self.total
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.bytes() == 0
    }

    /// Why appends fail now (a full disk: "No space left on device"), if they do.
    #[must_use]
    pub fn failing(&self) -> Option<&str> {
        self.failing.as_deref()
    }

    /// Appends one record; makes room by dropping the oldest segments when full.
    ///
    /// # Errors
    /// Writing failed (a full disk): said once while it lasts, counted in
    /// [`Self::unwritable`]; the caller counts the message as dropped.
    pub fn append(&mut self, kind: Kind, body: &[u8]) -> std::io::Result<()> {
        match self.try_append(kind, body) {
            Ok(()) => {
                if self.failing.take().is_some() {
                    eprintln!("mbtap: mqtt: the buffer in {} is writable again", self.dir.display());
                }
                Ok(())
            }
            Err(e) => {
                self.unwritable += 1;
                if self.failing.is_none() {
                    eprintln!(
                        "mbtap: mqtt: the buffer in {} cannot be written: {e}; messages are dropped (counted) until it can",
                        self.dir.display()
                    );
                    self.failing = Some(e.to_string());
                }
                Err(e)
            }
        }
    }

    fn try_append(&mut self, kind: Kind, body: &[u8]) -> std::io::Result<()> {
        let mut rec = Vec::with_capacity(body.len() + HEADER);
        if !encode_record(kind, body, &mut rec) {
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "a message too long to hold"));
        }
        let need_new = self.current.is_none() || self.segments.back().is_none_or(|(_, b)| *b >= SEGMENT_BYTES);
        if need_new {
            self.sync();
            self.current = None;
            // A new file only (O_EXCL): a name someone placed is passed over, never written through.
            let f = loop {
                let n = self.next;
                self.next = n.saturating_add(1);
                match OpenOptions::new().append(true).create_new(true).open(segment_path(&self.dir, n)) {
                    Ok(f) => {
                        self.segments.push_back((n, 0));
                        break f;
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                    Err(e) => return Err(e),
                }
            };
            self.current = Some(f);
        }
        let rec_len = rec.len() as u64;
        if let Some(f) = self.current.as_mut() {
            f.write_all(&rec)?;
        }
        if let Some((_, b)) = self.segments.back_mut() {
            *b += rec_len;
        }
        self.total += rec_len;
        self.unsynced = true;
        while self.total > self.max_bytes && self.segments.len() > 1 {
            let Some((n, size)) = self.segments.pop_front() else { break };
            self.total -= size;
            let path = segment_path(&self.dir, n);
            match read_segment(&path) {
                Ok(bytes) => {
                    let lost = parse_records(&bytes).records.len() as u64;
                    let _ = std::fs::remove_file(&path);
                    self.dropped += lost;
                    eprintln!(
                        "mbtap: mqtt: the buffer in {} is full ({} bytes): the oldest {lost} held messages dropped ({} so far)",
                        self.dir.display(),
                        self.max_bytes,
                        self.dropped
                    );
                }
                Err(why) => self.set_aside(&path, &why),
            }
        }
        if self.synced_at.elapsed() >= SYNC_EVERY {
            self.sync();
        }
        Ok(())
    }

    fn set_aside(&mut self, path: &Path, why: &str) {
        self.aside += 1;
        eprintln!(
            "mbtap: mqtt: {} skipped: it {why}; left in place, not forwarded (move it away or remove it)",
            path.display()
        );
    }

    /// Forces what was appended to the disk.
    pub fn sync(&mut self) {
        if self.unsynced
            && let Some(f) = self.current.as_ref()
        {
            let _ = f.sync_data();
        }
        self.unsynced = false;
        self.synced_at = Instant::now();
    }

    /// The oldest segment's records, to forward: (its number, records). The segment being
    /// appended to is closed first, so new records go to a fresh one. A segment that cannot be
    /// read (it changed since start: permissions, a link, a FIFO) is said and left in place,
    /// and the next one taken.
    pub fn oldest(&mut self) -> Option<(u64, Vec<Record>)> {
        loop {
            let &(n, size) = self.segments.front()?;
            if self.segments.len() == 1 {
                self.sync();
                self.current = None;
            }
            let path = segment_path(&self.dir, n);
            let bytes = match read_segment(&path) {
                Ok(b) => b,
                Err(why) => {
                    self.segments.pop_front();
                    self.total -= size;
                    self.set_aside(&path, &why);
                    continue;
                }
            };
            let parsed = parse_records(&bytes);
            let skipped = parsed.damaged.len() as u64 + u64::from(parsed.torn_at.is_some());
            if skipped > 0 {
                self.damaged += skipped;
                eprintln!(
                    "mbtap: mqtt: {}: {skipped} torn or damaged record(s) skipped, the rest forwarded",
                    path.display()
                );
            }
            return Some((n, parsed.records.into_iter().map(|(k, b)| (k, b.to_vec())).collect()));
        }
    }

    /// A segment was forwarded whole: removed.
    pub fn forwarded(&mut self, n: u64) {
        let gone: u64 = self.segments.iter().filter(|(s, _)| *s == n).map(|(_, b)| b).sum();
        self.segments.retain(|(s, _)| *s != n);
        self.total -= gone;
        let _ = std::fs::remove_file(segment_path(&self.dir, n));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::FileTypeExt as _;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("mbtap-spool-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn held_messages_survive_a_restart_in_order() {
        let d = tmp("restart");
        let mut s = Spool::open(&d, 1 << 20).unwrap();
        for i in 0..100u32 {
            s.append(Kind::Mqtt, &i.to_le_bytes()).unwrap();
        }
        drop(s);
        let mut s = Spool::open(&d, 1 << 20).unwrap();
        let (n, recs) = s.oldest().unwrap();
        assert_eq!(recs.len(), 100);
        assert_eq!(recs[99].1, 99u32.to_le_bytes());
        s.forwarded(n);
        assert!(s.is_empty());
        assert!(s.oldest().is_none());
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A full buffer drops the oldest and says how many.
    #[test]
    fn a_full_buffer_drops_the_oldest_segments_and_counts_them() {
        let d = tmp("full");
        let mut s = Spool::open(&d, SEGMENT_BYTES * 2).unwrap();
        let body = vec![7u8; 1000];
        for _ in 0..1000 {
            s.append(Kind::Mqtt, &body).unwrap();
        }
        assert!(s.bytes() <= SEGMENT_BYTES * 2 + 1012, "{}", s.bytes());
        assert!(s.dropped > 0);
        let mut kept = 0u64;
        while let Some((n, recs)) = s.oldest() {
            kept += recs.len() as u64;
            s.forwarded(n);
        }
        assert_eq!(kept + s.dropped, 1000, "every message either kept or counted as dropped");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A power cut mid-append costs the torn record only.
    #[test]
    fn a_torn_tail_costs_one_record() {
        let d = tmp("torn");
        let mut s = Spool::open(&d, 1 << 20).unwrap();
        for i in 0..10u8 {
            s.append(Kind::Mqtt, &[i; 40]).unwrap();
        }
        drop(s);
        let path = segment_path(&d, 1);
        let len = std::fs::metadata(&path).unwrap().len();
        OpenOptions::new().write(true).open(&path).unwrap().set_len(len - 7).unwrap();
        let mut s = Spool::open(&d, 1 << 20).unwrap();
        let (_, recs) = s.oldest().unwrap();
        assert_eq!(recs.len(), 9);
        assert_eq!(s.damaged, 1);
        let _ = std::fs::remove_dir_all(&d);
    }

    /// Fills `d` with three segments of 10 records each (numbers 1–3), closed.
    fn three_segments(d: &Path) {
        let mut s = Spool::open(d, 1 << 30).unwrap();
        for seg in 0..3u8 {
            for i in 0..10u8 {
                s.append(Kind::Mqtt, &[seg, i]).unwrap();
            }
            s.current = None;
            if let Some((_, b)) = s.segments.back_mut() {
                *b = SEGMENT_BYTES;
            }
        }
    }

    /// A FIFO, a directory, a symbolic link and a file larger than any segment in the
    /// buffer are said and left in place — never opened for reading (a FIFO would block
    /// forwarding for good), never deleted (a 64 GiB sparse file is not "0 messages"), never
    /// written through; the other segments are forwarded and new ones numbered above them.
    #[test]
    fn what_is_not_a_segment_is_left_in_place_and_the_rest_forwarded() {
        let d = tmp("aside");
        three_segments(&d);
        let (fifo, dir, link, big) =
            (segment_path(&d, 4), segment_path(&d, 5), segment_path(&d, 6), segment_path(&d, 1));
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        std::fs::create_dir(&dir).unwrap();
        let decoy = d.join("decoy");
        std::fs::write(&decoy, b"keep").unwrap();
        std::os::unix::fs::symlink(&decoy, &link).unwrap();
        // Segment 1 made a sparse file of 64 GiB, its records still at the start.
        OpenOptions::new().write(true).open(&big).unwrap().set_len(64 << 30).unwrap();
        let mut s = Spool::open(&d, 1 << 30).unwrap();
        assert_eq!(s.aside, 4);
        let mut forwarded = 0;
        while let Some((n, recs)) = s.oldest() {
            forwarded += recs.len();
            s.forwarded(n);
        }
        assert_eq!(forwarded, 20, "segments 2 and 3");
        s.append(Kind::Mqtt, b"new").unwrap();
        assert!(segment_path(&d, 7).exists(), "numbered above every file there");
        for p in [&fifo, &dir, &link, &big] {
            assert!(std::fs::symlink_metadata(p).is_ok(), "{} removed", p.display());
        }
        assert_eq!(std::fs::read(&decoy).unwrap(), b"keep");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A segment that becomes unreadable after start (a FIFO put in its place) is
    /// passed over when its turn comes, not read, not deleted.
    #[test]
    fn a_segment_replaced_while_running_is_set_aside_not_deleted() {
        let d = tmp("replaced");
        three_segments(&d);
        let mut s = Spool::open(&d, 1 << 30).unwrap();
        let first = segment_path(&d, 1);
        std::fs::remove_file(&first).unwrap();
        nix::unistd::mkfifo(&first, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let (n, recs) = s.oldest().unwrap();
        assert_eq!((n, recs.len(), s.aside), (2, 10, 1));
        assert!(std::fs::symlink_metadata(&first).unwrap().file_type().is_fifo());
        let _ = std::fs::remove_dir_all(&d);
    }

    /// An append that cannot be written says why (a full disk said as such, not "queue
    /// full or broker away") and counts it.
    #[test]
    fn a_failed_append_is_said_with_its_cause_and_counted() {
        let d = tmp("unwritable");
        let mut s = Spool::open(&d, 1 << 30).unwrap();
        std::fs::remove_dir_all(&d).unwrap();
        // The directory gone: the new segment cannot be created.
        assert!(s.append(Kind::Mqtt, b"x").is_err());
        assert!(s.append(Kind::Mqtt, b"y").is_err());
        assert_eq!(s.unwritable, 2);
        assert!(s.failing().is_some_and(|w| w.contains("No such file")), "{:?}", s.failing());
    }
}
