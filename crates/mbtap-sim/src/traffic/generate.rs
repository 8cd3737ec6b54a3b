//! Synthetic bus traffic with ground truth: a master polling several slaves with a varied mix of
//! function codes, exceptions, broadcasts, absent slaves and a vendor code; with noise bursts,
//! corrupted bytes and slow slaves that leave gaps inside responses; and the physics of real
//! RS-485 lines that our own framer would otherwise never meet: turnaround glitches (a garbage
//! byte within a character of a frame's end, where a transceiver's driver switches off without
//! fail-safe biasing: `00` with a framing error after the master, `FE`/`FF` after a slave) and
//! CRC look-alikes (answers whose CRC high byte is `00`, so one byte shorter also passes the
//! CRC). The output is the wire: every byte with the time its last bit left, plus what each
//! stretch of bytes really was.
//!
//! Its `pdus` module holds what the generated master asks and its slaves answer.

use super::rng::Rng;
use mbtap_analysis::framer::LineSettings;
use mbtap_proto::{Request, encode_rtu};

mod pdus;
use pdus::{crc_tail_zero, make_lookalike, transaction, vendor_pdus};

/// What a stretch of wire bytes really was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TruthKind {
    /// A frame sent intact.
    Good,
    /// A frame with at least one byte changed on the way.
    Corrupted,
    /// Bytes that belong to no frame.
    Noise,
    /// One garbage byte at a driver's turnaround, right after a frame.
    Glitch,
}

/// One stretch of the wire: bytes `start..end` of [`Wire::bytes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Truth {
    pub kind: TruthKind,
    pub start: usize,
    pub end: usize,
    pub is_request: bool,
}

/// The wire: bytes, the time each byte's stop bit ended (ns), and the truth.
#[derive(Debug, Clone, Default)]
pub struct Wire {
    pub bytes: Vec<u8>,
    pub end_ns: Vec<u64>,
    pub truth: Vec<Truth>,
}

impl Wire {
    /// The wire's bytes in `range` as hex (`"01 03 …"`), for diagnostics; empty out of range.
    #[must_use]
    pub fn hex(&self, range: std::ops::Range<usize>) -> String {
        self.bytes.get(range).unwrap_or_default().iter().map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
    }

    /// What the wire held within `margin` bytes of `range`: each stretch's kind, direction,
    /// span and bytes (`Good req 0..8 [01 03 …]`), for saying why a framer read it as it did.
    #[must_use]
    pub fn truth_around(&self, range: &std::ops::Range<usize>, margin: usize) -> Vec<String> {
        self.truth
            .iter()
            .filter(|t| t.end + margin > range.start && t.start < range.end + margin)
            .map(|t| {
                let dir = if t.is_request { " req" } else { "" };
                format!("{:?}{dir} {}..{} [{}]", t.kind, t.start, t.end, self.hex(t.start..t.end))
            })
            .collect()
    }
}

/// Traffic settings.
#[derive(Debug, Clone, Copy)]
pub struct TrafficConfig {
    pub seed: u64,
    pub line: LineSettings,
    /// Transactions (request + response or timeout) to generate.
    pub transactions: usize,
    /// Probability of a noise burst before a transaction.
    pub noise: f64,
    /// Probability that a frame gets one corrupted byte.
    pub corrupt: f64,
    /// Probability that a response has a gap (> t1.5) inside it.
    pub slow: f64,
    /// Probability that a frame is followed by a turnaround glitch byte (0 on a well-biased
    /// line; 1 where every driver switch leaves one).
    pub glitch: f64,
    /// Probability that a register-read answer is made a CRC look-alike: its last data byte
    /// chosen so the CRC's high byte is `00` (1 in 256 answers are, by chance, anyway).
    pub lookalike: f64,
    /// Start time, ns since the epoch.
    pub start_ns: u64,
    /// A unit that pauses inside every answer it sends, [`Self::slow_unit_chars`] character
    /// times after its third byte: the slow device a health report must name, and the one
    /// whose pauses must not be taken for the observer's delay.
    pub slow_unit: Option<u8>,
    /// The pause of [`Self::slow_unit`], in character times.
    pub slow_unit_chars: u64,
    /// The shortest silence kept between frames (ns); `None`: the spec's recommended 4.5
    /// characters. A master that waits 1.05 × t3.5 is within the spec, barely.
    pub min_idle_ns: Option<u64>,
    /// Each unit sends its vendor function (`VENDOR_FC`) with the same request and answer
    /// lengths all day, as devices do (off: random lengths per transaction).
    pub vendor_fixed: bool,
    /// Share of vendor frames (requests and answers) whose CRC ends in `00`: made so by their
    /// last data byte (by chance, 1 in 256 do).
    pub vendor_lookalike: f64,
}

impl Default for TrafficConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            line: LineSettings::default(),
            transactions: 1000,
            noise: 0.02,
            corrupt: 0.02,
            slow: 0.02,
            glitch: 0.0,
            lookalike: 0.0,
            start_ns: 1_700_000_000_000_000_000,
            slow_unit: None,
            slow_unit_chars: 30,
            min_idle_ns: None,
            vendor_fixed: false,
            vendor_lookalike: 0.0,
        }
    }
}

/// Slave addresses that answer, and one that never does.
const SLAVES: [u8; 4] = [1, 5, 17, 247];
const ABSENT: u8 = 33;
/// A vendor (user-defined) function code whose length the structure cannot tell.
pub const VENDOR_FC: u8 = 0x41;

