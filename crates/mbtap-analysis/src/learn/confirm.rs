//! What `learn --confirm` asks the device again, and what the answers settled. Passive traffic
//! of a logger that reads each block once leaves registers decided by one or two samples (at a
//! confidence of at most [`super::few_samples::FEW`]); reading those blocks again — only reads,
//! only blocks the master itself read, so the device is asked nothing it was not asked already —
//! gives the series that decide them. Pure: the plan and the verdict; the asking is the
//! master's (`src/master/confirm.rs`).

use mbtap_device::profile::Table;

use super::few_samples::FEW;
use super::kind::Guess;
use super::{Learner, Unit};

/// Reads of each block that make a series ([`super::series`]'s `ENOUGH`).
pub const READS_EACH: u64 = 8;

/// A block to read again: (table, first address, quantity), and the function that reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Ask {
    pub table: Table,
    pub first: u16,
    pub quantity: u16,
}

impl Ask {
    /// The read's PDU (MAP v1.1b3 §6.3 read holding registers 0x03, §6.4 read input registers
    /// 0x04): function, first address, quantity.
    #[must_use]
    pub fn pdu(&self) -> Vec<u8> {
        let function = if self.table == Table::InputRegisters { 0x04 } else { 0x03 };
        let [a, b] = self.first.to_be_bytes();
        let [q, r] = self.quantity.to_be_bytes();
        vec![function, a, b, q, r]
    }
}

/// The registers a few samples decided: (table, guess), confidence at most [`FEW`].
#[must_use]
pub fn undecided(unit: &Unit) -> Vec<(Table, Guess)> {
    [Table::HoldingRegisters, Table::InputRegisters]
        .into_iter()
        .flat_map(|t| unit.guesses(t).into_iter().map(move |g| (t, g)))
        .filter(|(_, g)| g.confidence <= FEW)
        .collect()
}

/// The master's own register reads that hold an undecided register: the smallest such block
/// for each, each once, in address order.
#[must_use]
pub fn plan(unit: &Unit) -> Vec<Ask> {
    let mut asks: Vec<Ask> = undecided(unit)
        .iter()
        .filter_map(|(table, g)| {
            unit.blocks
                .keys()
                .filter(|&&(t, first, q)| {
                    t == *table && first <= g.address && u32::from(g.address) < u32::from(first) + u32::from(q)
                })
                .min_by_key(|&&(_, _, q)| q)
                .map(|&(table, first, quantity)| Ask { table, first, quantity })
        })
        .collect();
    asks.sort_unstable();
    asks.dedup();
    asks
}

/// Registers the guesses cover.
#[must_use]
pub fn registers(guesses: &[(Table, Guess)]) -> usize {
    guesses.iter().map(|(_, g)| usize::from(g.kind.width())).sum()
}

/// What the extra reads changed for `unit`: registers now decided beyond a few samples' word,
/// with their type before and after, and how many registers are still undecided.
#[must_use]
pub fn settled(before: &[(Table, Guess)], learner: &Learner, unit: u8) -> (Vec<String>, usize) {
    let Some(u) = learner.units.get(&unit) else { return (Vec::new(), registers(before)) };
    let still = undecided(u);
    let now: Vec<(Table, Guess)> = [Table::HoldingRegisters, Table::InputRegisters]
        .into_iter()
        .flat_map(|t| u.guesses(t).into_iter().map(move |g| (t, g)))
        .collect();
    let mut lines = Vec::new();
    let mut said: Vec<(Table, u16)> = Vec::new();
    for (t, was) in before {
        let covers =
            |nt: &Table, g: &Guess| nt == t && g.address <= was.address && was.address < g.address + g.kind.width();
        let Some((_, g)) = now.iter().find(|(nt, g)| covers(nt, g)) else { continue };
        let decided = !still.iter().any(|(st, g)| covers(st, g));
        // Each new guess said once (a pair that joined two registers is one line).
        if (g.kind != was.kind || decided) && !said.contains(&(*t, g.address)) {
            said.push((*t, g.address));
            lines.push(format!(
                "{} {}: {} → {} (confidence {:.2} → {:.2})",
                t.name(),
                was.address,
                was.kind.name(),
                g.kind.name(),
                was.confidence,
                g.confidence
            ));
        }
    }
    (lines, registers(&still))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Named constant: one read of holding 0–3 (FC 03, MAP v1.1b3 §6.3) and its answer — a
    /// u32 of 2 300 (0x0000 0x08FC) and one of 88 000 (0x0001 0x57C0), high word first.
    const REQUEST: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x04];
    const ANSWER: [u8; 10] = [0x03, 0x08, 0x00, 0x00, 0x08, 0xFC, 0x00, 0x01, 0x57, 0xC0];

    #[test]
    fn blocks_holding_what_one_sample_decided_are_asked_again_and_only_those() {
        let mut l = Learner::default();
        l.observe(1, &REQUEST, &ANSWER, 0);
        let u = &l.units[&1];
        assert!(!undecided(u).is_empty());
        let asks = plan(u);
        assert_eq!(asks, [Ask { table: Table::HoldingRegisters, first: 0, quantity: 4 }]);
        assert_eq!(asks[0].pdu(), REQUEST);
    }
}
