//! A Sparkplug B edge node as a state machine (Sparkplug 3.0 §7–§8, §11): births, data by
//! exception, deaths, sequence numbers, rebirth on command, and what to hold while no host can
//! hear. The shell tells it when the session starts and ends, the values heard (with bus time)
//! and the commands received; it answers with the messages to publish or the updates to store.
//! No clock, no broker here.
//!
//! Its `over_time` module holds the node as time passes and the host speaks.

use std::collections::{BTreeMap, VecDeque};

use serde::{Deserialize, Serialize};

use super::payload::{DataType, Metric, Payload, PropertyKind, PropertySet, PropertyValue, Value, value_of};

mod over_time;

/// The topic namespace of Sparkplug B (§6.1.1).
pub const NAMESPACE: &str = "spBv1.0";
/// The node metric a host sets to ask for a rebirth (§6.4.20, §8.3.1 `Node Control/Rebirth`).
pub const REBIRTH: &str = "Node Control/Rebirth";

/// The shortest time between two rebirths on command (ms): any client of the broker may publish
/// an NCMD, and each rebirth republishes every device's birth; requests inside it are counted
/// in [`EdgeNode::rebirths_ignored`], not obeyed (2 000 NCMDs made 4 000 births).
pub const REBIRTH_MIN_MS: u64 = 5_000;

/// How long a new device's metrics may keep growing before its DBIRTH goes out anyway (bus
/// time): a device polled in several blocks is heard block by block, and a DBIRTH must declare
/// every metric the device will report (Sparkplug B 3.0 §6.4.11, a new metric needs a new
/// birth) — so its birth waits until its first block is heard again or this has passed.
pub const BIRTH_SETTLE_NS: u64 = 2_000_000_000;
/// The birth/death sequence metric (§6.4.19).
pub const BD_SEQ: &str = "bdSeq";
/// A unit not heard for this many of its usual poll periods is said dead (DDEATH)…
const SILENT_PERIODS: u64 = 3;
/// …once at least this many inter-arrival gaps are known; the shortest silence said dead.
const MIN_GAPS: usize = 3;
/// Metrics a device may declare: a DBIRTH carries them all, so a line that reads ever new
/// addresses (garbage that parses, a scanner) must not grow one past what a broker takes.
/// A real device's map is far smaller; metrics beyond are not published, and counted.
pub const MAX_METRICS: usize = 4096;

/// One message to publish.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Out {
    pub topic: String,
    pub payload: Vec<u8>,
    /// NDEATH is QoS 1; births, data and deaths of devices QoS 0 (§7.1, §7.3, §7.5, §7.7).
    pub qos: u8,
    pub retain: bool,
}

/// One value of a device, as mbtap knows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// The metric's name, already escaped ([`metric_name`]).
    pub name: String,
    /// The value as mbtap shows it (number, label, text).
    pub value: serde_json::Value,
    /// A coil or discrete input: Boolean.
    pub bits: bool,
    /// Engineering unit (`V`, `°C`), carried as the `engUnit` property.
    pub unit: Option<String>,
    /// Milliseconds since the epoch when it was heard.
    pub t_ms: u64,
}

/// Updates of one device held while no host could hear: forwarded later as historical
/// (`is_historical`, their own timestamps).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Held {
    pub device: String,
    pub samples: Vec<Sample>,
}

/// What an update leads to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Emit {
    Send(Vec<Out>),
    /// Offline: store this (serialised [`Held`]) and forward it when a session begins.
    Hold(Vec<u8>),
}

#[derive(Debug, Clone, Default)]
struct Device {
    metrics: BTreeMap<String, Sample>,
    alive: bool,
    /// DBIRTH sent in this session.
    born: bool,
    /// Bus time the device was first heard: its birth waits until its metrics have settled.
    first_ns: Option<u64>,
    last_ns: Option<u64>,
    gaps: VecDeque<u64>,
}

