//! How rows become messages: each value on its topic (when it changed, or held for the interval),
//! Home Assistant discovery announcing it once, the unit status and findings of the health
//! analysis, and the held values flushed at a tick or at the end; the end itself (what is held
//! goes out, `offline`, the counts said).

use super::{Announce, FIGURES_EVERY_NS, Mqtt, Sent, State};
use crate::publish::discovery::{control, discovery, discovery_object};
use crate::publish::outbox::lock;
use mbtap_device::query::rows::Row;
use rumqttc::QoS;
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::sync::atomic::Ordering;
use std::time::Duration;

impl Mqtt {
    /// One message to the outbox: out now, held on disk, or dropped (counted).
    pub(super) fn send(&self, topic: &str, qos: QoS, retain: bool, payload: String) {
        lock(&self.outbox).send(topic, qos, retain, payload.into_bytes());
    }

    pub(super) fn value_topic(&self, r: &Row) -> String {
        format!("{}/unit/{}/{}/{}", self.prefix, r.unit, r.table.name(), r.address)
    }

    pub(super) fn publish_row(&self, st: &mut State, r: &Row, t_ns: u64) {
        let mut payload = r.to_json();
        if let Some(o) = payload.as_object_mut() {
            o.insert("t_ns".into(), t_ns.into());
        }
        let topic = self.value_topic(r);
        // The entity first, then its state: Home Assistant subscribes to the state topic when the
        // config arrives, so a state sent before it is never seen and the sensor sits at
        // `unknown` until the value changes (an energy total still overnight: all night).
        let discovering = self.discovery != Announce::Nothing;
        if discovering && r.name.is_some() {
            let key = (r.unit, r.table, r.address);
            if st.discovered.insert(key, (r.clone(), t_ns)).is_none() {
                let config = self.announce(r, &topic);
                if self.forget {
                    st.announced.insert(config);
                }
            }
        }
        // With discovery, states are retained: a Home Assistant that starts (or restarts) after
        // mbtap gets every current value at once, as it gets the retained configs.
        self.send(&topic, self.qos, self.retain || discovering, payload.to_string());
        st.last.insert((r.unit, r.table, r.address), Sent { raw: r.raw, shown: r.shown.clone(), t_ns });
    }

    /// Home Assistant came back (its birth message): every entity announced so far is announced
    /// again, then its current state, retained — so none sits `unknown` until its value changes.
    pub(super) fn announce_again(&self, st: &State) {
        for (r, t_ns) in st.discovered.values() {
            let topic = self.value_topic(r);
            let _ = self.announce(r, &topic);
            let mut payload = r.to_json();
            if let Some(o) = payload.as_object_mut() {
                o.insert("t_ns".into(), (*t_ns).into());
            }
            self.send(&topic, self.qos, true, payload.to_string());
        }
    }

    /// Home Assistant MQTT discovery: one entity per named value, grouped by device — a
    /// `binary_sensor` for coils and discrete inputs (on/off), a `sensor` for registers.
    /// The config's topic.
    pub(super) fn announce(&self, r: &Row, state_topic: &str) -> String {
        let profile = self.profiles.get(&r.unit);
        let (node, object, component, config) = discovery(&self.prefix, r, profile, state_topic);
        let _ = object;
        let (component, config) = match (self.discovery == Announce::Controls)
            .then(|| control(r, profile, state_topic, config.clone()))
            .flatten()
        {
            Some(control) => control,
            None => (component, config),
        };
        let topic = format!("homeassistant/{component}/{node}/{}/config", discovery_object(r));
        self.send(&topic, QoS::AtLeastOnce, true, config.to_string());
        topic
    }

    /// Takes rows read at bus time `t_ns`: each one published if it changed and its last
    /// publication is an interval old, else held for the next tick.
    pub(super) fn take_rows(&self, st: &mut State, rows: Vec<Row>, t_ns: u64) {
        // Home Assistant (re)started since the last rows: it is told everything again first.
        if !self.sparkplug && lock(&self.outbox).take_ha_birth() {
            self.announce_again(st);
        }
        if self.sparkplug {
            self.sparkplug_rows(rows, t_ns);
            return;
        }
        for r in rows {
            let key = (r.unit, r.table, r.address);
            match st.last.get(&key) {
                Some(s) if s.raw == r.raw && s.shown == r.shown => {
                    st.pending.remove(&key);
                }
                Some(s) if t_ns.saturating_sub(s.t_ns) < self.interval_ns => {
                    st.pending.insert(key, (r, t_ns));
                }
                _ => self.publish_row(st, &r, t_ns),
            }
        }
        self.tick(st, t_ns);
    }

