//! Observation models: how a program reading a serial port sees the wire. Each turns the
//! per-byte timeline into chunks (bytes + the time the read returned), as real hardware does.

use super::generate::Wire;

/// How bytes reach the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Observation {
    /// Every byte its own read, at the time its stop bit ended.
    PerByte,
    /// Every byte its own read, returned up to `jitter_ns` after its stop bit ended (a program
    /// reading byte by byte on a busy machine: each wake-up late by its own amount), never
    /// before the read of the byte before it.
    PerByteJitter { jitter_ns: u64 },
    /// One packet per frame (or noise burst), at its end: what gap-cutting sniffers write.
    PerFrame,
    /// 16550-style FIFO: a read when `trigger` bytes are waiting, or after `timeout_chars`
    /// character times without a new byte.
    Fifo { trigger: usize, timeout_chars: u64 },
    /// USB-serial adapter (FTDI-like): bytes are held until the latency timer expires or
    /// `max` bytes are buffered.
    Usb { latency_ns: u64, max: usize },
}

impl Observation {
    /// Byte by byte, up to 0.2 ms late: a per-byte capture.
    pub const PER_BYTE_JITTER: Self = Self::PerByteJitter { jitter_ns: 200_000 };
    /// The 16550's common setting: 14-byte trigger, 4-character timeout.
    pub const FIFO_16550: Self = Self::Fifo { trigger: 14, timeout_chars: 4 };
    /// FTDI with a 1 ms latency timer.
    pub const USB_1MS: Self = Self::Usb { latency_ns: 1_000_000, max: 62 };
    /// FTDI at its default 16 ms latency timer.
    pub const USB_16MS: Self = Self::Usb { latency_ns: 16_000_000, max: 62 };

    /// A short name for tables.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::PerByte => "per-byte timestamps",
            Self::PerByteJitter { .. } => "per-byte reads, up to 0.2 ms late",
            Self::PerFrame => "one packet per frame",
            Self::Fifo { .. } => "16550 FIFO (14 B / 4 chars)",
            Self::Usb { latency_ns: 1_000_000, .. } => "USB latency 1 ms",
            Self::Usb { latency_ns: 16_000_000, .. } => "USB latency 16 ms",
            Self::Usb { .. } => "USB latency (custom)",
        }
    }

    /// The latency bound a framer should assume for this model.
    #[must_use]
    pub const fn latency_ns(self, char_ns: u64) -> u64 {
        match self {
            Self::PerByte | Self::PerFrame => 0,
            Self::PerByteJitter { jitter_ns } => jitter_ns,
            Self::Fifo { timeout_chars, .. } => timeout_chars * char_ns,
            Self::Usb { latency_ns, .. } => latency_ns,
        }
    }
}

/// A chunk with owned bytes: (read time ns, byte range in the wire).
pub type ChunkSpan = (u64, std::ops::Range<usize>);

/// Splits the wire into reads as `model` delivers them.
#[must_use]
pub fn observe(wire: &Wire, model: Observation, char_ns: u64) -> Vec<ChunkSpan> {
    let n = wire.bytes.len();
    let mut out = Vec::new();
    let mut start = 0;
    match model {
        Observation::PerByte => {
            out.extend((0..n).map(|i| (wire.end_ns[i], i..i + 1)));
        }
        Observation::PerByteJitter { jitter_ns } => {
            let mut last = 0;
            for i in 0..n {
                // A fixed pseudo-random delay per byte (splitmix64 of its index): the same wire
                // gives the same reads.
                let mut z = (i as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                z ^= z >> 31;
                let t = (wire.end_ns[i] + z % jitter_ns.max(1)).max(last);
                last = t;
                out.push((t, i..i + 1));
            }
        }
        Observation::PerFrame => {
            out.extend(wire.truth.iter().map(|t| (wire.end_ns[t.end - 1], t.start..t.end)));
            let _ = start;
        }
        Observation::Fifo { trigger, timeout_chars } => {
            let timeout = timeout_chars * char_ns;
            for i in 0..n {
                let next_gap = wire.end_ns.get(i + 1).map(|&t| t - wire.end_ns[i]);
                if i + 1 - start >= trigger {
                    out.push((wire.end_ns[i], start..i + 1));
                    start = i + 1;
                } else if next_gap.is_none_or(|g| g >= timeout + char_ns) {
                    out.push((wire.end_ns[i] + timeout, start..i + 1));
                    start = i + 1;
                }
            }
        }
        Observation::Usb { latency_ns, max } => {
            // The timer starts with the first byte in an empty buffer.
            let mut deadline = 0;
            for i in 0..n {
                if i == start {
                    deadline = wire.end_ns[i] + latency_ns;
                }
                let next = wire.end_ns.get(i + 1).copied();
                if i + 1 - start >= max {
                    out.push((wire.end_ns[i], start..i + 1));
                    start = i + 1;
                } else if next.is_none_or(|t| t > deadline) {
                    out.push((deadline, start..i + 1));
                    start = i + 1;
                }
            }
        }
    }
    out
}