/// The edge node.
#[derive(Debug, Clone)]
pub struct EdgeNode {
    group: String,
    node: String,
    /// The birth/death sequence of the MQTT session (§6.4.19): in NBIRTH and in the will.
    bd_seq: u64,
    /// The next message's sequence number, 0–255 (§6.4.1).
    seq: u64,
    online: bool,
    devices: BTreeMap<String, Device>,
    /// The shortest silence said dead (bus time, ns), whatever the poll period.
    min_silence_ns: u64,
    /// Values not published because their device already declares [`MAX_METRICS`].
    pub over_limit: u64,
    /// When the last rebirth on command was obeyed (ms since the epoch).
    last_rebirth_ms: Option<u64>,
    /// Rebirth commands not obeyed: within [`REBIRTH_MIN_MS`] of the last.
    pub rebirths_ignored: u64,
}

impl EdgeNode {
    /// A node `group`/`node` (each escaped to one topic level). `min_silence_ns`: no unit is
    /// said dead before this much silence.
    #[must_use]
    pub fn new(group: &str, node: &str, min_silence_ns: u64) -> Self {
        Self {
            group: level(group),
            node: level(node),
            bd_seq: 0,
            seq: 0,
            online: false,
            devices: BTreeMap::new(),
            min_silence_ns,
            over_limit: 0,
            last_rebirth_ms: None,
            rebirths_ignored: 0,
        }
    }

    fn topic(&self, kind: &str, device: Option<&str>) -> String {
        match device {
            Some(d) => format!("{NAMESPACE}/{}/{kind}/{}/{d}", self.group, self.node),
            None => format!("{NAMESPACE}/{}/{kind}/{}", self.group, self.node),
        }
    }

    /// The topic commands to this node arrive on (NCMD), and its devices' (DCMD, `+`).
    #[must_use]
    pub fn command_topics(&self) -> [String; 2] {
        [self.topic("NCMD", None), self.topic("DCMD", Some("+"))]
    }

