//! Store-and-forward on disk (`--mqtt-buffer [DIR]`): while the broker (or the Sparkplug
//! primary host) is away, messages are appended to segment files of records
//! (`mbtap_core::spool`); when it is back, they are forwarded oldest first and each segment is
//! deleted once all its records are handed to the connection.
//!
//! Bounded by `--mqtt-buffer-max`: beyond it the oldest segment goes, its records counted as
//! dropped and said. Durability: appends are flushed to the file at once and `fsync`ed at most
//! once a second and at the end — a power cut loses at most the last second of held messages,
//! and a record torn by it is skipped on reading, never the file. Forwarding is at least once:
//! a segment cut off mid-forward (the broker gone again, mbtap stopped) is forwarded whole next
//! time.

use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use mbtap_core::spool::{Kind, encode_record, parse_records};

/// A segment is closed and a new one begun beyond this size.
const SEGMENT_BYTES: u64 = 256 * 1024;
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
    /// The segment being appended to (the newest), open.
    current: Option<File>,
    synced_at: Instant,
    unsynced: bool,
    /// Records dropped because the buffer was full (oldest first), since start.
    pub dropped: u64,
    /// Records skipped as torn or damaged when read back.
    pub damaged: u64,
}

fn segment_path(dir: &Path, n: u64) -> PathBuf {
    dir.join(format!("{n:012}.spool"))
}

impl Spool {
    /// Opens (creating) the buffer in `dir`, keeping what an earlier run left there.
    ///
    /// # Errors
    /// The directory cannot be made or read.
    pub fn open(dir: &Path, max_bytes: u64) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("--mqtt-buffer {}: cannot create it", dir.display()))?;
        let mut segments = Vec::new();
        for e in std::fs::read_dir(dir).with_context(|| format!("--mqtt-buffer {}: cannot read it", dir.display()))? {
            let e = e?;
            let name = e.file_name();
            let Some(n) = name.to_str().and_then(|n| n.strip_suffix(".spool")).and_then(|n| n.parse::<u64>().ok())
            else {
                continue;
            };
            segments.push((n, e.metadata().map_or(0, |m| m.len())));
        }
        segments.sort_unstable();
        Ok(Self {
            dir: dir.to_owned(),
            max_bytes: max_bytes.max(SEGMENT_BYTES),
            total: segments.iter().map(|(_, b)| b).sum(),
            segments: segments.into(),
            current: None,
            synced_at: Instant::now(),
            unsynced: false,
            dropped: 0,
            damaged: 0,
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

    /// Appends one record; makes room by dropping the oldest segments when full.
    ///
    /// # Errors
    /// Writing failed (a full disk): the caller counts the message as dropped.
    pub fn append(&mut self, kind: Kind, body: &[u8]) -> std::io::Result<()> {
        let mut rec = Vec::with_capacity(body.len() + mbtap_core::spool::HEADER);
        if !encode_record(kind, body, &mut rec) {
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "a message too long to hold"));
        }
        let need_new = self.current.is_none() || self.segments.back().is_none_or(|(_, b)| *b >= SEGMENT_BYTES);
        if need_new {
            self.sync();
            let n = self.segments.back().map_or(1, |(n, _)| n + 1);
            let f = OpenOptions::new().create(true).append(true).open(segment_path(&self.dir, n))?;
            self.segments.push_back((n, 0));
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
            let lost = std::fs::read(&path).map_or(0, |b| parse_records(&b).records.len() as u64);
            let _ = std::fs::remove_file(&path);
            self.dropped += lost;
            eprintln!(
                "mbtap: mqtt: the buffer in {} is full ({} bytes): the oldest {lost} held messages dropped ({} so far)",
                self.dir.display(),
                self.max_bytes,
                self.dropped
            );
        }
        if self.synced_at.elapsed() >= SYNC_EVERY {
            self.sync();
        }
        Ok(())
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
    /// appended to is closed first, so new records go to a fresh one.
    pub fn oldest(&mut self) -> Option<(u64, Vec<Record>)> {
        let &(n, _) = self.segments.front()?;
        if self.segments.len() == 1 {
            self.sync();
            self.current = None;
        }
        let bytes = std::fs::read(segment_path(&self.dir, n)).unwrap_or_default();
        let parsed = parse_records(&bytes);
        let skipped = parsed.damaged.len() as u64 + u64::from(parsed.torn_at.is_some());
        if skipped > 0 {
            self.damaged += skipped;
            eprintln!(
                "mbtap: mqtt: {}: {skipped} torn or damaged record(s) skipped, the rest forwarded",
                segment_path(&self.dir, n).display()
            );
        }
        Some((n, parsed.records.into_iter().map(|(k, b)| (k, b.to_vec())).collect()))
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

    /// Issue 30: a full buffer drops the oldest and says how many.
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

    /// Issue 30: a power cut mid-append costs the torn record only.
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
}
