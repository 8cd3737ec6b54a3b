//! `mbtap learn`: a register map drafted from what the line says. The master's requests give
//! the blocks it polls (first address, quantity, how often), the writes it makes and the
//! functions it uses; the answers over time give each register's type ([`infer`]); exceptions
//! 02 mark addresses the device does not have. Pure: transactions in (PDUs and times), a
//! report and a draft profile out. Memory grows with the registers heard, never with the
//! length of the capture ([`stats`]), and the registers kept are bounded too
//! ([`MAX_REGISTERS`], [`MAX_OTHER`]): a capture naming more is learned in part, and says so.
//!
//! Modules: `kind` (what a guess says a register holds), `series` (measures of a pair's series;
//! confidence), `infer` and `layout` (types pair by pair and block by block), `still_words` (32-bit
//! integers whose high word never moved), `few_samples` (typing from one or two samples),
//! `sunspec_map` (a SunSpec device typed by its models), `hint` (`--hint` values read off a
//! display), `confirm` (what `--confirm` asks again), `probe` (active read-only discovery), `diff`
//! (two register images compared), `truth` (the device `learn` is measured against).

pub mod confirm;
pub mod diff;
pub mod draft;
pub mod few_samples;
pub mod hint;
pub mod infer;
mod kind;
pub mod layout;
pub mod probe;
mod series;
pub mod stats;
mod still_words;
pub mod sunspec_map;
pub mod truth;

use std::collections::btree_map::Entry;
use std::collections::{BTreeMap, BTreeSet};

use infer::Guess;
use mbtap_device::profile::Table;
use mbtap_device::query::{is_bits, table_read_by};
use stats::{PairStat, RegStat};

/// Gaps between polls kept per block, for its period.
const GAPS: usize = 32;

/// A block the master reads: how often, and when last.
#[derive(Debug, Clone, Default)]
pub struct Block {
    /// Polls heard, answered or not (an unanswered poll is still one of the master's).
    pub polls: u64,
    pub first_t_ns: u64,
    pub last_t_ns: u64,
    /// The last [`GAPS`] gaps between two polls.
    gaps: std::collections::VecDeque<u64>,
}

impl Block {
    fn new(t_ns: u64) -> Self {
        Self { polls: 1, first_t_ns: t_ns, last_t_ns: t_ns, gaps: std::collections::VecDeque::new() }
    }

    /// One more poll at `t_ns`.
    fn polled(&mut self, t_ns: u64) {
        self.polls += 1;
        if self.gaps.len() == GAPS {
            self.gaps.pop_front();
        }
        self.gaps.push_back(t_ns.saturating_sub(self.last_t_ns));
        self.last_t_ns = t_ns;
    }

