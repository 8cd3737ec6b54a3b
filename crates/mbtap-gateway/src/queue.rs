//! The fair queue in front of a serial line: each client has its own bounded FIFO (its
//! pipelined requests answered in order), and the line takes turns between clients
//! (round-robin), so a client that floods the bridge delays only itself. A client that leaves
//! takes its waiting requests with it: they never spend line time.

use std::collections::{BTreeMap, VecDeque};

/// A client (one TCP connection).
pub type ClientId = u64;

/// No room: the request is refused (the caller answers exception 06, Server Device Busy,
/// MAP v1.1b3 §7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Full {
    /// The client already has its share waiting.
    Client,
    /// The line has its bound waiting, all clients together (3 000 UDP source ports
    /// queued 95 358 requests, 79 min of line time).
    Line,
}

/// Per-client FIFOs served in turn.
#[derive(Debug)]
pub struct FairQueue<T> {
    queues: BTreeMap<ClientId, VecDeque<T>>,
    /// Requests waiting, all clients (kept, not summed: checked at every push).
    waiting: usize,
    /// The bound on `waiting`.
    total: usize,
    /// The last client served: the next turn goes to the first client after it.
    last: Option<ClientId>,
    per_client: usize,
    /// Times in a row the priority class went first while others waited.
    passed_over: u64,
}

impl<T> FairQueue<T> {
    /// `per_client` waiting requests per client, and no bound for all together.
    #[must_use]
    pub fn new(per_client: usize) -> Self {
        Self::bounded(per_client, usize::MAX)
    }

    /// `per_client` waiting requests per client, `total` for all clients together.
    #[must_use]
    pub fn bounded(per_client: usize, total: usize) -> Self {
        Self {
            queues: BTreeMap::new(),
            waiting: 0,
            total: total.max(1),
            last: None,
            per_client: per_client.max(1),
            passed_over: 0,
        }
    }

    /// Queues `item` for `client`.
    ///
    /// # Errors
    /// [`Full::Client`] when the client already has `per_client` requests waiting,
    /// [`Full::Line`] when all clients together have `total`.
    pub fn push(&mut self, client: ClientId, item: T) -> Result<(), Full> {
        if self.waiting >= self.total {
            return Err(Full::Line);
        }
        let q = self.queues.entry(client).or_default();
        if q.len() >= self.per_client {
            return Err(Full::Client);
        }
        q.push_back(item);
        self.waiting += 1;
        Ok(())
    }

    /// The next request: the oldest of the next client in turn.
    pub fn pop(&mut self) -> Option<(ClientId, T)> {
        // After the highest id (the bridge's own polls are ClientId::MAX) the turn wraps.
        let next = match self.last.and_then(|last| last.checked_add(1)) {
            Some(after) => self.queues.range(after..).next().or_else(|| self.queues.iter().next()),
            None => self.queues.iter().next(),
        }
        .map(|(&c, _)| c)?;
        let q = self.queues.get_mut(&next)?;
        let item = q.pop_front()?;
        if q.is_empty() {
            self.queues.remove(&next);
        }
        self.waiting = self.waiting.saturating_sub(1);
        self.last = Some(next);
        Some((next, item))
    }

    /// Like [`Self::pop`], but a request for which `high` holds goes first (the first such head
    /// in turn order) — unless the others have been passed over `every - 1` times in a row, when
    /// they get a plain round-robin turn: a saturating high class leaves the rest at least
    /// 1/`every` of the line (no starvation), while an occasional high request always goes next.
    pub fn pop_prefer(&mut self, high: impl Fn(&T) -> bool, every: u64) -> Option<(ClientId, T)> {
        let others_waiting = self.queues.values().any(|q| q.front().is_some_and(|h| !high(h)));
        if !others_waiting || self.passed_over + 1 < every.max(1) {
            let after = self.last.and_then(|l| l.checked_add(1)).unwrap_or(0);
            let pick = self
                .queues
                .range(after..)
                .chain(self.queues.range(..after))
                .find(|(_, q)| q.front().is_some_and(&high))
                .map(|(&c, _)| c);
            if let Some(c) = pick
                && let Some(q) = self.queues.get_mut(&c)
                && let Some(item) = q.pop_front()
            {
                if q.is_empty() {
                    self.queues.remove(&c);
                }
                self.waiting = self.waiting.saturating_sub(1);
                self.last = Some(c);
                if others_waiting {
                    self.passed_over += 1;
                }
                return Some((c, item));
            }
        }
        self.passed_over = 0;
        self.pop()
    }

    /// Takes the first waiting request of every other client for which `pred` holds — only
    /// first ones, so each client's pipelined requests still come back in order.
    pub fn take_heads(&mut self, except: ClientId, mut pred: impl FnMut(&T) -> bool) -> Vec<(ClientId, T)> {
        let mut out = Vec::new();
        let mut emptied = Vec::new();
        for (&c, q) in &mut self.queues {
            if c != except && q.front().is_some_and(&mut pred) {
                if let Some(item) = q.pop_front() {
                    out.push((c, item));
                }
                if q.is_empty() {
                    emptied.push(c);
                }
            }
        }
        for c in emptied {
            self.queues.remove(&c);
        }
        self.waiting = self.waiting.saturating_sub(out.len());
        out
    }

    /// Drops everything `client` still has waiting; how many.
    pub fn remove_client(&mut self, client: ClientId) -> usize {
        let n = self.queues.remove(&client).map_or(0, |q| q.len());
        self.waiting = self.waiting.saturating_sub(n);
        n
    }

