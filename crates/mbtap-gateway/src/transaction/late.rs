//! After a timeout, what a unit says late: listened for and dropped (bounded by a
//! window, by the silence after the last late byte, and by the longest answer's length); and the
//! transceiver's turnaround glitch before an answer.

use super::MasterConfig;
use mbtap_proto::serial_line::LineSettings;
use mbtap_proto::serial_line::SerialMode;
use std::time::Duration;

/// After a timeout: listens up to the window for what the unit says late, ending
/// at the silence after the last late byte; noise that never stops cannot hold the line longer
/// than twice the window, and more bytes than the longest answer without a silence are no late
/// answer but garbage: the listening ends there (a serial server streaming garbage
/// held its line 2 s after every timeout, and its clients waited 4 s for their 0x0B).
#[derive(Debug, Clone)]
pub struct LateListener {
    start: Duration,
    until: Duration,
    hard_stop: Duration,
    silence: Duration,
    last: Option<Duration>,
    /// When the first late byte came (meaningful once `last` is set).
    first_at: Duration,
    heard: usize,
    max_adu: usize,
}

impl LateListener {
    /// Starts listening at `now` for up to `window` (the caller bounds it: the bridge's line to
    /// 1 s, so a slow unit costs the other clients little; mbtap's own master to its timeout).
    #[must_use]
    pub fn new(config: &MasterConfig, window: Duration, now: Duration) -> Self {
        Self::on_line(config.line, config.mode, config.latency, window, now)
    }

    /// As [`Self::new`], for a master that knows only its line, its mode and how late its
    /// adapter may deliver a byte (mbtap's own `read`/`watch`).
    #[must_use]
    pub fn on_line(line: LineSettings, mode: SerialMode, latency: Duration, window: Duration, now: Duration) -> Self {
        let silence = Duration::from_nanos(line.t35_ns()) + Duration::from_millis(1) + latency;
        Self {
            start: now,
            until: now + window,
            hard_stop: now + window * 2,
            silence,
            last: None,
            first_at: now,
            heard: 0,
            max_adu: super::steps::max_adu(mode),
        }
    }

    /// Read until this time; at it, stop.
    #[must_use]
    pub fn wait_until(&self) -> Duration {
        if self.garbage() {
            return self.last.unwrap_or(self.start);
        }
        self.last.map_or(self.until, |t| (t + self.silence).min(self.hard_stop))
    }

    /// `n` bytes arrived at `now`; true for the first late bytes (one late answer, counted once).
    pub fn bytes(&mut self, now: Duration, n: usize) -> bool {
        let first = self.last.is_none();
        if first {
            self.first_at = now;
        }
        self.last = Some(now);
        self.heard = self.heard.saturating_add(n);
        first
    }

    /// More bytes than the longest answer: not a late answer, and listening on is pointless.
    #[must_use]
    pub fn garbage(&self) -> bool {
        self.heard > self.max_adu
    }

    /// When the first late byte came, if one did.
    #[must_use]
    pub fn first(&self) -> Option<Duration> {
        self.last.map(|_| self.first_at)
    }

    /// When the line was last busy.
    #[must_use]
    pub fn last(&self) -> Duration {
        self.last.unwrap_or(self.start)
    }
}

/// Whether `buf` starts with a turnaround glitch before the awaited unit's answer: a byte a
/// transceiver leaves when it switches (00, FE, FF), not the unit's address, followed by it.
#[must_use]
pub fn turnaround_glitch(buf: &[u8], unit: u8) -> bool {
    matches!(buf, [g @ (0x00 | 0xFE | 0xFF), u, ..] if *g != unit && *u == unit)
}