    /// The median time between two polls (as `report`'s "polled every" takes it: a poll
    /// unanswered or skipped once does not stretch it), when it was polled more than once.
    #[must_use]
    pub fn period_ns(&self) -> Option<u64> {
        let mut g: Vec<u64> = self.gaps.iter().copied().collect();
        g.sort_unstable();
        g.get(g.len() / 2).copied()
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
        // A SunSpec device's points are typed by its models; the samples judge the rest.
        let by_models = if matches!(table, Table::HoldingRegisters) {
            sunspec_map::guesses(&|a| self.regs.get(&(table, a)).and_then(|r| r.last))
        } else {
            Vec::new()
        };
        let covered: BTreeSet<u16> =
            by_models.iter().flat_map(|g| (0..g.kind.width()).filter_map(move |k| g.address.checked_add(k))).collect();
        let regs: Vec<(u16, &RegStat)> = self
            .regs
            .range((table, 0)..=(table, u16::MAX))
            .map(|(&(_, a), r)| (a, r))
            .filter(|(a, _)| !covered.contains(a))
            .collect();
        let pair = |a| self.pairs.get(&(table, a));
        let blocks: Vec<(u16, u16)> =
            self.blocks.keys().filter(|&&(t, _, _)| t == table).map(|&(_, first, q)| (first, q)).collect();
        let heard = |a| self.regs.contains_key(&(table, a));
        let layout = layout::Layout::decide(&blocks, &pair, &heard);
        let still = still_words::still_word_pairs(&blocks, &|a| self.regs.get(&(table, a)));
        let ints = few_samples::int_blocks(&blocks, &pair);
        let mut out = infer::guess_table(&regs, &pair, layout.as_ref(), &still, &ints);
        out.extend(by_models);
        out.sort_by_key(|g| g.address);
        out
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

/// Registers and adjacent pairs kept, all units together: each costs up to ~0.5 KB once heard
/// [`stats::RECENT`] times, so this keeps the learner under ~35 MB whatever the capture (without
/// the bound, a capture of 400 000 distinct registers took 248 MB). A real bus polls far fewer.
pub const MAX_REGISTERS: usize = 65_536;
/// Blocks, exception ranges and written addresses kept, all units together.
pub const MAX_OTHER: usize = 32_768;

/// Everything learned, per unit.
#[derive(Debug, Clone, Default)]
pub struct Learner {
    pub units: BTreeMap<u8, Unit>,
    pub transactions: u64,
    /// Only this unit is learned (`learn --unit`): the others cost nothing.
    pub only: Option<u8>,
    /// Registers (and pairs) and other entries kept, against [`MAX_REGISTERS`], [`MAX_OTHER`].
    kept_registers: usize,
    kept_other: usize,
    /// Values of registers (and pairs), and reads, exceptions and writes of other entries,
    /// heard but not kept past those bounds (counted each time they are heard).
    pub not_kept_registers: u64,
    pub not_kept_other: u64,
}

fn word(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(at)?, *b.get(at.checked_add(1)?)?]))
}

impl Learner {
    /// A request of `unit` at `t_ns` that got no answer (or none that could be read): a poll of
    /// a block already known counts for its period, nothing else is learned.
    pub fn unanswered(&mut self, unit: u8, request: &[u8], t_ns: u64) {
        if let (Some(u), Some(table)) = (self.units.get_mut(&unit), request.first().and_then(|&fc| table_read_by(fc)))
            && let (Some(first), Some(quantity)) = (word(request, 1), word(request, 3))
            && let Some(b) = u.blocks.get_mut(&(table, first, quantity))
        {
            b.polled(t_ns);
        }
    }