    /// Every interval of bus time: held values; every [`FIGURES_EVERY_NS`] (or the interval,
    /// if longer) of bus time and at least a second of the clock: unit health, findings, own
    /// counts. The figures cost a health report each, so they never follow a short interval (at
    /// `--mqtt-interval 0`, per event, they would be quadratic over a long capture).
    pub(super) fn tick(&self, st: &mut State, t_ns: u64) {
        if self.sparkplug {
            let mut ob = lock(&self.outbox);
            let outs = ob.node.as_mut().map(|n| n.tick(t_ns, crate::publish::outbox::now_ms())).unwrap_or_default();
            ob.send_outs(outs);
            return;
        }
        if !st.pending.is_empty() {
            let due = *st.next_tick_ns.get_or_insert(t_ns.saturating_add(self.interval_ns));
            if t_ns >= due {
                st.next_tick_ns = Some(t_ns.saturating_add(self.interval_ns));
                for (_, (r, t)) in std::mem::take(&mut st.pending) {
                    self.publish_row(st, &r, t);
                }
            }
        }
        let every = self.interval_ns.max(FIGURES_EVERY_NS);
        let due = *st.next_figures_ns.get_or_insert(t_ns.saturating_add(every));
        // Also a second of the clock: a replay runs a thousand times faster than its line, and
        // each report sorts every latency heard (live, bus time and the clock agree).
        let clock_due = st.figures_at.is_none_or(|at| at.elapsed() >= Duration::from_secs(1));
        if t_ns >= due && clock_due {
            st.next_figures_ns = Some(t_ns.saturating_add(every));
            st.figures_at = Some(std::time::Instant::now());
            self.flush(st, false);
        }
    }

    pub(super) fn flush(&self, st: &mut State, last: bool) {
        for (_, (r, t)) in std::mem::take(&mut st.pending) {
            self.publish_row(st, &r, t);
        }
        if let Some(h) = &st.health {
            let report = h.report();
            for u in &report.units {
                let j = serde_json::to_value(u).unwrap_or_default().to_string();
                if st.units.get(&u.unit) != Some(&j) {
                    self.send(&format!("{}/unit/{}/status", self.prefix, u.unit), self.qos, true, j.clone());
                    st.units.insert(u.unit, j);
                }
            }
            let kinds: BTreeSet<(String, Option<u8>)> =
                report.findings.iter().map(|f| (f.kind.to_owned(), f.unit)).collect();
            if st.findings.as_ref() != Some(&kinds) || last {
                let list: Vec<serde_json::Value> = report
                    .findings
                    .iter()
                    .map(|f| serde_json::json!({"kind": f.kind, "unit": f.unit, "count": f.count, "summary": f.summary, "last_t_ns": f.last_t_ns}))
                    .collect();
                self.send(
                    &format!("{}/findings", self.prefix),
                    self.qos,
                    true,
                    serde_json::Value::from(list).to_string(),
                );
                st.findings = Some(kinds);
            }
        }
        let counts = {
            let ob = lock(&self.outbox);
            (ob.published, ob.dropped, ob.refused_writes)
        };
        if counts.1 != st.counts_sent.1 || counts.2 != st.refused_sent || last {
            // The count of drops itself may be dropped; the next change or the end says it again.
            let j = serde_json::json!({"published": counts.0, "dropped": counts.1, "refused_writes": counts.2});
            st.refused_sent = counts.2;
            self.send(&format!("{}/publisher", self.prefix), QoS::AtLeastOnce, true, j.to_string());
            st.counts_sent = (counts.0, counts.1);
        }
    }
}

