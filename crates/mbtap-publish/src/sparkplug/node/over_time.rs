//! The node as time passes and the host speaks: data messages, a silent device's death and
//! its rebirth when it speaks again, held updates forwarded as historical, and the host's
//! commands (a rebirth at most once each `REBIRTH_MIN_MS`).

use super::{BIRTH_SETTLE_NS, EdgeNode, Held, MIN_GAPS, Out, REBIRTH, REBIRTH_MIN_MS, SILENT_PERIODS, Sample, metric};
use crate::sparkplug::payload::{Payload, Value};

impl EdgeNode {
    pub(super) fn ddata(&mut self, device: &str, samples: &[Sample], historical: bool, now_ms: u64) -> Out {
        let seq = self.next_seq();
        let metrics = samples.iter().map(|s| metric(s, false, historical)).collect();
        let p = Payload { timestamp: Some(now_ms), metrics, seq: Some(seq), ..Payload::default() };
        Out { topic: self.topic("DDATA", Some(device)), payload: p.to_bytes(), qos: 0, retain: false }
    }

    /// Bus time `t_ns` has come: a device silent for [`SILENT_PERIODS`] of its usual period
    /// (and at least the minimum) is dead — DDEATH when a session is on.
    pub fn tick(&mut self, t_ns: u64, now_ms: u64) -> Vec<Out> {
        let min = self.min_silence_ns;
        let dead: Vec<String> = self
            .devices
            .iter_mut()
            .filter(|(_, d)| d.alive)
            .filter_map(|(name, d)| {
                let last = d.last_ns?;
                let limit = if d.gaps.len() >= MIN_GAPS {
                    let mut g: Vec<u64> = d.gaps.iter().copied().collect();
                    g.sort_unstable();
                    g[g.len() / 2].saturating_mul(SILENT_PERIODS).max(min)
                } else {
                    min
                };
                (t_ns.saturating_sub(last) > limit).then(|| {
                    d.alive = false;
                    name.clone()
                })
            })
            .collect();
        let mut out = Vec::new();
        for name in dead {
            let born = self.devices.get(&name).is_some_and(|d| d.born);
            if let Some(d) = self.devices.get_mut(&name) {
                d.born = false;
                d.gaps.clear();
            }
            if self.online && born {
                out.push(self.ddeath(&name, now_ms));
            }
            if let Some(d) = self.devices.get_mut(&name) {
                d.first_ns = None;
            }
        }
        // A new device heard once and then not again within the settling time: born now.
        if self.online {
            let settled: Vec<String> = self
                .devices
                .iter()
                .filter(|(_, d)| {
                    d.alive
                        && !d.born
                        && !d.metrics.is_empty()
                        && d.first_ns.is_some_and(|f| t_ns.saturating_sub(f) >= BIRTH_SETTLE_NS)
                })
                .map(|(n, _)| n.clone())
                .collect();
            for name in settled {
                out.push(self.dbirth(&name, now_ms));
            }
        }
        out
    }

    pub(super) fn ddeath(&mut self, device: &str, now_ms: u64) -> Out {
        if let Some(d) = self.devices.get_mut(device) {
            d.born = false;
        }
        let seq = self.next_seq();
        let p = Payload { timestamp: Some(now_ms), seq: Some(seq), ..Payload::default() };
        Out { topic: self.topic("DDEATH", Some(device)), payload: p.to_bytes(), qos: 0, retain: false }
    }

    /// Held updates forwarded in a new session: DDATA whose metrics are `is_historical` with
    /// their own timestamps. A device not born in this session (it died meanwhile) is born for
    /// them and said dead again after.
    pub fn historical(&mut self, held: &[u8], now_ms: u64) -> Vec<Out> {
        let Ok(held) = serde_json::from_slice::<Held>(held) else { return Vec::new() };
        if !self.online || held.samples.is_empty() {
            return Vec::new();
        }
        let dev = self.devices.entry(held.device.clone()).or_default();
        for s in &held.samples {
            dev.metrics.entry(s.name.clone()).or_insert_with(|| s.clone());
        }
        let (born, alive) = (dev.born, dev.alive);
        let mut out = Vec::new();
        if !born {
            out.push(self.dbirth(&held.device, now_ms));
        }
        out.push(self.ddata(&held.device, &held.samples, true, now_ms));
        if !alive {
            if let Some(d) = self.devices.get_mut(&held.device) {
                d.born = false;
            }
            let seq = self.next_seq();
            let p = Payload { timestamp: Some(now_ms), seq: Some(seq), ..Payload::default() };
            out.push(Out {
                topic: self.topic("DDEATH", Some(&held.device)),
                payload: p.to_bytes(),
                qos: 0,
                retain: false,
            });
        }
        out
    }

    /// A command received on `topic`. NCMD `Node Control/Rebirth` = true: a rebirth (NBIRTH,
    /// DBIRTHs). Anything else is not this node's, or not a command it carries out: nothing.
    pub fn command(&mut self, topic: &str, payload: &[u8], now_ms: u64) -> Vec<Out> {
        if topic != self.topic("NCMD", None) || !self.online {
            return Vec::new();
        }
        let Ok(p) = Payload::parse_payload(payload) else { return Vec::new() };
        let rebirth = p
            .metrics
            .iter()
            .any(|m| m.name.as_deref() == Some(REBIRTH) && matches!(m.value, Some(Value::Boolean(true))));
        if !rebirth {
            return Vec::new();
        }
        if self.last_rebirth_ms.is_some_and(|last| now_ms.saturating_sub(last) < REBIRTH_MIN_MS) {
            self.rebirths_ignored += 1;
            return Vec::new();
        }
        self.last_rebirth_ms = Some(now_ms);
        self.online(now_ms)
    }
}