    /// The device a DCMD topic is addressed to, if it is this node's.
    #[must_use]
    pub fn dcmd_device<'t>(&self, topic: &'t str) -> Option<&'t str> {
        let device = topic.strip_prefix(&format!("{NAMESPACE}/{}/DCMD/{}/", self.group, self.node))?;
        (!device.is_empty() && !device.contains('/')).then_some(device)
    }

    fn next_seq(&mut self) -> u64 {
        let s = self.seq;
        self.seq = (self.seq + 1) % 256;
        s
    }

    /// The NDEATH to register as the MQTT will of the next session (§7.2: bdSeq as in the
    /// NBIRTH that follows; no seq).
    #[must_use]
    pub fn will(&self) -> Out {
        let payload = Payload {
            timestamp: None,
            metrics: vec![Metric {
                name: Some(BD_SEQ.into()),
                datatype: Some(DataType::UInt64.code()),
                value: Some(Value::Long(self.bd_seq)),
                ..Metric::default()
            }],
            ..Payload::default()
        };
        Out { topic: self.topic("NDEATH", None), payload: payload.to_bytes(), qos: 1, retain: false }
    }

    /// A session began and a host can hear (`now_ms`: the clock, ms since the epoch): NBIRTH
    /// with seq 0, then a DBIRTH for every device alive. Also the answer to a rebirth command.
    pub fn online(&mut self, now_ms: u64) -> Vec<Out> {
        self.online = true;
        self.seq = 0;
        let seq = self.next_seq();
        let node_metrics = vec![
            Metric {
                name: Some(BD_SEQ.into()),
                timestamp: Some(now_ms),
                datatype: Some(DataType::UInt64.code()),
                value: Some(Value::Long(self.bd_seq)),
                ..Metric::default()
            },
            Metric {
                name: Some(REBIRTH.into()),
                timestamp: Some(now_ms),
                datatype: Some(DataType::Boolean.code()),
                value: Some(Value::Boolean(false)),
                ..Metric::default()
            },
        ];
        let nbirth = Payload { timestamp: Some(now_ms), metrics: node_metrics, seq: Some(seq), ..Payload::default() };
        let mut out =
            vec![Out { topic: self.topic("NBIRTH", None), payload: nbirth.to_bytes(), qos: 0, retain: false }];
        let alive: Vec<String> = self.devices.iter().filter(|(_, d)| d.alive).map(|(n, _)| n.clone()).collect();
        for d in alive {
            out.push(self.dbirth(&d, now_ms));
        }
        out
    }

    /// The session ended (the broker went away, or the host did): the next session has the
    /// next bdSeq; until it begins, updates are held.
    pub fn offline(&mut self) {
        if self.online {
            self.bd_seq = (self.bd_seq + 1) % 256;
        }
        self.online = false;
        for d in self.devices.values_mut() {
            d.born = false;
        }
    }

    /// Whether a session is on.
    #[must_use]
    pub fn is_online(&self) -> bool {
        self.online
    }

    /// The primary host went offline while the MQTT session stays: nothing is published until
    /// it is back (updates are held), and then the node is born again — with the same bdSeq, as
    /// the session's will still carries it.
    pub fn pause(&mut self) {
        self.online = false;
        for d in self.devices.values_mut() {
            d.born = false;
        }
    }

    fn dbirth(&mut self, device: &str, now_ms: u64) -> Out {
        let metrics = self
            .devices
            .get(device)
            .map(|d| d.metrics.values().map(|s| metric(s, true, false)).collect())
            .unwrap_or_default();
        if let Some(d) = self.devices.get_mut(device) {
            d.born = true;
        }
        let seq = self.next_seq();
        let p = Payload { timestamp: Some(now_ms), metrics, seq: Some(seq), ..Payload::default() };
        Out { topic: self.topic("DBIRTH", Some(device)), payload: p.to_bytes(), qos: 0, retain: false }
    }

    /// Values of `device` heard at bus time `t_ns`: those that changed go out (DDATA, report
    /// by exception), after a DBIRTH when the device is new, back, or has a metric its birth
    /// did not declare; held while offline.
    pub fn update(&mut self, device: &str, samples: Vec<Sample>, t_ns: u64, now_ms: u64) -> Emit {
        let dev = self.devices.entry(level(device)).or_default();
        if let Some(last) = dev.last_ns
            && t_ns > last
        {
            dev.gaps.push_back(t_ns - last);
            if dev.gaps.len() > 8 {
                dev.gaps.pop_front();
            }
        }
        dev.last_ns = Some(dev.last_ns.map_or(t_ns, |l| l.max(t_ns)));
        let first_ns = *dev.first_ns.get_or_insert(t_ns);
        // A device heard before (it died and came back, or a session began) is born at once
        // with what it declared; a new one once its metrics have settled.
        let known_before = !dev.metrics.is_empty();
        let came_back = !dev.alive;
        dev.alive = true;
        let repeated = samples.iter().any(|s| dev.metrics.contains_key(&s.name));
        let settled = repeated || t_ns.saturating_sub(first_ns) >= BIRTH_SETTLE_NS;
        let mut changed = Vec::new();
        let mut new_metric = false;
        for s in samples {
            match dev.metrics.get(&s.name) {
                Some(k) if k.value == s.value && k.unit == s.unit => {}
                None if dev.metrics.len() >= MAX_METRICS => self.over_limit += 1,
                known => {
                    new_metric |= known.is_none();
                    changed.push(s.clone());
                    dev.metrics.insert(s.name.clone(), s);
                }
            }
        }
        let device = level(device);
        if !self.online {
            if changed.is_empty() {
                return Emit::Send(Vec::new());
            }
            let held = Held { device, samples: changed };
            return Emit::Hold(serde_json::to_vec(&held).unwrap_or_default());
        }
        let born = self.devices.get(&device).is_some_and(|d| d.born);
        if !born {
            if settled || (came_back && known_before) {
                return Emit::Send(vec![self.dbirth(&device, now_ms)]);
            }
            return Emit::Send(Vec::new());
        }
        if new_metric {
            // Its birth did not declare this metric: the device dies and is born again with it
            // (Sparkplug B 3.0 §6.4.11) — a host drops a DBIRTH that is not after a DDEATH.
            let death = self.ddeath(&device, now_ms);
            return Emit::Send(vec![death, self.dbirth(&device, now_ms)]);
        }
        if changed.is_empty() {
            return Emit::Send(Vec::new());
        }
        Emit::Send(vec![self.ddata(&device, &changed, false, now_ms)])
    }
}

