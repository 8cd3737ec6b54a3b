//! Who asks the bridge, as the web view lists them (`--web`): each client's transport, address
//! and role, its requests and its refusals by why — kept by the one admission ([`super::request::admit`])
//! for every asker (connections, UDP peers, the serial front, the broker, mbtap's own master).
//! Bounded: the [`KEPT`] most recently heard; an older one makes room, counted.

use std::collections::BTreeMap;
use std::sync::{Mutex, PoisonError};
use std::time::{SystemTime, UNIX_EPOCH};

use mbtap_gateway::queue::ClientId;
use serde_json::{Value, json};

use crate::output::audit::Who;

/// Clients kept.
pub const KEPT: usize = 256;

#[derive(Debug)]
struct Entry {
    who: Who,
    requests: u64,
    refusals: BTreeMap<&'static str, u64>,
    first_ms: u64,
    last_ms: u64,
}

#[derive(Debug, Default)]
struct Inner {
    by_id: BTreeMap<ClientId, Entry>,
    /// Clients forgotten to make room.
    forgotten: u64,
}

/// The clients the bridge has heard.
#[derive(Debug, Default)]
pub struct ClientBook(Mutex<Inner>);

fn now_ms() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(0))
}

impl ClientBook {
    fn with<R>(&self, f: impl FnOnce(&mut Inner) -> R) -> R {
        f(&mut self.0.lock().unwrap_or_else(PoisonError::into_inner))
    }

    fn entry<'a>(inner: &'a mut Inner, id: ClientId, who: &Who, t: u64) -> &'a mut Entry {
        if !inner.by_id.contains_key(&id) && inner.by_id.len() >= KEPT {
            let oldest = inner.by_id.iter().min_by_key(|(_, e)| e.last_ms).map(|(&k, _)| k);
            if let Some(k) = oldest {
                inner.by_id.remove(&k);
                inner.forgotten += 1;
            }
        }
        let e = inner.by_id.entry(id).or_insert_with(|| Entry {
            who: who.clone(),
            requests: 0,
            refusals: BTreeMap::new(),
            first_ms: t,
            last_ms: t,
        });
        e.last_ms = t;
        e
    }

    /// A request from `id`.
    pub fn request(&self, id: ClientId, who: &Who) {
        let t = now_ms();
        self.with(|i| Self::entry(i, id, who, t).requests += 1);
    }

    /// A request from `id` refused for `reason`.
    pub fn refused(&self, id: ClientId, who: &Who, reason: &'static str) {
        let t = now_ms();
        self.with(|i| *Self::entry(i, id, who, t).refusals.entry(reason).or_default() += 1);
    }

    /// The clients, most recently heard first, and how many were forgotten.
    #[must_use]
    pub fn snapshot(&self) -> (Vec<Value>, u64) {
        self.with(|i| {
            let mut list: Vec<&Entry> = i.by_id.values().collect();
            list.sort_by_key(|e| std::cmp::Reverse(e.last_ms));
            let clients = list
                .iter()
                .map(|e| {
                    let mut c = e.who.json();
                    c["requests"] = json!(e.requests);
                    c["refusals"] = json!(e.refusals.values().sum::<u64>());
                    c["refused_for"] = json!(e.refusals);
                    c["first_ms"] = json!(e.first_ms);
                    c["last_ms"] = json!(e.last_ms);
                    c
                })
                .collect();
            (clients, i.forgotten)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clients_are_counted_and_the_book_is_bounded() {
        let book = ClientBook::default();
        let who = Who { transport: "tcp", address: "192.0.2.1:5000".parse().ok(), role: None };
        book.request(1, &who);
        book.refused(1, &who, "read_only");
        let (list, _) = book.snapshot();
        assert_eq!((list[0]["requests"].as_u64(), list[0]["refusals"].as_u64()), (Some(1), Some(1)));
        assert_eq!(list[0]["refused_for"]["read_only"], 1);
        for id in 2..(2 + ClientId::try_from(KEPT).unwrap()) {
            book.request(id, &who);
        }
        let (list, forgotten) = book.snapshot();
        assert_eq!((list.len(), forgotten), (KEPT, 1));
    }
}
