//! `mbtap probe`: active, **read-only** discovery of a device's map, as a state machine that
//! says which request to send next and when, and takes the answers (sans-IO: the edge sends,
//! waits and reports; time is an input).
//!
//! Only reads (functions 01–04, MAP v1.1b3 §6.1–6.4) are ever asked for. Per table, the range is
//! read in blocks of the largest quantity the device accepts (exception 03, illegal data value,
//! halves it); a block answered with exception 02 (illegal data address) is bisected until the
//! addresses that answer and the boundaries of those that do not are found — so present
//! stretches cost one request per block and absent ones at most one per address. Exception 01
//! (illegal function) skips the table. The first sign of distress — no answer, exception 06
//! (server busy) or 05 (acknowledge: a long operation) or anything unexpected — stops the probe
//! and says why: a device that is struggling is not pushed further. Requests are paced at the
//! rate asked for.

use std::collections::BTreeMap;

use mbtap_device::profile::Table;
use mbtap_device::query::is_bits;

mod found;

/// MAP v1.1b3 §6.3/§6.4: at most 125 registers per read.
const MAX_REGISTERS: u16 = 125;
/// MAP v1.1b3 §6.1/§6.2: at most 2000 coils or inputs per read.
const MAX_BITS: u16 = 2000;
/// Exception codes (MAP v1.1b3 §7).
const ILLEGAL_FUNCTION: u8 = 0x01;
const ILLEGAL_DATA_ADDRESS: u8 = 0x02;
const ILLEGAL_DATA_VALUE: u8 = 0x03;

/// What to do next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Send this read now.
    Read { table: Table, address: u16, quantity: u16 },
    /// Nothing before this time (ns): the rate.
    WaitUntil(u64),
    /// Finished (or stopped: see [`Probe::stopped`]).
    Done,
}

/// How a read ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// Values (registers, or bits as 0/1).
    Values(Vec<u16>),
    Exception(u8),
    /// No answer in time, or a broken link.
    NoAnswer(String),
    /// The device closed the connection the read went out on (nothing came back on it); the
    /// next read opens a new one.
    Closed(String),
}

/// What the probe found in one table.
#[derive(Debug, Clone, Default)]
pub struct TableFound {
    /// Addresses that answered, with the value read.
    pub present: BTreeMap<u16, u16>,
    /// The largest quantity the device accepted in one read (answered, or refused only for an
    /// address: a server checks the quantity before the address, MAP v1.1b3 §7 Figure 9).
    pub max_block: Option<u16>,
    /// The smallest quantity refused with exception 03.
    pub refused_block: Option<u16>,
    /// The table is not supported (exception 01).
    pub unsupported: bool,
}

/// The probe.
#[derive(Debug, Clone)]
pub struct Probe {
    tables: Vec<Table>,
    first: u16,
    last: u16,
    interval_ns: u64,
    /// Ranges still to read in the current table, the last one next: `(first, count)`.
    todo: Vec<(u16, u32)>,
    table_index: usize,
    /// The quantity to ask next: doubled after an answer (up to `max_q`), 1 after an
    /// exception 02 (to see whether the block's first address is the absent one).
    q: u16,
    /// The largest quantity not refused with exception 03.
    max_q: u16,
    /// The read sent and not yet answered.
    sent: Option<(Table, u16, u16)>,
    next_at: u64,
    pub found: BTreeMap<Table, TableFound>,
    pub requests: u64,
    /// Single addresses found absent in a row: the stride of the gallop over an absent stretch.
    streak: u32,
    /// The stretch the last gallop stepped over, unread: `(first, count)`.
    skipped: Option<(u16, u32)>,
    /// Where an absent stretch turns present, between a known absent address and a known
    /// present one with unread addresses between: `(absent, present)`, narrowed by halves.
    search: Option<(u32, u32)>,
    /// Addresses stepped over by galloping and not read (taken as absent).
    pub assumed_absent: u64,
    /// The most addresses stepped over at once ([`DEFAULT_MAX_SKIP`]; 0: every address read).
    pub max_skip: u32,
    /// Why the probe stopped early.
    pub stopped: Option<String>,
    /// The read now pending is a second try, on a new connection, of one whose connection the
    /// device closed.
    reopened: bool,
}

/// Inside an absent stretch, at most this many addresses are stepped over at once: a present
/// stretch of 4 or more is always found; a shorter one between absent addresses may be missed
/// (the summary says how many addresses were stepped over; `--thorough` reads every one).
/// An absent stretch costs a read per 4 addresses.
pub const DEFAULT_MAX_SKIP: u32 = 3;

