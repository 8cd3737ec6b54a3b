//! The line's figures as the web view shows them (`--web`: `/api/state`): per unit requests,
//! answers, exceptions, timeouts, p50/p99 latency of the last [`RECENT_LATENCIES`] answers, the
//! breaker's state, the time waited for its gap; the line's cache and poller; the last
//! [`LAST_TRANSACTIONS`] transactions. Built under the metrics' lock, bounded by construction.

use std::time::{SystemTime, UNIX_EPOCH};

use serde_json::{Value, json};

use super::Metrics;

/// Latencies kept per unit for its percentiles.
pub const RECENT_LATENCIES: usize = 512;
/// Transactions kept per line for the list.
pub const LAST_TRANSACTIONS: usize = 200;

/// One transaction as the list shows it.
#[derive(Debug, Clone)]
pub struct Transaction {
    /// Milliseconds since 1970, when it ended.
    pub t_ms: u64,
    pub unit: u8,
    pub function: u8,
    /// The first address it names (a read's or a write's), where it names one.
    pub address: Option<u16>,
    pub outcome: String,
    pub latency_ms: f64,
}

/// The `p`-th percentile (0–1) of `values`, by rank; `None` for none.
fn percentile(values: &std::collections::VecDeque<f64>, p: f64) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().collect();
    v.sort_by(f64::total_cmp);
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss, clippy::cast_precision_loss)]
    let i = ((v.len() as f64 - 1.0) * p).round() as usize;
    v.get(i).map(|x| (x * 1000.0).round() / 1000.0)
}

impl Metrics {
    /// A transaction ended: kept for the list (the oldest dropped past [`LAST_TRANSACTIONS`]).
    pub fn transaction(&self, unit: u8, pdu: &[u8], outcome: String, latency: std::time::Duration) {
        let t_ms =
            SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(0));
        let address = pdu.get(1..3).map(|b| u16::from_be_bytes([b[0], b[1]]));
        let function = pdu.first().copied().unwrap_or(0);
        self.with(|m| {
            if m.last.len() == LAST_TRANSACTIONS {
                m.last.pop_front();
            }
            m.last.push_back(Transaction {
                t_ms,
                unit,
                function,
                address,
                outcome,
                latency_ms: latency.as_secs_f64() * 1000.0,
            });
        });
    }

    /// Whether `unit` rests behind its open breaker.
    pub fn resting(&self, unit: u8, resting: bool) {
        self.with(|m| {
            if resting || m.units.contains_key(&unit) {
                m.units.entry(unit).or_default().resting = resting;
            }
        });
    }

    /// The server's figures for the web view: connections, refusals by why.
    #[must_use]
    pub fn server_snapshot(&self) -> Value {
        self.with(|m| {
            json!({
                "connections": m.connections,
                "connections_open": m.connections_open,
                "refused": m.refused,
                "abandoned": m.abandoned,
            })
        })
    }

    /// The line's figures for the web view.
    #[must_use]
    pub fn snapshot(&self) -> (Value, Vec<Value>) {
        self.with(|m| {
            let units: Vec<Value> = m
                .units
                .iter()
                .map(|(&unit, u)| {
                    let exceptions: u64 = u.exceptions.values().sum();
                    json!({
                        "unit": unit,
                        "requests": u.requests,
                        "answers": u.responses,
                        "exceptions": exceptions,
                        "gateway_exceptions": u.gateway_exceptions.values().sum::<u64>(),
                        "timeouts": u.timeouts,
                        "crc_errors": u.crc_errors,
                        "late_answers": u.late_answers,
                        "p50_ms": percentile(&u.recent, 0.5),
                        "p99_ms": percentile(&u.recent, 0.99),
                        "breaker": if u.resting { "open" } else { "closed" },
                        "breaker_answered": u.circuit_open,
                        "gap_wait_s": u.gap_wait.as_secs_f64(),
                    })
                })
                .collect();
            let line = json!({
                "units": units,
                "cache": {"hits": m.cache_hits, "misses": m.cache_misses, "coalesced": m.coalesced},
                "line_seconds": m.line_time.iter().map(|(k, v)| (k.to_string(), json!(v.as_secs_f64()))).collect::<serde_json::Map<_, _>>(),
                "queue_depth": m.queue_depth,
                "dropped": m.dropped,
                "reopened": m.reopened,
            });
            let last = m
                .last
                .iter()
                .map(|t| {
                    json!({
                        "t_ms": t.t_ms, "unit": t.unit, "function": t.function, "address": t.address,
                        "outcome": t.outcome, "latency_ms": (t.latency_ms * 1000.0).round() / 1000.0,
                    })
                })
                .collect();
            (line, last)
        })
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn a_units_figures_and_percentiles_of_its_last_answers() {
        let m = Metrics::default();
        for ms in 1..=100 {
            m.request(1);
            m.response(1, &[0x03, 0x02, 0, 0]);
            m.latency(1, Duration::from_millis(ms));
        }
        m.transaction(1, &[0x03, 0x01, 0xAE, 0x00, 0x01], "done".into(), Duration::from_millis(4));
        let (line, last) = m.snapshot();
        let u = &line["units"][0];
        assert_eq!(
            (u["unit"].as_u64(), u["requests"].as_u64(), u["answers"].as_u64()),
            (Some(1), Some(100), Some(100))
        );
        assert!((u["p50_ms"].as_f64().unwrap() - 50.0).abs() <= 1.0, "{u}");
        assert!((u["p99_ms"].as_f64().unwrap() - 99.0).abs() <= 1.0, "{u}");
        assert_eq!(last[0]["address"], 430);
        for _ in 0..LAST_TRANSACTIONS + 5 {
            m.transaction(2, &[0x04], "done".into(), Duration::ZERO);
        }
        assert_eq!(m.snapshot().1.len(), LAST_TRANSACTIONS, "bounded");
    }
}
