//! 32-bit integers whose high word never moved while recorded. A meter's totals and
//! a tank's volume (the Display's input 0–3: `73`, then a level around 15 700) keep their high
//! word for hours; each pair alone reads as a constant beside a 16-bit value, and only the block
//! says otherwise: where, pair by pair from the block's start, the first word of every pair
//! that moves at all is still and its second word moves — never the other way round, at least
//! twice, and the pairs read one register later do not show it as well — the registers are
//! high words and low words of 32-bit values, high word first. A guess with little evidence
//! behind it: its confidence says so (at most [`CONFIDENCE`]).
//!
//! Not mirrored: a moving word then a still one is a measurement beside a setting as often as a
//! low word beside its high word (the MKZP's phase currents beside its insulation resistance,
//! holding 52–55, would be joined), so a low-word-first value shows only by its carries.

use std::collections::BTreeMap;

use super::stats::RegStat;

/// The most a layout of still words is trusted: the values never showed a carry.
pub const CONFIDENCE: f64 = 0.3;

/// Pairs of a table that read as 32-bit values high word first whose high words stayed still:
/// start address → `true` (the word order, for the guess). `blocks` the table's polled blocks (first address, quantity),
/// `reg(a)` what register `a` did.
#[must_use]
pub fn still_word_pairs<'a>(blocks: &[(u16, u16)], reg: &dyn Fn(u16) -> Option<&'a RegStat>) -> BTreeMap<u16, bool> {
    // [aligned with the block's start, shifted by one] × [still first word, still second word]
    let mut votes = [[0u32; 2]; 2];
    // Where the still-first pairs start, aligned with their block and shifted.
    let mut found: [Vec<u16>; 2] = Default::default();
    for &(first, quantity) in blocks {
        for k in 0..quantity.saturating_sub(1) {
            let Some(a) = first.checked_add(k) else { break };
            let (Some(r1), Some(r2)) = (reg(a), a.checked_add(1).and_then(reg)) else { continue };
            let shape = match (r1.changes == 0, r2.changes == 0) {
                (true, false) => 0,
                (false, true) => 1,
                _ => continue,
            };
            let s = usize::from(k % 2);
            votes[s][shape] += 1;
            if shape == 0 {
                found[s].push(a);
            }
        }
    }
    let [aligned, shifted] = votes;
    // Still first words only (none the other way round), at least twice, where the block's
    // start puts the pairs; the shifted reading must not show it as clearly (a run of still
    // registers beside moving ones would).
    match aligned {
        [n, 0] if n >= 2 && shifted[0] < n => std::mem::take(&mut found[0]).into_iter().map(|a| (a, true)).collect(),
        _ => BTreeMap::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reg(values: &[u16]) -> RegStat {
        let mut r = RegStat::default();
        for &v in values {
            r.push(v);
        }
        r
    }

    /// The Display's input 0–7 as `simulate --poll` answers them (31 polls): 73 and a
    /// level around 15 700 (u32 0–1), 0 and a counter (u32 2–3), 73 and a level (4–5), two
    /// settings (6, 7). The pairs at 0, 2 and 4 are 32-bit values high word first; 6 is not.
    #[test]
    fn still_high_words_beside_moving_low_words_are_32_bit_values() {
        let level: Vec<u16> = (0..31).map(|i| 15_680 + (i * 37) % 190).collect();
        let counter: Vec<u16> = (0..31).map(|i| 100 + i * 3).collect();
        let regs: BTreeMap<u16, RegStat> = [
            (0, reg(&[73; 31])),
            (1, reg(&level)),
            (2, reg(&[0; 31])),
            (3, reg(&counter)),
            (4, reg(&[73; 31])),
            (5, reg(&level)),
            (6, reg(&[8000; 31])),
            (7, reg(&[18; 31])),
        ]
        .into_iter()
        .collect();
        let pairs = still_word_pairs(&[(0, 4), (4, 4)], &|a| regs.get(&a));
        assert_eq!(pairs, [(0, true), (2, true), (4, true)].into_iter().collect());
        // One such pair alone is no layout.
        assert!(still_word_pairs(&[(0, 2)], &|a| regs.get(&a)).is_empty());
        // Checked on the simulated bus: the MKZP's currents (moving) beside its
        // insulation resistance and pulsation (still), holding 52–55, stay registers of their own.
        let mkzp: BTreeMap<u16, RegStat> =
            [(52, reg(&level)), (53, reg(&[9500; 31])), (54, reg(&level)), (55, reg(&[0; 31]))].into_iter().collect();
        assert!(still_word_pairs(&[(52, 4)], &|a| mkzp.get(&a)).is_empty());
        // Moving words at both offsets of the block's pairs: nothing is claimed.
        let mixed: BTreeMap<u16, RegStat> =
            [(0, reg(&[73; 31])), (1, reg(&level)), (2, reg(&level)), (3, reg(&[5; 31]))].into_iter().collect();
        assert!(still_word_pairs(&[(0, 4)], &|a| mixed.get(&a)).is_empty());
    }

    /// End to end: the Display (unit 5) polled 31 times for input 0–3 (FC 04, MAP
    /// v1.1b3 §6.4) as `simulate --poll` answers it — the learner drafts two u32 values high
    /// word first (it drafted "constant 73" and a u16 before), trusted at most [`CONFIDENCE`].
    #[test]
    fn the_display_s_fuel_volume_is_drafted_as_a_u32() {
        use super::super::kind::Kind;
        use crate::learn::Learner;
        use mbtap_device::profile::Table;
        /// FC 04, start address 0, quantity 4.
        const READ_INPUT_0_TO_3: [u8; 5] = [0x04, 0x00, 0x00, 0x00, 0x04];
        let mut l = Learner::default();
        for i in 0..31u16 {
            let words = [73, 15_680 + (i * 37) % 190, 0, 100 + i * 3];
            // FC 04, byte count 8, the four words big-endian.
            let mut answer = vec![0x04, 8];
            answer.extend(words.iter().flat_map(|w| w.to_be_bytes()));
            l.observe(5, &READ_INPUT_0_TO_3, &answer, u64::from(i) * 1_220_000_000);
        }
        let guesses = l.units[&5].guesses(Table::InputRegisters);
        let kinds: Vec<(u16, &Kind)> = guesses.iter().map(|g| (g.address, &g.kind)).collect();
        assert_eq!(
            kinds,
            [(0, &Kind::U32 { high_first: true, counter: false }), (2, &Kind::U32 { high_first: true, counter: true })]
        );
        assert!(guesses.iter().all(|g| g.confidence <= CONFIDENCE));
    }
}