impl Probe {
    /// A probe of `tables` over `first..=last` at most `rate` requests per second.
    #[must_use]
    pub fn new(tables: &[Table], first: u16, last: u16, rate: f64) -> Self {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let interval_ns = if rate > 0.0 { (1e9 / rate) as u64 } else { 0 };
        let mut p = Self {
            tables: tables.to_vec(),
            first: first.min(last),
            last: last.max(first),
            interval_ns,
            todo: Vec::new(),
            table_index: 0,
            q: 1,
            max_q: 1,
            sent: None,
            next_at: 0,
            found: BTreeMap::new(),
            requests: 0,
            streak: 0,
            skipped: None,
            search: None,
            assumed_absent: 0,
            max_skip: DEFAULT_MAX_SKIP,
            stopped: None,
            reopened: false,
        };
        p.start_table();
        p
    }

    fn table(&self) -> Option<Table> {
        self.tables.get(self.table_index).copied()
    }

    fn start_table(&mut self) {
        self.todo.clear();
        self.streak = 0;
        self.skipped = None;
        self.search = None;
        if let Some(t) = self.table() {
            self.max_q = if is_bits(t) { MAX_BITS } else { MAX_REGISTERS };
            self.q = self.max_q;
            let count = u32::from(self.last) - u32::from(self.first) + 1;
            self.todo.push((self.first, count));
            self.found.entry(t).or_default();
        }
    }

    fn next_table(&mut self) {
        self.table_index += 1;
        self.start_table();
    }

    /// What to do at time `now_ns`.
    pub fn next(&mut self, now_ns: u64) -> Step {
        if self.stopped.is_some() || self.sent.is_some() {
            return Step::Done;
        }
        loop {
            let Some(table) = self.table() else { return Step::Done };
            let read = match self.search {
                Some((lo, hi)) if hi - lo > 1 => Some((u16::try_from(lo + (hi - lo) / 2).unwrap_or(u16::MAX), 1)),
                _ => {
                    self.search = None;
                    self.todo
                        .last()
                        .map(|&(a, count)| (a, u16::try_from(count.min(u32::from(self.q))).unwrap_or(self.q).max(1)))
                }
            };
            let Some((address, quantity)) = read else {
                self.next_table();
                continue;
            };
            if now_ns < self.next_at {
                return Step::WaitUntil(self.next_at);
            }
            self.sent = Some((table, address, quantity));
            self.requests += 1;
            self.next_at = now_ns.saturating_add(self.interval_ns);
            return Step::Read { table, address, quantity };
        }
    }