/// One metric of a sample; in births with its datatype and engineering unit.
fn metric(s: &Sample, birth: bool, historical: bool) -> Metric {
    let (datatype, value) = value_of(&s.value, s.bits);
    let properties = s.unit.as_ref().filter(|_| birth).map(|u| PropertySet {
        keys: vec!["engUnit".into()],
        values: vec![PropertyValue {
            r#type: Some(DataType::String.code()),
            is_null: None,
            value: Some(PropertyKind::String(u.clone())),
        }],
    });
    Metric {
        name: Some(s.name.clone()),
        timestamp: Some(s.t_ms),
        datatype: Some(datatype.code()),
        is_historical: historical.then_some(true),
        is_null: value.is_none().then_some(true),
        properties,
        value,
        ..Metric::default()
    }
}

/// One topic level from free text: `/`, `+`, `#` (MQTT v3.1.1 §4.7) and control characters
/// become `_` (Sparkplug 3.0 §6.1.1: group, node and device ids are single levels).
#[must_use]
pub fn level(s: &str) -> String {
    let t: String = s.chars().map(|c| if matches!(c, '/' | '+' | '#') || c.is_control() { '_' } else { c }).collect();
    if t.is_empty() { "_".into() } else { t }
}

/// A metric name from free text: `/` (Sparkplug's folder separator: a register's name must not
/// invent folders), `+`, `#` and control characters become `_`.
#[must_use]
pub fn metric_name(s: &str) -> String {
    level(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SEC: u64 = 1_000_000_000;

    fn sample(name: &str, value: serde_json::Value, t_ms: u64) -> Sample {
        Sample { name: name.into(), value, bits: false, unit: Some("V".into()), t_ms }
    }

    fn decode(o: &Out) -> Payload {
        Payload::parse_payload(&o.payload).unwrap()
    }

    fn sends(e: Emit) -> Vec<Out> {
        match e {
            Emit::Send(v) => v,
            Emit::Hold(_) => panic!("held while online"),
        }
    }

    #[test]
    fn births_then_data_by_exception_with_counting_seq() {
        let mut n = EdgeNode::new("plant", "pump/station", 5 * SEC);
        let will = n.will();
        assert_eq!(will.topic, "spBv1.0/plant/NDEATH/pump_station");
        assert_eq!((will.qos, will.retain), (1, false));
        assert_eq!(decode(&will).metrics[0].value, Some(Value::Long(0)));
        let births = n.online(1000);
        assert_eq!(births.len(), 1);
        let nbirth = decode(&births[0]);
        assert_eq!(nbirth.seq, Some(0));
        assert_eq!(nbirth.metrics[0].name.as_deref(), Some(BD_SEQ));
        assert_eq!(nbirth.metrics[1].name.as_deref(), Some(REBIRTH));
        // A new device heard block by block: its birth waits until its first block comes again,
        // then declares every metric, its datatype and engineering unit.
        assert!(sends(n.update("mk4-1", vec![sample("Voltage", 230.5.into(), 5)], SEC, 1001)).is_empty());
        assert!(sends(n.update("mk4-1", vec![sample("Power", 1.into(), 5)], SEC + 1, 1001)).is_empty());
        let out = sends(n.update("mk4-1", vec![sample("Voltage", 230.5.into(), 6)], 2 * SEC, 1002));
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].topic, "spBv1.0/plant/DBIRTH/pump_station/mk4-1");
        let dbirth = decode(&out[0]);
        assert_eq!(dbirth.seq, Some(1));
        assert_eq!(dbirth.metrics.len(), 2, "both blocks in the one birth");
        assert_eq!(dbirth.metrics[1].datatype, Some(DataType::Double.code()));
        assert_eq!(dbirth.metrics[1].properties.as_ref().unwrap().keys, ["engUnit"]);
        // Unchanged: nothing.
        assert!(sends(n.update("mk4-1", vec![sample("Voltage", 230.5.into(), 6)], 2 * SEC, 1002)).is_empty());
        // A metric its birth did not declare: DDEATH, then a DBIRTH with it.
        let out = sends(n.update(
            "mk4-1",
            vec![sample("Voltage", 231.0.into(), 7), sample("Current", 4.into(), 7)],
            3 * SEC,
            1003,
        ));
        let topics: Vec<&str> = out.iter().map(|o| o.topic.as_str()).collect();
        assert_eq!(topics, ["spBv1.0/plant/DDEATH/pump_station/mk4-1", "spBv1.0/plant/DBIRTH/pump_station/mk4-1"]);
        // Changed: DDATA with that metric only.
        let out = sends(n.update("mk4-1", vec![sample("Current", 5.into(), 8)], 4 * SEC, 1004));
        let ddata = decode(&out[0]);
        assert_eq!(out[0].topic, "spBv1.0/plant/DDATA/pump_station/mk4-1");
        assert_eq!(ddata.seq, Some(4));
        assert_eq!(ddata.metrics.len(), 1);
        assert_eq!(ddata.metrics[0].value, Some(Value::Long(5)));
        assert_eq!(ddata.metrics[0].timestamp, Some(8));
    }

    #[test]
    fn seq_wraps_at_256() {
        let mut n = EdgeNode::new("g", "n", 5 * SEC);
        n.online(0);
        let mut last = None;
        for i in 0..300u64 {
            let out = sends(n.update("d", vec![sample("v", i.into(), i)], i * SEC / 100, i));
            if let Some(o) = out.first() {
                last = decode(o).seq;
                assert!(last.unwrap() < 256);
            }
        }
        // NBIRTH 0; the first value settles the device; DBIRTH 1 at the second, then 298 DDATA:
        // 299 messages after the NBIRTH → seq 299 mod 256.
        assert_eq!(last, Some(299 % 256));
    }

    #[test]
    fn a_silent_unit_dies_and_is_born_again_when_it_speaks() {
        let mut n = EdgeNode::new("g", "n", 2 * SEC);
        n.online(0);
        for i in 0..5u64 {
            n.update("d", vec![sample("v", i.into(), i)], i * SEC, i);
        }
        // Polled every second: dead after three periods of silence (the minimum is 2 s).
        assert!(n.tick(4 * SEC + 3 * SEC, 0).is_empty(), "exactly three periods: not yet");
        let out = n.tick(4 * SEC + 3 * SEC + 1, 0);
        assert_eq!(out[0].topic, "spBv1.0/g/DDEATH/n/d");
        assert!(decode(&out[0]).seq.is_some());
        assert!(n.tick(20 * SEC, 0).is_empty(), "said once");
        let out = sends(n.update("d", vec![sample("v", 4.into(), 30)], 30 * SEC, 30));
        assert_eq!(out[0].topic, "spBv1.0/g/DBIRTH/n/d", "back: born again, even with its old value");
    }

    #[test]
    fn offline_updates_are_held_and_forwarded_as_historical_after_the_births() {
        let mut n = EdgeNode::new("g", "n", 60 * SEC);
        n.online(0);
        n.update("d", vec![sample("v", 1.into(), 1)], SEC, 1);
        n.offline();
        assert_eq!(decode(&n.will()).metrics[0].value, Some(Value::Long(1)), "the next session's bdSeq");
        let Emit::Hold(a) = n.update("d", vec![sample("v", 2.into(), 2)], 2 * SEC, 2) else { panic!() };
        let Emit::Hold(b) = n.update("d", vec![sample("v", 3.into(), 3)], 3 * SEC, 3) else { panic!() };
        let births = n.online(10);
        assert_eq!(births.len(), 2, "NBIRTH and the alive device's DBIRTH, with its newest value");
        assert_eq!(decode(&births[1]).metrics[0].value, Some(Value::Long(3)));
        let mut seqs = Vec::new();
        for held in [a, b] {
            let out = n.historical(&held, 11);
            assert_eq!(out.len(), 1);
            let p = decode(&out[0]);
            assert_eq!(p.metrics[0].is_historical, Some(true));
            seqs.push((p.seq, p.metrics[0].timestamp));
        }
        assert_eq!(seqs, [(Some(2), Some(2)), (Some(3), Some(3))], "in order, with their own timestamps");
    }

    #[test]
    fn rebirth_on_ncmd_only() {
        let mut n = EdgeNode::new("g", "n", 60 * SEC);
        n.online(0);
        n.update("d", vec![sample("v", 1.into(), 1)], SEC, 1);
        let cmd = Payload {
            metrics: vec![Metric {
                name: Some(REBIRTH.into()),
                datatype: Some(DataType::Boolean.code()),
                value: Some(Value::Boolean(true)),
                ..Metric::default()
            }],
            ..Payload::default()
        };
        let out = n.command("spBv1.0/g/NCMD/n", &cmd.to_bytes(), 5);
        assert_eq!(out.len(), 2);
        assert_eq!(decode(&out[0]).seq, Some(0));
        assert!(n.command("spBv1.0/g/NCMD/other", &cmd.to_bytes(), 5).is_empty());
        assert!(n.command("spBv1.0/g/NCMD/n", b"\xFF\xFF garbage", 5).is_empty());
        // A flood of rebirths is obeyed at most once per REBIRTH_MIN_MS.
        for t in 6..1_000 {
            assert!(n.command("spBv1.0/g/NCMD/n", &cmd.to_bytes(), t).is_empty());
        }
        assert_eq!(n.rebirths_ignored, 994);
        assert_eq!(n.command("spBv1.0/g/NCMD/n", &cmd.to_bytes(), 5 + REBIRTH_MIN_MS).len(), 2);
    }

    /// A device heard once and then silent for the settling time is born by the tick
    /// (its birth does not wait for a second poll forever).
    #[test]
    fn a_new_device_is_born_once_its_metrics_settle() {
        let mut n = EdgeNode::new("g", "n", 60 * SEC);
        n.online(0);
        assert!(sends(n.update("d", vec![sample("a", 1.into(), 1)], SEC, 1)).is_empty());
        assert!(sends(n.update("d", vec![sample("b", 1.into(), 1)], SEC + 100, 1)).is_empty());
        assert!(n.tick(SEC + BIRTH_SETTLE_NS - 1, 2).is_empty());
        let out = n.tick(SEC + BIRTH_SETTLE_NS, 2);
        assert_eq!(out.len(), 1);
        assert_eq!(decode(&out[0]).metrics.len(), 2);
        assert!(n.tick(SEC + 2 * BIRTH_SETTLE_NS, 3).is_empty(), "born once");
    }

    #[test]
    fn ids_and_names_never_invent_topic_levels() {
        assert_eq!(level("a/b+c#d\u{7}"), "a_b_c_d_");
        assert_eq!(level(""), "_");
        let n = EdgeNode::new("g/x", "#", SEC);
        assert_eq!(n.will().topic, "spBv1.0/g_x/NDEATH/_");
    }

    /// A line reading ever new addresses cannot grow a device's birth without bound.
    #[test]
    fn a_device_declares_at_most_max_metrics() {
        let mut n = EdgeNode::new("g", "n", 60 * SEC);
        n.online(0);
        let samples: Vec<Sample> = (0..MAX_METRICS + 10).map(|i| sample(&format!("r{i}"), 1.into(), 1)).collect();
        assert!(sends(n.update("d", samples, SEC, 1)).is_empty());
        let out = n.tick(SEC + BIRTH_SETTLE_NS, 1);
        assert_eq!(decode(&out[0]).metrics.len(), MAX_METRICS);
        assert_eq!(n.over_limit, 10);
    }
}
