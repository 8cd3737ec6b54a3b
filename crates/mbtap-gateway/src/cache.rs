//! The bridge's register cache (`--cache UNITS:TABLE:FIRST-LAST=MAX_AGE`): reads of covered
//! registers are answered from memory while every register asked for is younger than its
//! rule's maximum age, otherwise they go to the line and the answer fills the cache. Writes
//! that reach the line invalidate what they overlap (whatever their outcome: a write that timed
//! out may have been done). Exceptions are never cached. Time is an input (a `Duration` since the caller's origin): no clock here.

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use mbtap_proto::Table;

use crate::BadValue;
use mbtap_proto::table::{is_bits, read_function, table_read_by, table_word};

/// One `--cache` rule.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rule {
    pub units: BTreeSet<u8>,
    pub table: Table,
    pub first: u16,
    pub last: u16,
    pub max_age: Duration,
}

/// `1:holding:0-9=1s`, `1,5-7:input:430-433=500ms`.
///
/// # Errors
/// What part is wrong, with the value.
pub fn parse_rule(spec: &str) -> Result<Rule, BadValue> {
    let bad = |what: &str| {
        BadValue(format!("--cache {spec:?}: {what}; expected UNITS:TABLE:FIRST-LAST=MAX_AGE, e.g. 1:holding:0-9=1s"))
    };
    let (head, age) = spec.split_once('=').ok_or_else(|| bad("no =MAX_AGE"))?;
    let mut parts = head.splitn(3, ':');
    let (units, table, range) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let units = crate::parse::parse_units(units).map_err(|e| bad(&e.0))?;
    if units.is_empty() {
        return Err(bad("no unit"));
    }
    let table =
        table_word(table.trim()).ok_or_else(|| bad(&format!("{table:?} is not coils, discrete, holding or input")))?;
    let (a, b) = range.split_once('-').unwrap_or((range, range));
    let num = |s: &str| s.trim().parse::<u16>().map_err(|_| bad(&format!("{s:?} is not an address 0..=65535")));
    let (first, last) = (num(a)?, num(b)?);
    if last < first {
        return Err(bad("the range runs backwards"));
    }
    // More than nothing (an age of 0 would cache nothing), at most a day.
    let max_age = mbtap_proto::duration::parse_duration(age, Duration::from_millis(1), Duration::from_hours(24))
        .map_err(|e| bad(&e))?;
    Ok(Rule { units, table, first, last, max_age })
}

/// One `--poll` rule: the bridge reads these registers itself every `interval` (agent mode),
/// keeping the cache fresh for its clients.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Poll {
    pub rule: Rule,
    pub interval: Duration,
}

/// `1:holding:100-109@1s`: as a cache rule, with `@INTERVAL` for its age. The cached values
/// are kept for two intervals (a poll that is late by less than one still finds them fresh).
///
/// # Errors
/// What part is wrong, with the value.
pub fn parse_poll(spec: &str) -> Result<Poll, BadValue> {
    let (head, interval) = spec.rsplit_once('@').ok_or_else(|| {
        BadValue(format!("--poll {spec:?}: expected UNITS:TABLE:FIRST-LAST@INTERVAL, e.g. 1:holding:100-109@1s"))
    })?;
    let rule = parse_rule(&format!("{head}={interval}")).map_err(|e| BadValue(e.0.replacen("--cache", "--poll", 1)))?;
    let interval = rule.max_age;
    Ok(Poll { rule: Rule { max_age: interval.saturating_mul(2), ..rule }, interval })
}

impl Poll {
    /// The read requests (PDUs) that cover the rule for one unit, split at the spec's limits
    /// (MAP v1.1b3 §6.1–§6.4: 2000 bits, 125 registers).
    #[must_use]
    pub fn requests(&self) -> Vec<Vec<u8>> {
        let limit: u32 = if is_bits(self.rule.table) { 2000 } else { 125 };
        let mut out = Vec::new();
        let mut a = u32::from(self.rule.first);
        let last = u32::from(self.rule.last);
        while a <= last {
            let n = (last - a + 1).min(limit);
            let mut pdu = vec![read_function(self.rule.table)];
            pdu.extend_from_slice(&u16::try_from(a).unwrap_or(u16::MAX).to_be_bytes());
            pdu.extend_from_slice(&u16::try_from(n).unwrap_or(1).to_be_bytes());
            out.push(pdu);
            a += n;
        }
        out
    }
}