    /// The answer to the read last sent.
    pub fn reply(&mut self, reply: &Reply) {
        let Some((table, address, quantity)) = self.sent.take() else { return };
        let span = || format!("{} {address}..{}", table.word(), u32::from(address) + u32::from(quantity) - 1);
        // Some devices and gateways end their connection after each request: the read that
        // went out on the closed one goes again, once, on a new one — at the same pace, as
        // `next` gives it (else the probe stops at its second read).
        let reopened = std::mem::take(&mut self.reopened);
        if let Reply::Closed(why) = reply {
            if reopened {
                self.stopped = Some(format!(
                    "{}: {why} — and closed the new one too, without answering; stopped (the device takes connections but answers none: is it the right unit and port?)",
                    span()
                ));
            } else {
                self.reopened = true;
            }
            return;
        }
        // A single read narrowing where an absent stretch turns present.
        if let Some((lo, hi)) = self.search
            && quantity == 1
            && u32::from(address) == lo + (hi - lo) / 2
        {
            let mid = u32::from(address);
            self.assumed_absent = self.assumed_absent.saturating_sub(1);
            match reply {
                Reply::Values(v) if !v.is_empty() => {
                    self.found.entry(table).or_default().present.insert(address, v[0]);
                    // Between here and the present end: not read, likely present — read them.
                    if hi - mid > 1 {
                        self.assumed_absent = self.assumed_absent.saturating_sub(u64::from(hi - mid - 1));
                        self.todo.push((address.saturating_add(1), hi - mid - 1));
                    }
                    self.search = Some((lo, mid));
                    return;
                }
                Reply::Exception(ILLEGAL_DATA_ADDRESS) => {
                    self.search = Some((mid, hi));
                    return;
                }
                _ => {}
            }
        }
        let Some(&(first, count)) = self.todo.last() else { return };
        let found = self.found.entry(table).or_default();
        match reply {
            Reply::Values(v) => {
                if v.len() < usize::from(quantity) {
                    self.stopped = Some(format!(
                        "{}: {} value(s) for {quantity} asked — a damaged or foreign answer; stopped",
                        span(),
                        v.len()
                    ));
                    return;
                }
                for (i, &val) in v.iter().take(usize::from(quantity)).enumerate() {
                    if let Ok(i) = u16::try_from(i) {
                        found.present.insert(address.saturating_add(i), val);
                    }
                }
                found.max_block = Some(found.max_block.map_or(quantity, |m| m.max(quantity)));
                self.advance(first, count, u32::from(quantity));
                self.q = quantity.saturating_mul(2).min(self.max_q);
                self.streak = 0;
                // Present right after a stretch stepped over: find where the stretch turns
                // present, by halves.
                if let Some((s, k)) = self.skipped.take()
                    && u32::from(s) + k == u32::from(address)
                {
                    self.search = Some((u32::from(s) - 1, u32::from(address)));
                }
            }
            Reply::Exception(ILLEGAL_FUNCTION) => {
                found.unsupported = true;
                self.next_table();
            }
            Reply::Exception(ILLEGAL_DATA_VALUE) if quantity > 1 => {
                // Too many at once for this device: halve and ask again.
                found.refused_block = Some(found.refused_block.map_or(quantity, |m| m.min(quantity)));
                self.max_q = (quantity / 2).max(1);
                self.q = self.max_q;
            }
            Reply::Exception(ILLEGAL_DATA_ADDRESS) if quantity > 1 => {
                // A server checks the quantity before the address (MAP v1.1b3 §7): accepted.
                found.max_block = Some(found.max_block.map_or(quantity, |m| m.max(quantity)));
                // Somewhere in the block an address does not answer: is it the first?
                self.q = 1;
            }
            Reply::Exception(ILLEGAL_DATA_ADDRESS | ILLEGAL_DATA_VALUE) => {
                // This address does not answer. Absent addresses come in stretches: after each
                // one in a row, step over twice as many (up to `max_skip`) unread; if the next
                // one read answers, where the stretch turns present is found by halves.
                self.streak = self.streak.saturating_add(1);
                let skip = ((1u32 << (self.streak - 1).min(16)) - 1).min(self.max_skip).min(count - 1);
                self.skipped = (skip > 0).then(|| (address.saturating_add(1), skip));
                self.assumed_absent += u64::from(skip);
                self.advance(first, count, 1 + skip);
            }
            Reply::Exception(code) => {
                let why = match code {
                    0x05 => "acknowledge (a long operation under way)",
                    0x06 => "server busy",
                    _ => "an exception a read should not get",
                };
                self.stopped = Some(format!(
                    "{}: exception 0x{code:02X}, {why}; stopped so as not to load a struggling device",
                    span()
                ));
            }
            Reply::NoAnswer(why) => {
                self.stopped = Some(format!(
                    "{}: {why}; stopped (some devices ignore reads of addresses they lack: narrow --range, or lower --rate)",
                    span()
                ));
            }
            // Taken before the match.
            Reply::Closed(_) => {}
        }
    }

