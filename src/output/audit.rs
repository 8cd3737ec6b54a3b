//! `--audit FILE`: one JSON line per request that may change a device, with who asked, what,
//! and how it ended ([`mbtap_gateway::audit`] says which requests and in which words). Written
//! by a thread of its own: the line hands a record over and goes on — a slow or full disk never
//! holds a request back; what cannot be queued or written is counted, and said. Each batch is
//! appended and synced (`fdatasync`) before the next; past `--audit-max-bytes` the file is
//! rotated (`FILE.1` … `FILE.3`, the oldest dropped).

use std::io::Write as _;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context as _;
use mbtap_gateway::audit::Change;

/// Records waiting for the disk: a burst of writes larger than this on a stalled disk loses the
/// excess, counted, rather than memory or the line's time.
const QUEUED: usize = 4096;
/// Rotated files kept beside the current one.
const KEPT: u32 = 3;
/// How often a disk that keeps failing is mentioned.
const SAY_EVERY: Duration = Duration::from_mins(1);

/// `--audit FILE` and its rotation size, for `bridge` and `simulate`.
#[derive(Debug, Clone, clap::Args)]
pub struct AuditArgs {
    /// Record every request that may change a device (writes 05, 06, 0F, 10, 16, 17; diagnostics
    /// that restart or silence it; functions not known to be harmless; the broker's writes), one
    /// JSON line each: time, client (transport, address, TLS or broker role), unit, function,
    /// address, quantity, values, and how it ended (done, exception N, timeout, refused and why).
    /// Reads are not recorded. Appended and synced; a slow or full disk never holds a request
    /// back (what could not be written is counted: `mbtap_bridge_audit_lost_total`, and said).
    #[arg(long, value_name = "FILE")]
    pub audit: Option<PathBuf>,
    /// Rotate the audit file past this size (`FILE.1` … `FILE.3` kept), bytes.
    #[arg(long, value_name = "BYTES", default_value_t = 16 << 20, value_parser = clap::value_parser!(u64).range(4096..), requires = "audit")]
    pub audit_max_bytes: u64,
}

impl AuditArgs {
    /// The audit log, when asked for.
    ///
    /// # Errors
    /// The file cannot be opened for appending.
    pub fn open(&self) -> anyhow::Result<Option<std::sync::Arc<Audit>>> {
        self.audit.as_deref().map(|p| Audit::open(p, self.audit_max_bytes)).transpose()
    }
}

/// Who asked: the transport, the peer's address where it has one, and its TLS role (or the
/// broker's `--mqtt-role`).
#[derive(Debug, Clone, Default)]
pub struct Who {
    pub transport: &'static str,
    pub address: Option<SocketAddr>,
    pub role: Option<String>,
}

impl Who {
    /// As the audit's lines and the web view's clients name it.
    #[must_use]
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "transport": self.transport,
            "address": self.address.map(|a| a.to_string()),
            "role": self.role,
        })
    }
}

/// The audit log's writer.
#[derive(Debug)]
pub struct Audit {
    path: PathBuf,
    tx: SyncSender<String>,
    /// Records handed over, and those lost (queue full or not written).
    pub records: AtomicU64,
    pub lost: std::sync::Arc<AtomicU64>,
}

impl Audit {
    /// Opens (creates, appending) `path` and starts its writer; a file that cannot be opened
    /// stops the start, named.
    ///
    /// # Errors
    /// The file cannot be created or opened for appending.
    pub fn open(path: &Path, max_bytes: u64) -> anyhow::Result<std::sync::Arc<Self>> {
        let file = open_append(path).with_context(|| {
            format!("--audit {}: cannot open it for appending (a link there is not followed)", path.display())
        })?;
        let (tx, rx) = sync_channel(QUEUED);
        let lost = std::sync::Arc::new(AtomicU64::new(0));
        let writer = Writer { path: path.to_owned(), file, max_bytes, lost: std::sync::Arc::clone(&lost), said: None };
        std::thread::Builder::new()
            .name("audit".into())
            .spawn(move || writer.run(&rx))
            .context("--audit: starting its writer")?;
        Ok(std::sync::Arc::new(Self { path: path.to_owned(), tx, records: AtomicU64::new(0), lost }))
    }

    /// Records one request: who, the unit, what it changes, how it ended. Never blocks.
    pub fn record(&self, who: &Who, unit: u8, change: &Change, outcome: &str) {
        let now = now_rfc3339();
        let line = serde_json::json!({
            "time": now,
            "client": who.json(),
            "unit": unit,
            "function": change.function,
            "what": change.what,
            "address": change.address,
            "quantity": change.quantity,
            "values": change.values,
            "outcome": outcome,
        })
        .to_string();
        self.queue(line);
    }

    /// Records a value set by name from the broker (`simulate --values-from`): no Modbus
    /// request, the `NAME=VALUE` asked and how it ended.
    pub fn record_set(&self, who: &Who, unit: u8, item: &str, outcome: &str) {
        let now = now_rfc3339();
        let line = serde_json::json!({
            "time": now,
            "client": who.json(),
            "unit": unit,
            "set": item,
            "outcome": outcome,
        })
        .to_string();
        self.queue(line);
    }