/// The cache of one line, and the writes queued or on the line that it must not answer past.
#[derive(Debug, Default)]
pub struct Cache {
    rules: Vec<Rule>,
    values: BTreeMap<(u8, Table, u16), (u16, Duration)>,
    /// Writes begun and not yet done, by id: a read they may change is not answered from
    /// memory (a client pipelining "write h101, read h101" read the old value).
    writes: BTreeMap<WriteId, (u8, Vec<u8>)>,
    next_write: u64,
}

/// A write among those not yet done ([`Cache::write_begins`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct WriteId(u64);

/// A read request's table, address and quantity, when it is one.
fn read_of(pdu: &[u8]) -> Option<(Table, u16, u16)> {
    let table = table_read_by(*pdu.first()?)?;
    let address = u16::from_be_bytes([*pdu.get(1)?, *pdu.get(2)?]);
    let quantity = u16::from_be_bytes([*pdu.get(3)?, *pdu.get(4)?]);
    (pdu.len() == 5 && quantity > 0).then_some((table, address, quantity))
}

impl Cache {
    #[must_use]
    pub fn new(rules: Vec<Rule>) -> Self {
        Self { rules, ..Self::default() }
    }

    /// A write `pdu` to `unit` is queued: until [`Self::write_ends`], no read it may change is
    /// answered from memory. `None` when the cache is off or `pdu` writes nothing it holds.
    pub fn write_begins(&mut self, unit: u8, pdu: &[u8]) -> Option<WriteId> {
        if !self.is_on() {
            return None;
        }
        written_range(pdu)?;
        let id = WriteId(self.next_write);
        self.next_write = self.next_write.wrapping_add(1);
        self.writes.insert(id, (unit, pdu.to_vec()));
        Some(id)
    }

    /// The write is done (answered, failed, or dropped unsent).
    pub fn write_ends(&mut self, id: WriteId) {
        self.writes.remove(&id);
    }

    /// Whether there are rules at all.
    #[must_use]
    pub fn is_on(&self) -> bool {
        !self.rules.is_empty()
    }

    fn max_age(&self, unit: u8, table: Table, address: u16) -> Option<Duration> {
        self.rules
            .iter()
            .filter(|r| r.table == table && r.units.contains(&unit) && (r.first..=r.last).contains(&address))
            .map(|r| r.max_age)
            .min()
    }

    /// The answer from memory to `pdu` for `unit` at `now`, when every register it reads is
    /// covered and fresh, and no write not yet done may change it (read your own write).
    #[must_use]
    pub fn lookup(&self, unit: u8, pdu: &[u8], now: Duration) -> Option<Vec<u8>> {
        let (table, address, quantity) = read_of(pdu)?;
        if self.writes.values().any(|(u, w)| read_overlaps_write(unit, pdu, *u, w)) {
            return None;
        }
        let mut values = Vec::with_capacity(usize::from(quantity));
        for i in 0..quantity {
            let a = address.checked_add(i)?;
            let max_age = self.max_age(unit, table, a)?;
            let &(v, at) = self.values.get(&(unit, table, a))?;
            if now.saturating_sub(at) > max_age {
                return None;
            }
            values.push(v);
        }
        let mut out = vec![read_function(table)];
        if is_bits(table) {
            // MAP v1.1b3 §6.1: packed, LSB of the first byte is the first point.
            let mut bytes = vec![0u8; values.len().div_ceil(8)];
            for (i, v) in values.iter().enumerate() {
                if *v != 0 {
                    bytes[i / 8] |= 1 << (i % 8);
                }
            }
            out.push(u8::try_from(bytes.len()).ok()?);
            out.extend(bytes);
        } else {
            out.push(u8::try_from(values.len() * 2).ok()?);
            out.extend(values.iter().flat_map(|v| v.to_be_bytes()));
        }
        Some(out)
    }

