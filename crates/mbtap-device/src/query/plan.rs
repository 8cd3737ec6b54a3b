//! Targets split into read requests the spec and the device allow: at most 125 registers
//! (MAP v1.1b3 §6.3 and §6.4: quantity 1 to 125, 0x7D) or 2000 bits (§6.1 and §6.2: 1 to
//! 2000, 0x7D0) per request, never across an address the device's document reserves (devices
//! answer exception 02 for the whole request), never across an address the profile does not map
//! when it maps others in the range (`input 0..342` of a meter: the values it names, not three
//! 02s for its gaps), and never through the middle of a multi-register value (each half would
//! be read at a different time).

use super::resolve::Target;
use super::{QueryError, is_bits};
use crate::profile::{Profile, Table};

/// MAP v1.1b3 §6.3/§6.4: at most 125 registers in one read.
pub const MAX_READ_REGISTERS: u16 = 125;
/// MAP v1.1b3 §6.1/§6.2: at most 2000 coils or discrete inputs in one read.
pub const MAX_READ_BITS: u16 = 2000;

/// One read request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Read {
    /// Which target (index into the planned targets) it serves.
    pub target: usize,
    pub table: Table,
    pub address: u16,
    pub quantity: u16,
}

impl Read {
    /// The function code that reads `table` (MAP v1.1b3 §6.1–§6.4).
    #[must_use]
    pub const fn function(&self) -> u8 {
        super::read_function(self.table)
    }
}

/// A plan: the reads, and the addresses left out (to tell the user): reserved by the document,
/// or not in the profile's map.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Plan {
    pub reads: Vec<Read>,
    pub skipped: Vec<(usize, Table, u16, u16)>,
    pub unmapped: Vec<(usize, Table, u16, u16)>,
}

/// Why an address is not read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Gap {
    Reserved,
    Unmapped,
}

/// Splits `targets` into reads. See the module documentation.
pub fn plan(targets: &[Target], p: Option<&Profile>) -> Result<Plan, QueryError> {
    let mut out = Plan::default();
    for (i, t) in targets.iter().enumerate() {
        let limit = if is_bits(t.table) { MAX_READ_BITS } else { MAX_READ_REGISTERS };
        // The profile's map counts only where it maps something in the range: a range it knows
        // nothing of is read as asked (raw values, for exploring).
        let maps_some = p.is_some_and(|p| (t.first..=t.last).any(|a| p.slot(t.table, a).is_some()));
        let gap = |a: u16| match p {
            Some(p) if p.is_reserved(t.table, a) => Some(Gap::Reserved),
            Some(p) if maps_some && p.slot(t.table, a).is_none() => Some(Gap::Unmapped),
            _ => None,
        };
        let before = out.reads.len();
        let mut a = u32::from(t.first);
        let last = u32::from(t.last);
        while a <= last {
            // Bounded by the u16 range: a and last are u16 values widened.
            let at = u16::try_from(a).unwrap_or(u16::MAX);
            if let Some(why) = gap(at) {
                let mut end = a;
                while end < last && gap(u16::try_from(end + 1).unwrap_or(u16::MAX)) == Some(why) {
                    end += 1;
                }
                let run = (i, t.table, at, u16::try_from(end).unwrap_or(u16::MAX));
                match why {
                    Gap::Reserved => out.skipped.push(run),
                    Gap::Unmapped => out.unmapped.push(run),
                }
                a = end + 1;
                continue;
            }
            // As far as the limit, the target's end or the next address not read.
            let mut end = a;
            while end < last
                && end + 1 - a < u32::from(limit)
                && gap(u16::try_from(end + 1).unwrap_or(u16::MAX)).is_none()
            {
                end += 1;
            }
            // Cut before a value that would straddle the request's end.
            if end < last
                && let Some(p) = p
                && let Some((slot, def)) = p.slot(t.table, u16::try_from(end).unwrap_or(u16::MAX))
                && u32::from(slot.first) + u32::from(def.width) - 1 > end
                && u32::from(slot.first) > a
            {
                end = u32::from(slot.first) - 1;
            }
            out.reads.push(Read {
                target: i,
                table: t.table,
                address: at,
                quantity: u16::try_from(end - a + 1).unwrap_or(limit),
            });
            a = end + 1;
        }
        if out.reads.len() == before {
            return Err(QueryError::AllReserved { item: t.item.text.clone() });
        }
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::super::items::parse_item;
    use super::super::resolve::resolve;
    use super::*;

    fn plan_of(items: &[&str], p: Option<&Profile>) -> Plan {
        let targets: Vec<Target> = items.iter().map(|i| resolve(&parse_item(i, None).unwrap(), p).unwrap()).collect();
        plan(&targets, p).unwrap()
    }

    #[test]
    fn split_at_the_spec_quantity_limits() {
        let p = plan_of(&["holding 0..299", "coils 0..4999"], None);
        let q: Vec<(u16, u16)> = p.reads.iter().map(|r| (r.address, r.quantity)).collect();
        assert_eq!(q, [(0, 125), (125, 125), (250, 50), (0, 2000), (2000, 2000), (4000, 1000)]);
    }

    #[test]
    fn reserved_addresses_are_left_out_and_told() {
        let mk4 = crate::profile::builtin::get("mk4").unwrap().unwrap();
        let (t, a, b) = *mk4.reserved.first().expect("the MK4 document reserves addresses");
        let first = a.saturating_sub(1);
        let last = b.saturating_add(1);
        let item = format!(
            "{} {first}..{last}",
            match t {
                Table::Coils => "coils",
                Table::DiscreteInputs => "discrete",
                Table::HoldingRegisters => "holding",
                Table::InputRegisters => "input",
            }
        );
        let p = plan_of(&[&item], Some(&mk4));
        assert!(p.reads.iter().all(|r| !(a..=b).contains(&r.address)), "{p:?}");
        assert_eq!(p.skipped.first().map(|s| (s.2, s.3)), Some((a, b)), "{p:?}");
    }

    /// The SDM630 maps input 0–47 with gaps (44–45 is no value of its map): a read of 40..49
    /// asks for what the map names and leaves the gap out, told.
    #[test]
    fn unmapped_addresses_between_mapped_ones_are_left_out_and_told() {
        let sdm = crate::profile::builtin::get("sdm630").unwrap().unwrap();
        let p = plan_of(&["input 40..49"], Some(&sdm));
        let q: Vec<(u16, u16)> = p.reads.iter().map(|r| (r.address, r.quantity)).collect();
        assert_eq!(q, [(40, 4), (46, 4)], "{p:?}");
        assert_eq!(p.unmapped.iter().map(|s| (s.2, s.3)).collect::<Vec<_>>(), [(44, 45)]);
        // A range the profile maps nothing of is read as asked.
        let raw = plan_of(&["input 1000..1009"], Some(&sdm));
        assert_eq!(raw.reads.iter().map(|r| (r.address, r.quantity)).collect::<Vec<_>>(), [(1000, 10)]);
    }
}