impl Mqtt {
    /// `--mqtt-forget`: every discovery config this run announced taken back with an empty
    /// retained message (MQTT v3.1.1 §3.3.1.3: a zero-byte retained message removes the retained
    /// one; Home Assistant removes an entity whose config is emptied). The values' retained states
    /// stay: without a config they make no entity, and a reader of the topics still finds them.
    fn forget_announced(&self, st: &mut State) {
        let n = st.announced.len();
        for topic in std::mem::take(&mut st.announced) {
            lock(&self.outbox).publish_now(&topic, QoS::AtLeastOnce, true, Vec::new());
        }
        eprintln!("mbtap: mqtt: {n} Home Assistant entities taken back (--mqtt-forget)");
    }

    /// The end: what is held goes out, `offline` (retained), then the connection closes
    /// (waiting at most 2 s for the broker to take what is queued).
    pub fn finish(&self) {
        if let Ok(mut st) = self.state.lock() {
            self.flush(&mut st, true);
            if self.forget {
                self.forget_announced(&mut st);
            }
        }
        {
            let mut ob = lock(&self.outbox);
            // The end said at once, never held: a held `offline` forwarded after the next run's
            // `online` would say the wrong thing. Sparkplug: the NDEATH a clean end publishes
            // itself (§7.2), with the session's bdSeq.
            if self.connected.load(Ordering::SeqCst) {
                let end = match ob.node.as_ref().map(mbtap_publish::sparkplug::EdgeNode::will) {
                    Some(w) => (w.topic, w.payload, false),
                    None => (format!("{}/status", self.prefix), b"offline".to_vec(), true),
                };
                ob.publish_now(&end.0, QoS::AtLeastOnce, end.2, end.1);
            }
            if let Some(s) = ob.spool.as_mut() {
                s.sync();
            }
        }
        let _ = self.client.try_disconnect();
        if let Some(done) = self.done.lock().ok().and_then(|mut d| d.take()) {
            let _ = done.recv_timeout(Duration::from_secs(2));
        }
        let ob = lock(&self.outbox);
        if let Some(n) = ob.node.as_ref().filter(|n| n.rebirths_ignored > 0) {
            eprintln!(
                "mbtap: mqtt: {} rebirth commands not obeyed (at most one each {} s)",
                n.rebirths_ignored,
                mbtap_publish::sparkplug::node::REBIRTH_MIN_MS / 1000
            );
        }
        if ob.commands.oversized > 0 {
            eprintln!(
                "mbtap: mqtt: {} messages from the broker dropped as too long (commands are at most {} bytes)",
                ob.commands.oversized,
                crate::publish::outbox::MAX_COMMAND
            );
        }
        if ob.commands.busy_writes > 0 {
            eprintln!(
                "mbtap: mqtt: {} writes from the broker dropped: {} already waited for the line",
                ob.commands.busy_writes,
                crate::publish::outbox::COMMANDS_WAITING
            );
        }
        if let Some(n) = ob.node.as_ref().filter(|n| n.over_limit > 0) {
            eprintln!(
                "mbtap: mqtt: {} values not published: their device already declares {} metrics (the most one Sparkplug birth carries here)",
                n.over_limit,
                mbtap_publish::sparkplug::node::MAX_METRICS
            );
        }
        let mut held = match &ob.spool {
            Some(s) if !s.is_empty() => format!("; {} held on disk for the next run ({} bytes)", ob.held, s.bytes()),
            Some(s) if s.dropped > 0 => format!("; {} held messages dropped (the buffer was full)", s.dropped),
            _ => String::new(),
        };
        let mut why = "queue full or broker away";
        if let Some(s) = ob.spool.as_ref().filter(|s| s.unwritable > 0) {
            why = "queue full, broker away, or the buffer could not be written";
            let _ = write!(held, "; {} could not be written to the buffer", s.unwritable);
        }
        if let Some(s) = ob.spool.as_ref().filter(|s| s.aside > 0) {
            let _ = write!(held, "; {} file(s) in the buffer left aside unread (said above)", s.aside);
        }
        eprintln!("mbtap: mqtt: {} messages queued for the broker, {} dropped ({why}){held}", ob.published, ob.dropped);
    }
}
