//! Progress of reading a capture file on a terminal: bytes read, rate and time left, redrawn
//! in place on stderr four times a second. Never on a pipe (stderr not a terminal), never
//! under the TUI (the caller says), and only once the work has run a second: short work stays
//! quiet. `replay`, `report`, `export` and `play` share it.
//!
//! Why not `indicatif`: one line redrawn with `\r` is all this needs; see the README's
//! "Dependencies".

use std::fs::File;
use std::io::{IsTerminal, Read, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;

/// Whether a progress line is on the screen (warnings clear it before they print).
static SHOWN: AtomicBool = AtomicBool::new(false);

/// How often the line is redrawn.
const EVERY: Duration = Duration::from_millis(250);

/// A file reader that shows how far it has read.
#[derive(Debug)]
pub struct Progress<R> {
    inner: R,
    name: String,
    total: u64,
    read: u64,
    started: Instant,
    next: Instant,
    enabled: bool,
}

/// Opens a capture; `show` is false under the TUI. The line appears only on a terminal and
/// after `MBTAP_PROGRESS_AFTER_MS` (default 1000) ms.
///
/// # Errors
/// When the file cannot be opened.
pub fn open_capture(path: &Path, show: bool) -> anyhow::Result<Progress<File>> {
    let file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let total = file.metadata().map_or(0, |m| m.len());
    let after = std::env::var("MBTAP_PROGRESS_AFTER_MS").ok().and_then(|v| v.parse().ok()).unwrap_or(1000);
    let started = Instant::now();
    Ok(Progress {
        inner: file,
        name: path.display().to_string(),
        total,
        read: 0,
        started,
        next: started + Duration::from_millis(after),
        enabled: show && std::io::stderr().is_terminal() && total > 0,
    })
}

/// Clears the progress line, if one is shown, so a message prints on a line of its own.
pub fn clear_line() {
    if SHOWN.swap(false, Ordering::Relaxed) {
        eprint!("\r\x1b[K");
    }
}

/// The progress line for `read` of `total` bytes after `elapsed`.
#[must_use]
pub fn line(name: &str, read: u64, total: u64, elapsed: Duration) -> String {
    let mib = |b: u64| b / (1 << 20);
    let pct = read.saturating_mul(100).checked_div(total).unwrap_or(0).min(100);
    let ms = u64::try_from(elapsed.as_millis()).unwrap_or(u64::MAX).max(1);
    // Bytes per second, and the seconds left at that rate.
    let rate = read.saturating_mul(1000) / ms;
    let left = total.saturating_sub(read).checked_div(rate).map_or_else(|| "?".to_owned(), |s| s.to_string());
    format!("mbtap: reading {name}: {} of {} MiB ({pct} %), {} MiB/s, {left} s left", mib(read), mib(total), mib(rate))
}

impl<R: Read> Read for Progress<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read = self.read.saturating_add(n as u64);
        if self.enabled {
            let now = Instant::now();
            if now >= self.next {
                self.next = now + EVERY;
                let text = line(&self.name, self.read, self.total, now - self.started);
                let mut err = std::io::stderr().lock();
                let _ = write!(err, "\r\x1b[K{text}");
                let _ = err.flush();
                SHOWN.store(true, Ordering::Relaxed);
            }
        }
        Ok(n)
    }
}

impl<R> Drop for Progress<R> {
    fn drop(&mut self) {
        clear_line();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_says_how_far_how_fast_and_how_long() {
        let l = line("big.pcapng", 50 << 20, 200 << 20, Duration::from_secs(2));
        assert_eq!(l, "mbtap: reading big.pcapng: 50 of 200 MiB (25 %), 25 MiB/s, 6 s left");
        // Nothing read yet: no rate, no estimate; no division by zero anywhere.
        assert_eq!(line("x", 0, 0, Duration::ZERO), "mbtap: reading x: 0 of 0 MiB (0 %), 0 MiB/s, ? s left");
    }
}