    /// Whether any waiting request satisfies `pred`.
    pub fn any(&self, mut pred: impl FnMut(&T) -> bool) -> bool {
        self.queues.values().flatten().any(&mut pred)
    }

    /// Requests waiting, all clients.
    #[must_use]
    pub fn len(&self) -> usize {
        self.waiting
    }

    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.queues.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clients_take_turns_and_each_keeps_its_order() {
        let mut q = FairQueue::new(10);
        for i in 0..3 {
            q.push(7, ("a", i)).unwrap();
        }
        q.push(9, ("b", 0)).unwrap();
        q.push(3, ("c", 0)).unwrap();
        let order: Vec<_> = std::iter::from_fn(|| q.pop()).map(|(_, v)| v).collect();
        assert_eq!(order, [("c", 0), ("a", 0), ("b", 0), ("a", 1), ("a", 2)]);
        assert!(q.is_empty());
    }

    #[test]
    fn a_flooding_client_waits_for_its_own_turn() {
        let mut q = FairQueue::new(1000);
        for i in 0..100 {
            q.push(1, i).unwrap();
        }
        q.push(2, 1000).unwrap();
        // The quiet client is served second, not after the flood.
        assert_eq!(q.pop(), Some((1, 0)));
        assert_eq!(q.pop(), Some((2, 1000)));
    }

    #[test]
    fn the_priority_class_goes_first_but_never_starves_the_rest() {
        let mut q = FairQueue::new(100);
        for i in 0..20 {
            q.push(1, ('r', i)).unwrap();
        }
        for i in 0..20 {
            q.push(2, ('w', i)).unwrap();
        }
        let order: Vec<char> =
            (0..12).filter_map(|_| q.pop_prefer(|&(k, _)| k == 'w', 4)).map(|(_, (k, _))| k).collect();
        // Three writes, then the fourth turn is round-robin's (the reader's), and so on.
        assert_eq!(order.iter().collect::<String>(), "wwwrwwwrwwwr");
        // An occasional high request goes next, whatever turn it is.
        let mut q = FairQueue::new(100);
        for i in 0..5 {
            q.push(1, ('r', i)).unwrap();
            q.push(3, ('r', i)).unwrap();
        }
        assert_eq!(q.pop_prefer(|&(k, _)| k == 'w', 4).map(|(_, (k, _))| k), Some('r'));
        assert_eq!(q.pop_prefer(|&(k, _)| k == 'w', 4).map(|(_, (k, _))| k), Some('r'));
        assert_eq!(q.pop_prefer(|&(k, _)| k == 'w', 4).map(|(_, (k, _))| k), Some('r'));
        q.push(2, ('w', 0)).unwrap();
        assert_eq!(
            q.pop_prefer(|&(k, _)| k == 'w', 4).map(|(_, (k, _))| k),
            Some('w'),
            "the fourth pop, and still first"
        );
    }

    /// Found with agent polling: the turn after the poll client (ClientId::MAX) overflowed.
    #[test]
    fn the_turn_wraps_after_the_highest_client_id() {
        let mut q = FairQueue::new(10);
        q.push(ClientId::MAX, 'p').unwrap();
        q.push(ClientId::MAX, 'p').unwrap();
        q.push(1, 'c').unwrap();
        assert_eq!(q.pop(), Some((1, 'c')));
        assert_eq!(q.pop(), Some((ClientId::MAX, 'p')));
        assert_eq!(q.pop(), Some((ClientId::MAX, 'p')));
        assert_eq!(q.pop(), None);
    }

    #[test]
    fn twins_are_taken_from_the_heads_only() {
        let mut q = FairQueue::new(10);
        q.push(1, 'r').unwrap();
        q.push(2, 'r').unwrap();
        q.push(3, 'w').unwrap();
        q.push(3, 'r').unwrap();
        q.push(4, 'r').unwrap();
        q.push(4, 'x').unwrap();
        let (c, first) = q.pop().unwrap();
        let twins = q.take_heads(c, |&i| i == first);
        assert_eq!(twins, [(2, 'r'), (4, 'r')], "client 3's 'r' waits behind its 'w'");
        assert_eq!(q.len(), 3);
    }

    /// A client per source port gets its own 32 and the line bounds them all together; a client
    /// leaving gives its room back.
    #[test]
    fn udp_flood_the_line_bounds_all_clients_together() {
        let mut q = FairQueue::bounded(32, 100);
        for client in 0..10 {
            for k in 0..10 {
                q.push(client, k).unwrap();
            }
        }
        assert_eq!(q.push(99, 0), Err(Full::Line));
        assert_eq!(q.len(), 100);
        assert_eq!(q.remove_client(3), 10);
        assert!(q.pop().is_some());
        assert_eq!(q.len(), 89);
        for k in 0..11 {
            q.push(99, k).unwrap();
        }
        assert_eq!(q.push(98, 0), Err(Full::Line));
        let twins = q.take_heads(0, |&k| k == 0);
        assert_eq!(q.len(), 100 - twins.len());
    }

    #[test]
    fn a_full_client_is_refused_and_a_leaving_client_takes_its_requests() {
        let mut q = FairQueue::new(2);
        q.push(1, 'x').unwrap();
        q.push(1, 'y').unwrap();
        assert_eq!(q.push(1, 'z'), Err(Full::Client));
        q.push(2, 'k').unwrap();
        assert_eq!(q.remove_client(1), 2);
        assert_eq!(q.len(), 1);
        assert_eq!(q.pop(), Some((2, 'k')));
        assert_eq!(q.pop(), None);
    }
}
