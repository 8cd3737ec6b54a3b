//! A device with known register semantics, polled: the ground truth `learn` is measured
//! against (its tests, and `examples/learn_accuracy.rs` for the figures in BENCHMARKS.md).
//! Each register's meaning is drawn from a seed, so every run is a different map with the same
//! kinds of value in it: constants, counters, enumerations, bit fields, signed values around
//! zero, analog values, 32-bit counters and signed values and floats in both word orders,
//! text, registers that never change, and independent analog registers side by side (which
//! must not be joined).

use super::infer::Kind;

/// What a register (or run of registers) really holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Truth {
    Constant,
    Counter,
    Enum,
    Bits,
    I16,
    U16,
    U32 { high_first: bool },
    I32 { high_first: bool },
    F32 { high_first: bool },
    Text(u16),
}

impl Truth {
    fn width(self) -> u16 {
        match self {
            Self::U32 { .. } | Self::I32 { .. } | Self::F32 { .. } => 2,
            Self::Text(n) => n,
            _ => 1,
        }
    }

    /// Whether a guess names this truth (a u32 counter is a u32; an enum of two values that
    /// toggles is an enum).
    #[must_use]
    pub fn matches(self, k: &Kind) -> bool {
        match (self, k) {
            (Self::Constant, Kind::Constant)
            | (Self::Counter, Kind::Counter)
            | (Self::Enum, Kind::Enum(_))
            | (Self::Bits, Kind::Bits(_))
            | (Self::I16, Kind::I16)
            | (Self::U16, Kind::U16) => true,
            (Self::U32 { high_first: a }, Kind::U32 { high_first: b, .. })
            | (Self::I32 { high_first: a }, Kind::I32 { high_first: b })
            | (Self::F32 { high_first: a }, Kind::F32 { high_first: b }) => a == *b,
            (Self::Text(n), Kind::Text { registers, .. }) => n == *registers,
            _ => false,
        }
    }
}