    /// One answered transaction: the request and response PDUs (function code first) of
    /// `unit`, at `t_ns`. Anything else (broadcasts, unanswered requests) is ignored.
    pub fn observe(&mut self, unit: u8, request: &[u8], response: &[u8], t_ns: u64) {
        let (Some(&fc), Some(&rfc)) = (request.first(), response.first()) else { return };
        if unit == 0 || self.only.is_some_and(|only| only != unit) {
            return;
        }
        self.transactions += 1;
        let Self { units, kept_registers, kept_other, not_kept_registers, not_kept_other, .. } = self;
        // Whether a new entry may be kept: one more within `bound`, or counted as not kept.
        let room = |kept: &mut usize, bound: usize, not_kept: &mut u64| {
            if *kept < bound {
                *kept += 1;
                true
            } else {
                *not_kept += 1;
                false
            }
        };
        let u = units.entry(unit).or_default();
        u.functions.insert(fc);
        // A read: block, exception, and the values it returned (MAP v1.1b3 §6.1–6.4).
        if let Some(table) = table_read_by(fc)
            && let (Some(first), Some(quantity)) = (word(request, 1), word(request, 3))
            && quantity > 0
        {
            if rfc == fc | 0x80 {
                if let Some(b) = u.blocks.get_mut(&(table, first, quantity)) {
                    b.polled(t_ns);
                }
                let code = response.get(1).copied().unwrap_or(0);
                match u.exceptions.entry((table, first, quantity)) {
                    Entry::Occupied(mut e) => {
                        e.insert(code);
                    }
                    Entry::Vacant(e) => {
                        if room(kept_other, MAX_OTHER, not_kept_other) {
                            e.insert(code);
                        }
                    }
                }
                return;
            }
            match u.blocks.entry((table, first, quantity)) {
                Entry::Occupied(mut e) => e.get_mut().polled(t_ns),
                Entry::Vacant(e) => {
                    if room(kept_other, MAX_OTHER, not_kept_other) {
                        e.insert(Block::new(t_ns));
                    }
                }
            }
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
                match u.regs.entry((table, a)) {
                    Entry::Occupied(mut e) => e.get_mut().push(v),
                    Entry::Vacant(e) => {
                        if room(kept_registers, MAX_REGISTERS, not_kept_registers) {
                            e.insert(RegStat::default()).push(v);
                        }
                    }
                }
                if let (false, Some(p), Some(before)) = (is_bits(table), prev, a.checked_sub(1)) {
                    match u.pairs.entry((table, before)) {
                        Entry::Occupied(mut e) => e.get_mut().push(p, v),
                        Entry::Vacant(e) => {
                            if room(kept_registers, MAX_REGISTERS, not_kept_registers) {
                                e.insert(PairStat::default()).push(p, v);
                            }
                        }
                    }
                }
                prev = Some(v);
            }
            return;
        }
        // Writes (MAP v1.1b3 §6.5, 6.6, 6.11, 6.12): setpoints and commands.
        let mut wrote = |table: Table, a: u16, v: u16| {
            let w = match u.writes.entry((table, a)) {
                Entry::Occupied(e) => e.into_mut(),
                Entry::Vacant(e) => {
                    if !room(kept_other, MAX_OTHER, not_kept_other) {
                        return;
                    }
                    e.insert(Vec::new())
                }
            };
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
        if let crate::analyzer::Event::Transaction(t) = event {
            match (t.request_pdu, t.response_pdu) {
                (Some(req), Some(resp)) => self.observe(t.unit, req, resp, t.t_start.0),
                (Some(req), None) => self.unanswered(t.unit, req, t.t_start.0),
                _ => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Read one holding register at `a` (MAP v1.1b3 §6.3: 03, address, quantity 0001) and its
    /// answer (03, byte count 02, the value).
    fn read_one(a: u16, v: u16) -> ([u8; 5], [u8; 4]) {
        let [ah, al] = a.to_be_bytes();
        let [vh, vl] = v.to_be_bytes();
        ([0x03, ah, al, 0x00, 0x01], [0x03, 0x02, vh, vl])
    }

    /// A capture of 400 000 distinct registers (248 MB if every one were kept) is learned in part:
    /// what is kept is bounded, and what is not kept is counted and said.
    #[test]
    fn a_capture_of_more_registers_than_kept_is_learned_in_part_and_says_so() {
        let mut l = Learner::default();
        for k in 0..=u32::try_from(MAX_REGISTERS).unwrap() {
            let unit = if k < 65_536 { 1 } else { 2 };
            let (q, r) = read_one(u16::try_from(k % 65_536).unwrap(), 7);
            l.observe(unit, &q, &r, u64::from(k));
        }
        let kept: usize = l.units.values().map(|u| u.regs.len()).sum();
        let blocks: usize = l.units.values().map(|u| u.blocks.len()).sum();
        assert_eq!((kept, blocks), (MAX_REGISTERS, MAX_OTHER));
        assert_eq!(l.not_kept_registers, 1);
        assert_eq!(l.not_kept_other, u64::try_from(MAX_REGISTERS + 1 - MAX_OTHER).unwrap());
        let note = draft::not_kept_note(&l).unwrap();
        assert!(note.contains("--unit N") && note.contains("65536"), "{note}");
        assert!(draft::text(&l).contains(&note));
        // What was kept still learns: a kept register heard again is counted, not refused.
        let (q, r) = read_one(0, 8);
        l.observe(1, &q, &r, 1);
        assert_eq!(l.units[&1].regs[&(Table::HoldingRegisters, 0)].samples, 2);
        assert_eq!(l.not_kept_registers, 1);
    }

    #[test]
    fn learning_one_unit_keeps_nothing_of_the_others() {
        let mut l = Learner { only: Some(5), ..Learner::default() };
        let (q, r) = read_one(10, 1);
        l.observe(4, &q, &r, 0);
        l.observe(5, &q, &r, 0);
        assert_eq!(l.units.keys().copied().collect::<Vec<_>>(), [5]);
        assert_eq!(l.transactions, 1);
        assert!(draft::not_kept_note(&l).is_none());
    }
}