    /// A normal answer `response` to `request` for `unit`, received at `now`: the covered
    /// registers are kept. Exceptions and malformed answers are not.
    pub fn fill(&mut self, unit: u8, request: &[u8], response: &[u8], now: Duration) {
        let Some((table, address, quantity)) = read_of(request) else { return };
        if response.first() != Some(&read_function(table)) {
            return;
        }
        let data = response.get(2..).unwrap_or_default();
        for i in 0..quantity {
            let Some(a) = address.checked_add(i) else { break };
            if self.max_age(unit, table, a).is_none() {
                continue;
            }
            let i = usize::from(i);
            let v = if is_bits(table) {
                data.get(i / 8).map(|b| u16::from(b >> (i % 8) & 1))
            } else {
                data.get(i * 2..i * 2 + 2).map(|p| u16::from_be_bytes([p[0], p[1]]))
            };
            if let Some(v) = v {
                self.values.insert((unit, table, a), (v, now));
            }
        }
    }

    /// A write `request` sent to `unit` (broadcast: every unit): what it may have changed is
    /// forgotten — holding registers for 06/10/16/17, coils for 05/0F.
    pub fn invalidate(&mut self, unit: u8, request: &[u8]) {
        let Some((table, address, last)) = written_range(request) else { return };
        self.values.retain(|&(u, t, a), _| !((u == unit || unit == 0) && t == table && (address..=last).contains(&a)));
    }
}

/// What a write request may change: its table and first and last address — holding registers
/// for 06/10/16/17, coils for 05/0F (MAP v1.1b3 §6.5, 6.6, 6.11, 6.12, 6.16, 6.17).
#[must_use]
pub fn written_range(request: &[u8]) -> Option<(Table, u16, u16)> {
    let field = |i: usize| request.get(i..i + 2).map(|p| u16::from_be_bytes([p[0], p[1]]));
    let (table, address, quantity) = match request.first() {
        Some(0x05) => (Table::Coils, field(1), Some(1)),
        Some(0x0F) => (Table::Coils, field(1), field(3)),
        Some(0x06 | 0x16) => (Table::HoldingRegisters, field(1), Some(1)),
        Some(0x10) => (Table::HoldingRegisters, field(1), field(3)),
        // 17: the write part starts at byte 5 (MAP v1.1b3 §6.17).
        Some(0x17) => (Table::HoldingRegisters, field(5), field(7)),
        _ => return None,
    };
    let (address, quantity) = (address?, quantity?);
    Some((table, address, address.saturating_add(quantity.saturating_sub(1))))
}