    /// `done` addresses of the pending range `(first, count)` are settled.
    fn advance(&mut self, first: u16, count: u32, done: u32) {
        self.todo.pop();
        if count > done {
            self.todo.push((first.saturating_add(u16::try_from(done).unwrap_or(u16::MAX)), count - done));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A device with holding registers 0–9 and 100–104 only; at most 50 registers per read
    /// (exception 03 beyond); exception 02 for any read touching an absent address.
    fn device(table: Table, address: u16, quantity: u16) -> Reply {
        if table != Table::HoldingRegisters {
            return Reply::Exception(ILLEGAL_FUNCTION);
        }
        if quantity > 50 {
            return Reply::Exception(ILLEGAL_DATA_VALUE);
        }
        let present = |a: u32| a < 10 || (100..105).contains(&a);
        let all = (u32::from(address)..u32::from(address) + u32::from(quantity)).all(present);
        if all {
            Reply::Values((0..quantity).map(|i| address + i).collect())
        } else {
            Reply::Exception(ILLEGAL_DATA_ADDRESS)
        }
    }

    fn run(p: &mut Probe, answer: impl Fn(Table, u16, u16) -> Reply) -> Vec<(Table, u16, u16)> {
        let mut now = 0;
        let mut sent = Vec::new();
        loop {
            match p.next(now) {
                Step::Read { table, address, quantity } => {
                    sent.push((table, address, quantity));
                    p.reply(&answer(table, address, quantity));
                }
                Step::WaitUntil(t) => now = t,
                Step::Done => return sent,
            }
        }
    }

    #[test]
    fn present_stretches_and_boundaries_are_found_with_bounded_reads_only() {
        let mut p = Probe::new(&[Table::HoldingRegisters, Table::InputRegisters], 0, 199, 20.0);
        let sent = run(&mut p, device);
        let runs = p.runs(Table::HoldingRegisters);
        assert_eq!(runs, [(0, 9), (100, 104)]);
        // 125 and 62 refused (exception 03), 31 accepted (answered 02: the address is checked
        // after the quantity).
        assert_eq!(p.found[&Table::HoldingRegisters].max_block, Some(31));
        assert_eq!(p.found[&Table::HoldingRegisters].refused_block, Some(62));
        assert!(p.found[&Table::InputRegisters].unsupported);
        assert!(p.stopped.is_none());
        // Far fewer requests than addresses (200 addresses): present stretches in blocks, absent
        // ones galloped over, their edges found by halves.
        assert!(sent.len() < 80, "{}: {sent:?}", sent.len());
        assert!(p.assumed_absent > 100, "{}", p.assumed_absent);
        // Thorough: every address read, the same map.
        let mut all = Probe::new(&[Table::HoldingRegisters], 0, 199, 20.0);
        all.max_skip = 0;
        let sent_all = run(&mut all, device);
        assert_eq!(all.runs(Table::HoldingRegisters), runs);
        assert_eq!(all.assumed_absent, 0);
        assert!(sent_all.len() > sent.len());
        assert!(sent.iter().all(|&(_, _, q)| q <= MAX_REGISTERS));
        let draft = p.skeleton(7, "test");
        assert!(mbtap_device::profile::load("probe.toml", &draft).is_ok(), "{draft}");
    }

    #[test]
    fn the_first_sign_of_distress_stops_the_probe() {
        for (reply, says) in
            [(Reply::NoAnswer("no answer within 1000 ms".into()), "no answer"), (Reply::Exception(0x06), "server busy")]
        {
            let mut p = Probe::new(&[Table::HoldingRegisters], 0, 999, 10.0);
            let sent = run(&mut p, |_, _, _| reply.clone());
            assert_eq!(sent.len(), 1);
            assert!(p.stopped.as_deref().is_some_and(|s| s.contains(says)), "{:?}", p.stopped);
        }
    }

    #[test]
    fn requests_keep_to_the_rate() {
        let mut p = Probe::new(&[Table::HoldingRegisters], 0, 9, 4.0);
        assert!(matches!(p.next(0), Step::Read { .. }));
        p.reply(&Reply::Exception(ILLEGAL_DATA_ADDRESS));
        assert_eq!(p.next(1), Step::WaitUntil(250_000_000));
        assert!(matches!(p.next(250_000_000), Step::Read { .. }));
    }

    /// A device that answers and then closes its connection is probed over new connections: a read
    /// whose connection closed goes again on a new one, so the probe maps what the open one maps,
    /// each read tried at most twice; one that closes without ever answering stops it, said as
    /// such.
    #[test]
    fn a_device_closing_after_each_request_is_probed_over_new_connections() {
        let mut open = Probe::new(&[Table::HoldingRegisters], 0, 199, 20.0);
        let sent_open = run(&mut open, device);
        // Every read after an answered one finds its connection closed, once.
        let answered_last = std::cell::Cell::new(false);
        let closing = |t, a, q| {
            if answered_last.replace(false) {
                return Reply::Closed("unit 1: the device closed the connection".into());
            }
            answered_last.set(true);
            device(t, a, q)
        };
        let mut p = Probe::new(&[Table::HoldingRegisters], 0, 199, 20.0);
        let sent = run(&mut p, closing);
        assert!(p.stopped.is_none(), "{:?}", p.stopped);
        assert_eq!(p.runs(Table::HoldingRegisters), open.runs(Table::HoldingRegisters));
        assert_eq!(sent.len(), 2 * sent_open.len() - 1, "each read after the first tried twice");

        let mut mute = Probe::new(&[Table::HoldingRegisters], 0, 199, 20.0);
        let sent = run(&mut mute, |_, _, _| Reply::Closed("unit 1: the device closed the connection".into()));
        assert_eq!(sent.len(), 2);
        let why = mute.stopped.unwrap_or_default();
        assert!(why.contains("closed the new one too") && why.contains("answers none"), "{why}");
    }
}