/// A small deterministic generator (xorshift64*): no dependency, the same map for a seed.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn draw(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// 0 ≤ r < n.
    pub fn below(&mut self, n: u64) -> u64 {
        self.draw() % n.max(1)
    }

    #[allow(clippy::cast_precision_loss)]
    pub fn unit(&mut self) -> f64 {
        (self.draw() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// One register or run of the device, with its state.
#[derive(Debug, Clone)]
struct Reg {
    truth: Truth,
    state: f64,
    phase: f64,
    scale: f64,
    text: [u8; 8],
}

/// The simulated device: its registers from address 0, in one block the master polls.
#[derive(Debug, Clone)]
pub struct Device {
    regs: Vec<Reg>,
    rng: Rng,
    t: u64,
}

impl Device {
    /// A map of `n` entries drawn from `seed`, every kind present.
    #[must_use]
    pub fn new(seed: u64, n: usize) -> Self {
        let mut rng = Rng::new(seed);
        let kinds = [
            Truth::Constant,
            Truth::Counter,
            Truth::Enum,
            Truth::Bits,
            Truth::I16,
            Truth::U16,
            Truth::U32 { high_first: true },
            Truth::U32 { high_first: false },
            Truth::I32 { high_first: true },
            Truth::I32 { high_first: false },
            Truth::F32 { high_first: true },
            Truth::F32 { high_first: false },
            Truth::Text(4),
            Truth::U16,
        ];
        let regs = (0..n)
            .map(|i| {
                // Every kind once, then drawn at random.
                let truth = kinds
                    .get(i)
                    .copied()
                    .unwrap_or_else(|| kinds[usize::try_from(rng.below(kinds.len() as u64)).unwrap_or(0)]);
                let mut text = [b' '; 8];
                for c in &mut text {
                    *c = b"ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-"[usize::try_from(rng.below(37)).unwrap_or(0)];
                }
                Reg {
                    truth,
                    state: rng.unit() * 1000.0,
                    phase: rng.unit() * std::f64::consts::TAU,
                    scale: 0.5 + rng.unit() * 4.0,
                    text,
                }
            })
            .collect();
        Self { regs, rng, t: 0 }
    }

    /// The truth per start address.
    #[must_use]
    pub fn truths(&self) -> Vec<(u16, Truth)> {
        let mut a = 0u16;
        self.regs
            .iter()
            .map(|r| {
                let at = a;
                a = a.saturating_add(r.truth.width());
                (at, r.truth)
            })
            .collect()
    }

    /// Registers the map covers.
    #[must_use]
    pub fn quantity(&self) -> u16 {
        self.regs.iter().map(|r| r.truth.width()).sum()
    }

    /// The register values after one more step of time.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss, clippy::cast_precision_loss)]
    pub fn step(&mut self) -> Vec<u16> {
        self.t += 1;
        let t = self.t as f64;
        let mut out = Vec::new();
        for r in &mut self.regs {
            let wave = (t / 25.0 * r.scale + r.phase).sin();
            match r.truth {
                Truth::Constant => out.push((r.state as u16) | 1),
                Truth::Counter => {
                    r.state += 1.0 + (self.rng.below(3) as f64);
                    out.push((r.state as u64 % 65_536) as u16);
                }
                Truth::Enum => {
                    if self.rng.below(6) == 0 {
                        r.state = self.rng.below(5) as f64;
                    }
                    out.push((r.state as u16) % 5);
                }
                Truth::Bits => {
                    if self.rng.below(4) == 0 {
                        r.phase = f64::from((r.phase as u16) ^ (1 << self.rng.below(9)));
                    }
                    out.push(r.phase as u16);
                }
                Truth::I16 => out.push(((wave * 300.0 * r.scale) as i16) as u16),
                Truth::U16 => out.push((2000.0 + wave * 500.0 * r.scale + self.rng.unit() * 20.0) as u16),
                Truth::U32 { high_first } => {
                    r.state += 3000.0 + self.rng.below(4000) as f64;
                    let v = r.state as u32;
                    push32(&mut out, v, high_first);
                }
                Truth::I32 { high_first } => {
                    let v = (wave * 100_000.0 * r.scale + self.rng.unit() * 50.0) as i32;
                    push32(&mut out, v as u32, high_first);
                }
                Truth::F32 { high_first } => {
                    let v = (230.0 * r.scale + wave * 5.0 + self.rng.unit() * 0.05) as f32;
                    push32(&mut out, v.to_bits(), high_first);
                }
                Truth::Text(n) => {
                    for i in 0..usize::from(n) {
                        out.push(u16::from_be_bytes([r.text[(2 * i) % 8], r.text[(2 * i + 1) % 8]]));
                    }
                }
            }
        }
        out
    }
}

fn push32(out: &mut Vec<u16>, v: u32, high_first: bool) {
    let (hi, lo) = ((v >> 16) as u16, (v & 0xFFFF) as u16);
    if high_first {
        out.extend([hi, lo]);
    } else {
        out.extend([lo, hi]);
    }
}

/// The request and response PDUs of one poll of `quantity` holding registers from 0.
#[must_use]
pub fn poll(values: &[u16]) -> (Vec<u8>, Vec<u8>) {
    let q = u16::try_from(values.len()).unwrap_or(u16::MAX);
    let mut req = vec![0x03, 0, 0];
    req.extend_from_slice(&q.to_be_bytes());
    let mut resp = vec![0x03, u8::try_from(values.len() * 2).unwrap_or(u8::MAX)];
    for v in values {
        resp.extend_from_slice(&v.to_be_bytes());
    }
    (req, resp)
}

/// Of `truths`, how many the learner typed right: (right, total), and the ones it got wrong.
#[must_use]
pub fn score(truths: &[(u16, Truth)], guesses: &[super::infer::Guess]) -> (usize, usize, Vec<String>) {
    let mut right = 0;
    let mut wrong = Vec::new();
    for &(a, t) in truths {
        match guesses.iter().find(|g| g.address == a) {
            Some(g) if t.matches(&g.kind) => right += 1,
            Some(g) => wrong.push(format!("{a}: {t:?} guessed {} ({})", g.kind.name(), g.evidence)),
            None => wrong.push(format!("{a}: {t:?} not guessed at its address (joined into another)")),
        }
    }
    (right, truths.len(), wrong)
}

#[cfg(test)]
mod tests {
    use super::super::Learner;
    use super::*;
    use mbtap_device::profile::Table;

    fn learn(seed: u64, n: usize, polls: u64) -> (usize, usize, Vec<String>, Learner) {
        let mut dev = Device::new(seed, n);
        let mut l = Learner::default();
        for i in 0..polls {
            let (req, resp) = poll(&dev.step());
            l.observe(1, &req, &resp, i * 500_000_000);
        }
        let guesses = l.units[&1].guesses(Table::HoldingRegisters);
        let (right, total, wrong) = score(&dev.truths(), &guesses);
        (right, total, wrong, l)
    }

    /// The bar: ≥ 95 % of registers typed right on traffic with known semantics, and no
    /// two independent registers joined (an independent register swallowed into a pair would
    /// show up as "not guessed at its address").
    #[test]
    fn registers_of_known_kinds_are_typed_right() {
        let (mut right, mut total) = (0, 0);
        let mut wrong_all = Vec::new();
        for seed in 1..=20 {
            let (r, t, wrong, _) = learn(seed, 40, 300);
            right += r;
            total += t;
            wrong_all.extend(wrong);
        }
        assert!(right * 100 >= total * 95, "{right} of {total} typed right:\n{}", wrong_all.join("\n"));
        // Registers that move are never swallowed into another's guess. (Text next to text, or
        // a constant next to text, cannot be told from one longer string by listening: those
        // merges are counted above as wrong, not excused.)
        let moving_joined: Vec<&String> = wrong_all
            .iter()
            .filter(|w| w.contains("joined into another") && !w.contains("Text(") && !w.contains("Constant"))
            .collect();
        assert!(moving_joined.is_empty(), "{moving_joined:#?}");
        eprintln!("learn accuracy: {right} of {total} typed right");
    }

    /// The draft loads as a profile (`profiles check` reads it the same way).
    #[test]
    fn the_draft_is_a_profile_that_loads() {
        let (_, _, _, l) = learn(7, 40, 200);
        let toml = super::super::draft::profile_toml(1, &l.units[&1], "a test", &[]);
        let p = mbtap_device::profile::load("draft.toml", &toml).unwrap_or_else(|e| panic!("{e}\n{toml}"));
        assert!(p.addresses(Table::HoldingRegisters).count() > 20, "{toml}");
        assert!(toml.contains("type = \"f32\"") && toml.contains("word_order = \"low_first\""), "{toml}");
    }

    /// `--hint`: the display shows a tenth of the raw value: scale 0.1 in the draft, which still
    /// loads and shows the hinted value.
    #[test]
    fn a_hint_fixes_the_scale() {
        let (_, _, _, l) = learn(7, 40, 200);
        let u = &l.units[&1];
        let guesses = u.guesses(Table::HoldingRegisters);
        let g = guesses.iter().find(|g| matches!(g.kind, Kind::U16)).unwrap();
        let raw = u.last_raw(Table::HoldingRegisters, g).unwrap();
        let hint =
            super::super::hint::Hint { unit: 1, table: Table::HoldingRegisters, address: g.address, value: raw / 10.0 };
        let toml = super::super::draft::profile_toml(1, u, "a test", &[hint]);
        assert!(
            toml.contains(&format!("address = {}\nname = \"reg_holding_{}\"\nscale = 0.1", g.address, g.address)),
            "{toml}"
        );
        let p = mbtap_device::profile::load("draft.toml", &toml).unwrap();
        assert!(p.slot(Table::HoldingRegisters, g.address).is_some());
    }

    /// Memory follows the registers, not the transactions.
    #[test]
    fn samples_kept_per_register_are_bounded() {
        let (_, _, _, l) = learn(3, 10, 2000);
        assert!(l.units[&1].regs.values().all(|r| r.recent.len() <= super::super::stats::RECENT));
        assert_eq!(l.transactions, 2000);
    }
}
