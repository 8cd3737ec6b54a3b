//! `mbtap learn`: a register map drafted from what the line says. The master's requests give
//! the blocks it polls (first address, quantity, how often), the writes it makes and the
//! functions it uses; the answers over time give each register's type ([`infer`]); exceptions
//! 02 mark addresses the device does not have. Pure: transactions in (PDUs and times), a
//! report and a draft profile out. Memory grows with the registers heard, never with the
//! length of the capture ([`stats`]).

pub mod diff;
pub mod draft;
pub mod hint;
pub mod infer;
pub mod probe;
pub mod stats;
pub mod truth;

use std::collections::{BTreeMap, BTreeSet};

use crate::profile::Table;
use crate::query::{is_bits, table_read_by};
use infer::Guess;
use stats::{PairStat, RegStat};

/// A block the master reads: how often, and when last.
#[derive(Debug, Clone, Default)]
pub struct Block {
    pub polls: u64,
    pub first_t_ns: u64,
    pub last_t_ns: u64,
}

impl Block {
    /// The mean time between two polls, when it was polled more than once.
    #[must_use]
    pub fn period_ns(&self) -> Option<u64> {
        (self.polls > 1).then(|| self.last_t_ns.saturating_sub(self.first_t_ns) / (self.polls - 1))
    }
}

/// What was learned of one unit.
#[derive(Debug, Clone, Default)]
pub struct Unit {
    pub functions: BTreeSet<u8>,
    /// (table, first address, quantity) → polls.
    pub blocks: BTreeMap<(Table, u16, u16), Block>,
    /// (table, address) → values written, last first, at most eight.
    pub writes: BTreeMap<(Table, u16), Vec<u16>>,
    /// (table, first address, quantity) of reads answered with an exception → the code.
    pub exceptions: BTreeMap<(Table, u16, u16), u8>,
    regs: BTreeMap<(Table, u16), RegStat>,
    pairs: BTreeMap<(Table, u16), PairStat>,
}

impl Unit {
    /// The guesses for one table.
    #[must_use]
    pub fn guesses(&self, table: Table) -> Vec<Guess> {
        let regs: Vec<(u16, &RegStat)> =
            self.regs.range((table, 0)..=(table, u16::MAX)).map(|(&(_, a), r)| (a, r)).collect();
        infer::guess_table(&regs, &|a| self.pairs.get(&(table, a)))
    }

    /// The last value of what `g` covers, as its type reads it (a 32-bit pair combined in its
    /// word order, a float as a float), for a hint to be compared with.
    #[must_use]
    #[allow(clippy::cast_possible_wrap)]
    pub fn last_raw(&self, table: Table, g: &Guess) -> Option<f64> {
        use infer::Kind;
        let one = self.regs.get(&(table, g.address))?.last?;
        let pair = || self.pairs.get(&(table, g.address))?.recent.back().copied();
        let join = |h: bool| {
            pair().map(|(a, b)| {
                let (hi, lo) = if h { (a, b) } else { (b, a) };
                (u32::from(hi) << 16) | u32::from(lo)
            })
        };
        Some(match g.kind {
            Kind::I16 => f64::from(one as i16),
            Kind::U32 { high_first, .. } => f64::from(join(high_first)?),
            Kind::I32 { high_first } => f64::from(join(high_first)?.cast_signed()),
            Kind::F32 { high_first } => f64::from(f32::from_bits(join(high_first)?)),
            _ => f64::from(one),
        })
    }

    /// The tables with registers or bits heard.
    #[must_use]
    pub fn tables(&self) -> BTreeSet<Table> {
        self.regs.keys().map(|&(t, _)| t).collect()
    }
}

/// Everything learned, per unit.
#[derive(Debug, Clone, Default)]
pub struct Learner {
    pub units: BTreeMap<u8, Unit>,
    pub transactions: u64,
}

fn word(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(at)?, *b.get(at.checked_add(1)?)?]))
}

impl Learner {
    /// One answered transaction: the request and response PDUs (function code first) of
    /// `unit`, at `t_ns`. Anything else (broadcasts, unanswered requests) is ignored.
    pub fn observe(&mut self, unit: u8, request: &[u8], response: &[u8], t_ns: u64) {
        let (Some(&fc), Some(&rfc)) = (request.first(), response.first()) else { return };
        if unit == 0 {
            return;
        }
        self.transactions += 1;
        let u = self.units.entry(unit).or_default();
        u.functions.insert(fc);
        // A read: block, exception, and the values it returned (MAP v1.1b3 §6.1–6.4).
        if let Some(table) = table_read_by(fc)
            && let (Some(first), Some(quantity)) = (word(request, 1), word(request, 3))
            && quantity > 0
        {
            if rfc == fc | 0x80 {
                u.exceptions.insert((table, first, quantity), response.get(1).copied().unwrap_or(0));
                return;
            }
            let b = u.blocks.entry((table, first, quantity)).or_insert(Block { first_t_ns: t_ns, ..Block::default() });
            b.polls += 1;
            b.last_t_ns = t_ns;
            let data = response.get(2..).unwrap_or_default();
            let mut prev: Option<u16> = None;
            for i in 0..quantity {
                let Some(a) = first.checked_add(i) else { break };
                let i = usize::from(i);
                let v = if is_bits(table) {
                    data.get(i / 8).map(|byte| u16::from(byte >> (i % 8) & 1))
                } else {
                    word(data, i * 2)
                };
                let Some(v) = v else { break };
                u.regs.entry((table, a)).or_default().push(v);
                if let (false, Some(p), Some(before)) = (is_bits(table), prev, a.checked_sub(1)) {
                    u.pairs.entry((table, before)).or_default().push(p, v);
                }
                prev = Some(v);
            }
            return;
        }
        // Writes (MAP v1.1b3 §6.5, 6.6, 6.11, 6.12): setpoints and commands.
        let mut wrote = |table: Table, a: u16, v: u16| {
            let w = u.writes.entry((table, a)).or_default();
            w.insert(0, v);
            w.truncate(8);
        };
        match fc {
            0x05 => {
                if let (Some(a), Some(v)) = (word(request, 1), word(request, 3)) {
                    wrote(Table::Coils, a, u16::from(v == 0xFF00));
                }
            }
            0x06 => {
                if let (Some(a), Some(v)) = (word(request, 1), word(request, 3)) {
                    wrote(Table::HoldingRegisters, a, v);
                }
            }
            0x10 => {
                if let (Some(first), Some(q)) = (word(request, 1), word(request, 3)) {
                    for i in 0..q {
                        if let (Some(a), Some(v)) = (first.checked_add(i), word(request, 6 + usize::from(i) * 2)) {
                            wrote(Table::HoldingRegisters, a, v);
                        }
                    }
                }
            }
            _ => {}
        }
    }
}

/// The learner as an analyzer sink: every answered transaction, its frames as on the wire.
impl crate::analyzer::Sink for Learner {
    fn event(&mut self, event: &crate::analyzer::Event<'_>) {
        if let crate::analyzer::Event::Transaction(t) = event
            && let (Some(req), Some(resp)) = (t.request_pdu, t.response_pdu)
        {
            self.observe(t.unit, req, resp, t.t_start.0);
        }
    }
}