/// Whether the read `read` (a request PDU) overlaps what the write `write` may change, on the
/// same unit (a broadcast write overlaps every unit).
#[must_use]
pub fn read_overlaps_write(unit: u8, read: &[u8], write_unit: u8, write: &[u8]) -> bool {
    let (Some((table, address, quantity)), Some((wt, first, last))) = (read_of(read), written_range(write)) else {
        return false;
    };
    let end = address.saturating_add(quantity - 1);
    (unit == write_unit || write_unit == 0) && table == wt && address <= last && first <= end
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Read holding 0–1 of unit 1 (03 0000 0002) and its answer 03 04 000A 000B.
    const READ: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x02];
    const ANSWER: [u8; 6] = [0x03, 0x04, 0x00, 0x0A, 0x00, 0x0B];

    #[test]
    fn answered_from_memory_while_fresh_and_forgotten_on_write() {
        let t0 = Duration::from_secs(10);
        let mut c = Cache::new(vec![parse_rule("1:holding:0-9=1s").unwrap()]);
        assert_eq!(c.lookup(1, &READ, t0), None, "empty");
        c.fill(1, &READ, &ANSWER, t0);
        assert_eq!(c.lookup(1, &READ, t0 + Duration::from_millis(900)), Some(ANSWER.to_vec()));
        assert_eq!(c.lookup(1, &READ, t0 + Duration::from_millis(1001)), None, "stale");
        assert_eq!(c.lookup(2, &READ, t0), None, "another unit");
        // Holding 1..10: 10 is outside the rule.
        assert_eq!(c.lookup(1, &[0x03, 0x00, 0x01, 0x00, 0x0A], t0), None);
        // A write to holding 1 (06 0001 0007) forgets it, not holding 0.
        c.invalidate(1, &[0x06, 0x00, 0x01, 0x00, 0x07]);
        assert_eq!(c.lookup(1, &READ, t0), None);
        assert_eq!(c.lookup(1, &[0x03, 0x00, 0x00, 0x00, 0x01], t0), Some(vec![0x03, 0x02, 0x00, 0x0A]));
    }

    /// The core decides which writes the cache waits for (the shell only keeps them).
    #[test]
    fn a_read_behind_a_write_not_yet_done_is_not_answered_from_memory() {
        let t0 = Duration::from_secs(10);
        let mut c = Cache::new(vec![parse_rule("1:holding:0-9=1s").unwrap()]);
        c.fill(1, &READ, &ANSWER, t0);
        // Write single register 1 = 7 (06 0001 0007), queued.
        let w = c.write_begins(1, &[0x06, 0x00, 0x01, 0x00, 0x07]).unwrap();
        assert_eq!(c.lookup(1, &READ, t0), None, "the write may change register 1");
        assert!(c.write_begins(1, &READ).is_none(), "a read writes nothing");
        c.write_ends(w);
        assert_eq!(c.lookup(1, &READ, t0), Some(ANSWER.to_vec()), "this test does not invalidate");
        let off = &mut Cache::new(Vec::new());
        assert!(off.write_begins(1, &[0x06, 0x00, 0x01, 0x00, 0x07]).is_none(), "no cache, nothing kept");
    }

    #[test]
    fn a_read_overlaps_the_writes_that_may_change_it() {
        let write_101 = [0x06, 0x00, 0x65, 0x00, 0x09];
        assert!(read_overlaps_write(1, &[0x03, 0x00, 0x65, 0x00, 0x01], 1, &write_101));
        assert!(read_overlaps_write(1, &[0x03, 0x00, 0x60, 0x00, 0x08], 1, &write_101));
        assert!(!read_overlaps_write(1, &[0x03, 0x00, 0x66, 0x00, 0x02], 1, &write_101), "after it");
        assert!(!read_overlaps_write(2, &[0x03, 0x00, 0x65, 0x00, 0x01], 1, &write_101), "another unit");
        assert!(read_overlaps_write(2, &[0x03, 0x00, 0x65, 0x00, 0x01], 0, &write_101), "a broadcast");
        assert!(!read_overlaps_write(1, &[0x04, 0x00, 0x65, 0x00, 0x01], 1, &write_101), "input registers");
        assert!(read_overlaps_write(
            1,
            &[0x01, 0x00, 0x00, 0x00, 0x10],
            1,
            &[0x0F, 0x00, 0x08, 0x00, 0x02, 0x01, 0x03]
        ));
    }

    #[test]
    fn exceptions_are_never_cached_and_bits_pack() {
        let t0 = Duration::from_secs(10);
        let mut c = Cache::new(vec![parse_rule("1:holding:0-9=1s").unwrap(), parse_rule("1:coils:0-7=1s").unwrap()]);
        c.fill(1, &READ, &[0x83, 0x02], t0);
        assert_eq!(c.lookup(1, &READ, t0), None);
        // Coils 0–4 = 1,0,1,1,0 (01 01 0D).
        c.fill(1, &[0x01, 0x00, 0x00, 0x00, 0x05], &[0x01, 0x01, 0x0D], t0);
        assert_eq!(c.lookup(1, &[0x01, 0x00, 0x01, 0x00, 0x03], t0), Some(vec![0x01, 0x01, 0x06]));
    }

    #[test]
    fn polls_cover_their_range_in_requests_the_spec_allows() {
        let p = parse_poll("1:holding:0-299@1s").unwrap();
        assert_eq!((p.interval, p.rule.max_age), (Duration::from_secs(1), Duration::from_secs(2)));
        let r = p.requests();
        assert_eq!(r, [vec![3, 0, 0, 0, 125], vec![3, 0, 125, 0, 125], vec![3, 0, 250, 0, 50]]);
        assert!(parse_poll("1:holding:0-9").unwrap_err().0.contains("--poll"));
    }

    #[test]
    fn rules_say_what_is_wrong() {
        assert!(parse_rule("1:holding:0-9").unwrap_err().0.contains("=MAX_AGE"));
        assert!(parse_rule("1:register:0-9=1s").unwrap_err().0.contains("\"register\""));
        assert!(parse_rule("1:holding:9-0=1s").unwrap_err().0.contains("backwards"));
        assert!(parse_rule("1:holding:0-9=0s").is_err());
        let r = parse_rule("1,5-6:input:430-433=500ms").unwrap();
        assert_eq!((r.units.len(), r.first, r.last, r.max_age), (3, 430, 433, Duration::from_millis(500)));
    }
}
