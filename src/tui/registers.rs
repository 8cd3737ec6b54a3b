//! The registers view's data: per unit, the latest value of every register and coil seen on
//! the bus, named and scaled by the unit's profile where there is one, with when it last
//! changed and a short history for a sparkline.

use std::collections::{BTreeMap, VecDeque};

use mbtap_device::profile::Table;
use mbtap_device::profile::annotate::{Annotation, Lang, Shown};
use mbtap_device::profile::image::RegisterImage;

/// Values kept per register for its sparkline.
pub const HISTORY: usize = 48;

/// One register (or a value spanning several, like a 32-bit pair).
#[derive(Debug, Clone, PartialEq)]
pub struct Register {
    pub name: Option<String>,
    /// The value as shown (scaled, with unit or label).
    pub text: String,
    pub raw: i64,
    /// Whether the history is worth a sparkline (a number, not a label or text).
    pub numeric: bool,
    pub changed_ns: u64,
    pub seen_ns: u64,
    pub history: VecDeque<i64>,
}

/// All units' registers.
#[derive(Debug, Clone, Default)]
pub struct Registers {
    pub values: BTreeMap<(u8, Table, u16), Register>,
    image: RegisterImage,
}

impl Registers {
    /// Takes in a completed transaction: its profile annotations when the unit has a profile,
    /// else the raw values read or written.
    pub fn update(
        &mut self,
        unit: u8,
        t_ns: u64,
        request_pdu: &[u8],
        response_pdu: Option<&[u8]>,
        annotations: &[Annotation],
        lang: Lang,
    ) {
        if annotations.is_empty() {
            self.image.values.clear();
            self.image.update(unit, t_ns, request_pdu, response_pdu);
            let raw: Vec<_> = self.image.values.iter().map(|(&k, v)| (k, v.raw)).collect();
            for ((u, table, address), value) in raw {
                self.set((u, table, address), None, value.to_string(), i64::from(value), true, t_ns);
            }
            return;
        }
        for a in annotations {
            let numeric = matches!(a.shown, Shown::Number { .. } | Shown::Raw | Shown::Bool { .. });
            // Names from profile files and strings from the bus: nothing a terminal would obey.
            let name = a.name_in(lang).map(|n| mbtap_analysis::report::format::printable(n).into_owned());
            let text = mbtap_analysis::report::format::printable(&a.value_text()).into_owned();
            self.set((unit, a.table, a.address), name, text, a.raw, numeric, t_ns);
        }
    }

    fn set(&mut self, key: (u8, Table, u16), name: Option<String>, text: String, raw: i64, numeric: bool, t: u64) {
        let r = self.values.entry(key).or_insert_with(|| Register {
            name: None,
            text: String::new(),
            raw,
            numeric,
            changed_ns: t,
            seen_ns: t,
            history: VecDeque::with_capacity(HISTORY),
        });
        if r.raw != raw {
            r.changed_ns = t;
        }
        r.name = name;
        r.text = text;
        r.raw = raw;
        r.numeric = numeric;
        r.seen_ns = t;
        if r.history.len() == HISTORY {
            r.history.pop_front();
        }
        r.history.push_back(raw);
    }

    /// Units with known registers.
    #[must_use]
    pub fn units(&self) -> Vec<u8> {
        let mut units: Vec<u8> = self.values.keys().map(|k| k.0).collect();
        units.dedup();
        units
    }

    /// One unit's registers in table and address order.
    pub fn of(&self, unit: u8) -> impl Iterator<Item = (Table, u16, &Register)> {
        self.values.range((unit, Table::Coils, 0)..=(unit, Table::InputRegisters, u16::MAX)).map(|(k, r)| (k.1, k.2, r))
    }
}

/// A history as a one-line sparkline of block characters, scaled to its own range.
#[must_use]
pub fn sparkline(history: &VecDeque<i64>, width: usize) -> String {
    const BARS: [char; 8] = ['▁', '▂', '▃', '▄', '▅', '▆', '▇', '█'];
    let start = history.len().saturating_sub(width);
    let shown: Vec<i64> = history.iter().skip(start).copied().collect();
    let (Some(&lo), Some(&hi)) = (shown.iter().min(), shown.iter().max()) else { return String::new() };
    let span = i128::from(hi) - i128::from(lo);
    shown
        .iter()
        .map(|&v| {
            let level = if span == 0 { 3 } else { (i128::from(v) - i128::from(lo)) * 7 / span };
            BARS[usize::try_from(level).unwrap_or(0).min(7)]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sparkline_spans_its_own_range() {
        let h: VecDeque<i64> = [0, 7, 14, 7, 0].into_iter().collect();
        assert_eq!(sparkline(&h, 10), "▁▄█▄▁");
        assert_eq!(sparkline(&h, 2), "█▁", "the last two, scaled to their own range");
        let flat: VecDeque<i64> = [5, 5].into_iter().collect();
        assert_eq!(sparkline(&flat, 10), "▄▄");
        assert_eq!(sparkline(&VecDeque::new(), 10), "");
    }

    #[test]
    fn raw_values_without_a_profile_and_their_changes() {
        // Unit 9 reads holding 100..101 = [1, 2], later [1, 3]: the PDUs pairing hands over.
        // Request: function 03, address 0064, quantity 0002.
        const READ_100_TWO: [u8; 5] = [0x03, 0x00, 0x64, 0x00, 0x02];
        // Responses: function 03, byte count 04, values 0001 0002, then 0001 0003.
        const VALUES_1_2: [u8; 6] = [0x03, 0x04, 0x00, 0x01, 0x00, 0x02];
        const VALUES_1_3: [u8; 6] = [0x03, 0x04, 0x00, 0x01, 0x00, 0x03];
        let mut r = Registers::default();
        r.update(9, 10, &READ_100_TWO, Some(&VALUES_1_2), &[], Lang::En);
        r.update(9, 20, &READ_100_TWO, Some(&VALUES_1_3), &[], Lang::En);
        let regs: Vec<_> = r.of(9).collect();
        assert_eq!(regs.len(), 2);
        assert_eq!((regs[0].1, regs[0].2.raw, regs[0].2.changed_ns), (100, 1, 10), "unchanged since 10");
        assert_eq!((regs[1].1, regs[1].2.raw, regs[1].2.changed_ns), (101, 3, 20), "changed at 20");
        assert_eq!(regs[1].2.history, [2, 3]);
        assert_eq!(r.units(), [9]);
    }
}