    fn queue(&self, line: String) {
        self.records.fetch_add(1, Ordering::Relaxed);
        if self.tx.try_send(line).is_err() {
            self.lost.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Where it writes.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }
}

fn open_append(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt as _;
    std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .mode(0o640)
        .custom_flags(nix::fcntl::OFlag::O_NOFOLLOW.bits())
        .open(path)
}

struct Writer {
    path: PathBuf,
    file: std::fs::File,
    max_bytes: u64,
    lost: std::sync::Arc<AtomicU64>,
    said: Option<Instant>,
}

impl Writer {
    fn run(mut self, rx: &Receiver<String>) {
        while let Ok(first) = rx.recv() {
            let mut batch = vec![first];
            batch.extend(rx.try_iter().take(255));
            let mut written = 0u64;
            let mut failed: Option<std::io::Error> = None;
            for line in &batch {
                match self.file.write_all(line.as_bytes()).and_then(|()| self.file.write_all(b"\n")) {
                    Ok(()) => written += 1,
                    Err(e) => {
                        failed.get_or_insert(e);
                    }
                }
            }
            if let Err(e) = self.file.sync_data() {
                failed.get_or_insert(e);
            }
            let lost = u64::try_from(batch.len()).unwrap_or(u64::MAX) - written;
            if lost > 0 {
                self.lost.fetch_add(lost, Ordering::Relaxed);
            }
            if let Some(e) = failed
                && self.said.is_none_or(|t| t.elapsed() >= SAY_EVERY)
            {
                eprintln!(
                    "mbtap: --audit {}: cannot write ({e}); {} record(s) lost so far (mbtap_bridge_audit_lost_total)",
                    self.path.display(),
                    self.lost.load(Ordering::Relaxed)
                );
                self.said = Some(Instant::now());
            }
            if self.file.metadata().is_ok_and(|m| m.len() >= self.max_bytes) {
                self.rotate();
            }
        }
    }

    /// `FILE` → `FILE.1` → … → `FILE.KEPT` (dropped), and a new `FILE`.
    fn rotate(&mut self) {
        let numbered = |n: u32| PathBuf::from(format!("{}.{n}", self.path.display()));
        for n in (1..KEPT).rev() {
            let _ = std::fs::rename(numbered(n), numbered(n + 1));
        }
        let _ = std::fs::rename(&self.path, numbered(1));
        match open_append(&self.path) {
            Ok(f) => self.file = f,
            Err(e) => eprintln!("mbtap: --audit {}: cannot open a new file after rotating ({e})", self.path.display()),
        }
    }
}

/// The clock's time now, as [`rfc3339`] writes it.
fn now_rfc3339() -> String {
    let (secs, nanos) =
        SystemTime::now().duration_since(UNIX_EPOCH).map_or((0, 0), |d| (d.as_secs(), d.subsec_nanos()));
    rfc3339(secs, nanos)
}

/// Seconds and nanoseconds since 1970 as RFC 3339 UTC (`2026-12-07T05:20:34.123456Z`).
#[must_use]
pub fn rfc3339(secs: u64, nanos: u32) -> String {
    let rem = secs % 86_400;
    let (year, month, day) = mbtap_analysis::report::format::civil_date(i64::try_from(secs / 86_400).unwrap_or(0));
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:06}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        nanos / 1000
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Past the size given, the file moves to `FILE.1` and a new one starts: every record is
    /// in one of them, none twice.
    #[test]
    fn the_file_is_rotated_by_size_and_nothing_is_lost() {
        let dir = std::env::temp_dir().join(format!("mbtap-audit-rotate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("audit.jsonl");
        let audit = Audit::open(&path, 4096).unwrap();
        let change = mbtap_gateway::audit::change(&[0x06, 0x00, 0x64, 0x00, 0x05]).unwrap();
        let who = Who { transport: "tcp", address: "192.0.2.9:50000".parse().ok(), role: None };
        for _ in 0..60 {
            audit.record(&who, 1, &change, "done");
        }
        let count = |p: &Path| std::fs::read_to_string(p).map_or(0, |t| t.lines().count());
        let numbered = |n: u32| PathBuf::from(format!("{}.{n}", path.display()));
        let all = || count(&path) + (1..=KEPT).map(|n| count(&numbered(n))).sum::<usize>();
        let start = Instant::now();
        while all() < 60 && start.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(20));
        }
        assert_eq!(all(), 60);
        assert!(count(&numbered(1)) > 0, "rotated");
        assert_eq!(audit.lost.load(Ordering::Relaxed), 0);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn times_are_rfc3339_utc() {
        assert_eq!(rfc3339(0, 0), "1970-01-01T00:00:00.000000Z");
        // 2026-12-07 05:20:34 UTC, and a leap day.
        assert_eq!(rfc3339(1_796_620_834, 123_456_000), "2026-12-07T05:20:34.123456Z");
        assert_eq!(rfc3339(951_782_400, 0), "2000-02-29T00:00:00.000000Z");
    }
}