struct Builder {
    rng: Rng,
    /// Draws of the options added later (vendor lengths, vendor look-alikes), apart from `rng`
    /// so that traffic without them stays what it was for every seed.
    rng2: Rng,
    cfg: TrafficConfig,
    char_ns: u64,
    t: u64,
    wire: Wire,
}

impl Builder {
    /// Puts bytes on the wire back to back from `self.t`, with an optional gap before byte
    /// `gap_at`.
    fn send(&mut self, bytes: &[u8], kind: TruthKind, is_request: bool, gap: Option<(usize, u64)>) {
        let start = self.wire.bytes.len();
        for (i, &b) in bytes.iter().enumerate() {
            if let Some((at, ns)) = gap
                && at == i
            {
                self.t += ns;
            }
            self.t += self.char_ns;
            self.wire.bytes.push(b);
            self.wire.end_ns.push(self.t);
        }
        self.wire.truth.push(Truth { kind, start, end: self.wire.bytes.len(), is_request });
    }

    fn frame(&mut self, unit: u8, pdu: &[u8], is_request: bool, slow: bool) {
        let mut wire = Vec::with_capacity(pdu.len() + 3);
        encode_rtu(unit, pdu, &mut wire);
        // Draws only when asked for, so every seed without the new physics gives the same
        // traffic it always gave (the regression captures were made from it).
        if !is_request && self.cfg.lookalike > 0.0 && self.rng.chance(self.cfg.lookalike) {
            make_lookalike(&mut wire);
        }
        if pdu.first() == Some(&VENDOR_FC)
            && self.cfg.vendor_lookalike > 0.0
            && self.rng2.chance(self.cfg.vendor_lookalike)
        {
            crc_tail_zero(&mut wire);
        }
        let mut kind = TruthKind::Good;
        if self.rng.chance(self.cfg.corrupt) {
            let at = usize::try_from(self.rng.below(wire.len() as u64)).unwrap_or(0);
            let flip = u8::try_from(self.rng.range(1, 255)).unwrap_or(1);
            wire[at] ^= flip;
            kind = TruthKind::Corrupted;
        }
        let gap = if !is_request && self.cfg.slow_unit == Some(unit) && wire.len() > 4 {
            Some((3, self.cfg.slow_unit_chars.saturating_mul(self.char_ns)))
        } else if slow && wire.len() > 3 {
            // A gap between t1.5 and 10 ms somewhere inside.
            let at = usize::try_from(self.rng.range(1, wire.len() as u64 - 1)).unwrap_or(1);
            let lo = self.cfg.line.t15_ns() + self.char_ns;
            Some((at, self.rng.range(lo, lo.max(10_000_000))))
        } else {
            None
        };
        self.send(&wire, kind, is_request, gap);
        if self.cfg.glitch > 0.0 && self.rng.chance(self.cfg.glitch) {
            // Within one character of the frame's last byte: no silence separates them.
            let glitch = if is_request {
                0x00
            } else if self.rng.chance(0.5) {
                0xFE
            } else {
                0xFF
            };
            self.t += self.rng.below(self.char_ns / 2);
            self.send(&[glitch], TruthKind::Glitch, is_request, None);
        }
    }

    fn idle(&mut self, min_ns: u64, max_ns: u64) {
        self.t += self.rng.range(min_ns, max_ns);
    }
}

/// Generates the wire for `cfg`.
#[must_use]
pub fn generate(cfg: &TrafficConfig) -> Wire {
    let line = cfg.line;
    let mut b = Builder {
        rng: Rng::new(cfg.seed),
        rng2: Rng::new(cfg.seed ^ 0x005E_ED0F_2025),
        cfg: *cfg,
        char_ns: line.char_ns(),
        t: cfg.start_ns,
        wire: Wire::default(),
    };
    // Turnaround and inter-poll idle: never below 4.5 characters (the spec's recommendation).
    let min_gap = cfg.min_idle_ns.unwrap_or(line.t35_ns() + line.char_ns());
    for _ in 0..cfg.transactions {
        if b.rng.chance(cfg.noise) {
            let n = usize::try_from(b.rng.range(1, 12)).unwrap_or(1);
            let noise = b.rng.bytes(n);
            b.send(&noise, TruthKind::Noise, false, None);
            b.idle(min_gap, min_gap * 3);
        }
        let (req, resp) = transaction(&mut b.rng);
        let roll = b.rng.below(100);
        let (unit, answer) = match roll {
            0..=2 => (0, false),      // broadcast: nobody answers
            3..=5 => (ABSENT, false), // absent slave: timeout
            _ => (*b.rng.pick(&SLAVES).unwrap_or(&1), true),
        };
        let (req, resp) = if cfg.vendor_fixed && req.first() == Some(&VENDOR_FC) {
            let (q, a) = vendor_pdus(unit, &mut b.rng2);
            (q, Some(a))
        } else {
            (req, resp)
        };
        // Broadcasts are writes only (Modbus over Serial Line v1.02 §2.1).
        let req = if unit == 0 {
            let mut w = Vec::new();
            let _ = Request::WriteSingleRegister { address: 100, value: 1 }.encode(&mut w);
            w
        } else {
            req
        };
        b.frame(unit, &req, true, false);
        if answer && let Some(resp) = resp {
            b.idle(min_gap, min_gap + 5_000_000);
            let slow = b.rng.chance(cfg.slow);
            b.frame(unit, &resp, false, slow);
            b.idle(min_gap, min_gap + 20_000_000);
        } else {
            // The master waits out its response timeout.
            b.idle(100_000_000, 120_000_000);
        }
    }
    b.wire
}
