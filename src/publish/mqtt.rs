//! Publishing to an MQTT broker with rumqttc: per unit and register the latest value (on
//! change, at most every `--mqtt-interval` of bus time), per unit its health figures, the bus's
//! findings when they appear or go, a retained `status` (`online`, and `offline` as the last
//! will), the publisher's own counts, and optionally Home Assistant discovery.
//!
//! Never blocks the analysis: messages go into rumqttc's bounded request queue with
//! `try_publish`; when the queue is full (a slow or absent broker) the message is dropped and
//! counted, and the count is published. The connection runs on its own thread and runtime and
//! reconnects every second while the broker is away.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use mbtap_analysis::analyzer::Event;
use mbtap_analysis::health::Health;
use mbtap_device::profile::image::RegisterImage;
use mbtap_device::profile::{Profiles, Table};
use mbtap_device::query::rows::{Row, rows};
use rumqttc::{AsyncClient, MqttOptions, QoS, Transport};

use super::discovery::{control, discovery, discovery_object};
pub use super::mqtt_options::{MqttArgs, topic_level};
use super::mqtt_options::{check_prefix, credentials, default_buffer_dir, hostname, parse_url};

/// The largest MQTT packet sent: a DBIRTH of a big device fits many times over.
pub const MAX_PACKET: usize = 4 << 20;

/// How long a Sparkplug node waits at start for its first session before it analyses on
/// (holding what it measures meanwhile).
const FIRST_SESSION_WAIT: Duration = Duration::from_secs(5);

/// Unit health, findings and the publisher's counts go out at most this often (bus time).
const FIGURES_EVERY_NS: u64 = 1_000_000_000;

/// What was last published for one value.
#[derive(Debug, Clone)]
struct Sent {
    raw: i64,
    shown: String,
    t_ns: u64,
}

#[derive(Debug, Default)]
struct State {
    image: RegisterImage,
    health: Option<Health>,
    last: BTreeMap<(u8, Table, u16), Sent>,
    /// Changed values held back by the interval, newest row each.
    pending: BTreeMap<(u8, Table, u16), (Row, u64)>,
    discovered: BTreeSet<(u8, Table, u16)>,
    units: BTreeMap<u8, String>,
    findings: Option<BTreeSet<(String, Option<u8>)>>,
    next_tick_ns: Option<u64>,
    next_figures_ns: Option<u64>,
    figures_at: Option<std::time::Instant>,
    counts_sent: (u64, u64),
    refused_sent: u64,
}

/// What Home Assistant discovery announces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Announce {
    Nothing,
    /// Every named value as a sensor (or binary sensor).
    Sensors,
    /// With writes from the broker on: writable registers as switches and numbers.
    Controls,
}

/// The publisher.
pub struct Mqtt {
    client: AsyncClient,
    outbox: Arc<Mutex<super::outbox::Outbox>>,
    /// Sparkplug B instead of plain topics.
    sparkplug: bool,
    prefix: String,
    qos: QoS,
    retain: bool,
    interval_ns: u64,
    discovery: Announce,
    profiles: Profiles,
    state: Mutex<State>,
    connected: Arc<AtomicBool>,
    done: Mutex<Option<std::sync::mpsc::Receiver<()>>>,
}

impl std::fmt::Debug for Mqtt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // rumqttc's client has no Debug; the figures are what matter.
        f.debug_struct("Mqtt")
            .field("prefix", &self.prefix)
            .field("qos", &self.qos)
            .field("retain", &self.retain)
            .field("interval_ns", &self.interval_ns)
            .field("discovery", &self.discovery)
            .field("profiles", &self.profiles.len())
            .field("state", &self.state)
            .field("outbox", &self.outbox)
            .field("connected", &self.connected)
            .field("done", &"…")
            .finish_non_exhaustive()
    }
}

use super::outbox::{lock, qos};

impl Mqtt {
    /// Connects (in the background) as `args` say. `source` names the line for the default
    /// prefix; `health` keeps a health analysis for the unit status and findings topics (not for
    /// `watch`, which hears only its own answers).
    pub fn start(args: &MqttArgs, source: &str, profiles: Profiles, health: bool) -> anyhow::Result<Option<Arc<Self>>> {
        Self::start_with(args, source, profiles, health, None)
    }

    /// As [`Self::start`], for a command that writes what the broker asks (`watch`): the asks
    /// go to `writes`. Without it, `--mqtt-writes` is refused at start: a passive sniffer never
    /// writes to the line.
    pub fn start_with(
        args: &MqttArgs,
        source: &str,
        profiles: Profiles,
        health: bool,
        writes: Option<std::sync::mpsc::SyncSender<mbtap_publish::remote::Ask>>,
    ) -> anyhow::Result<Option<Arc<Self>>> {
        let Some(url) = &args.mqtt else { return Ok(None) };
        anyhow::ensure!(
            !args.mqtt_writes || writes.is_some(),
            "--mqtt-writes: only `watch` and `bridge` write what the broker asks; this command only listens, and a passive sniffer never writes to the line"
        );
        let (tls, host, port) = parse_url(url)?;
        let prefix = args.mqtt_prefix.clone().unwrap_or_else(|| {
            let name = std::path::Path::new(source)
                .file_name()
                .map_or_else(|| source.to_owned(), |n| n.to_string_lossy().into_owned());
            format!("mbtap/{}/{}", hostname(), topic_level(&name))
        });
        check_prefix(&prefix).map_err(|why| anyhow::anyhow!("--mqtt-prefix {prefix:?}: {why}"))?;
        let status = format!("{prefix}/status");
        let node = match &args.sparkplug {
            None => None,
            Some(spec) => {
                let (group, node) = spec
                    .split_once('/')
                    .filter(|(g, n)| !g.is_empty() && !n.is_empty() && !n.contains('/'))
                    .with_context(|| format!("--sparkplug {spec:?}: expected GROUP/NODE, e.g. plant1/pumpstation3"))?;
                // Silence shorter than this never kills a device (a slow poll cycle is no death).
                Some(mbtap_publish::sparkplug::EdgeNode::new(group, node, 5_000_000_000))
            }
        };
        let spool = match &args.mqtt_buffer {
            None => None,
            Some(dir) => {
                let dir = if dir.as_os_str().is_empty() {
                    default_buffer_dir(args.sparkplug.as_deref().unwrap_or(&prefix))
                } else {
                    dir.clone()
                };
                let spool = super::spool::Spool::open(&dir, args.mqtt_buffer_max)?;
                eprintln!(
                    "mbtap: mqtt: holding messages in {} while the broker is away (at most {} MB{})",
                    dir.display(),
                    args.mqtt_buffer_max >> 20,
                    if spool.is_empty() {
                        String::new()
                    } else {
                        format!("; {} bytes held from before", spool.bytes())
                    }
                );
                Some(spool)
            }
        };
        let sparkplug = node.is_some();
        let mut options = MqttOptions::new(format!("mbtap-{}-{}", hostname(), std::process::id()), host.clone(), port);
        options.set_keep_alive(Duration::from_secs(10));
        options.set_request_channel_capacity(args.mqtt_queue.max(1));
        // rumqttc refuses packets over 10 KiB by default and drops the connection over one: a
        // DBIRTH declaring a device's hundred metrics is bigger (MQTT allows 256 MiB, v3.1.1 §2.2.3).
        options.set_max_packet_size(super::outbox::MAX_INCOMING, MAX_PACKET);
        if let Some((u, p)) = credentials(args)? {
            options.set_credentials(u, p);
        }
        if tls {
            let ca_path = args
                .mqtt_ca
                .as_ref()
                .context("mqtts:// needs --mqtt-ca FILE: the CA certificate (PEM) that signed the broker's")?;
            let ca =
                std::fs::read(ca_path).with_context(|| format!("--mqtt-ca {}: cannot read it", ca_path.display()))?;
            // One process-wide provider; a second install (a second publisher) is harmless.
            let _ = rustls::crypto::ring::default_provider().install_default();
            options.set_transport(Transport::tls(ca, None, None));
        }
        let (client, eventloop) = {
            // The will needs the outbox (Sparkplug: the NDEATH with its bdSeq), the outbox the client.
            let probe = super::outbox::Outbox::will_of(node.as_ref(), (!sparkplug).then_some(status.as_str()));
            if let Some(w) = probe {
                options.set_last_will(w);
            }
            AsyncClient::new(options, args.mqtt_queue.max(1))
        };
        let mut ob = super::outbox::Outbox::new(client.clone(), spool, node, (!sparkplug).then(|| status.clone()));
        ob.writes = writes.filter(|_| args.mqtt_writes);
        let writes_on = ob.writes.is_some();
        ob.prefix.clone_from(&prefix);
        ob.profiles = profiles.clone();
        ob.memory_cap = args.mqtt_queue.max(1);
        ob.host = args.sparkplug_host.as_deref().map(|h| (mbtap_publish::sparkplug::state_topic(h), false));
        let outbox = Arc::new(Mutex::new(ob));
        let connected = Arc::new(AtomicBool::new(false));
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().context("--mqtt: a runtime")?;
        let (loop_outbox, loop_connected) = (Arc::clone(&outbox), Arc::clone(&connected));
        let broker = format!("{host}:{port}");
        std::thread::Builder::new()
            .name("mqtt".into())
            .spawn(move || {
                rt.block_on(super::connection::run(eventloop, loop_outbox, loop_connected, broker));
                let _ = done_tx.send(());
            })
            .context("--mqtt: starting the publisher thread")?;
        match &args.sparkplug {
            Some(spec) => {
                eprintln!("mbtap: mqtt: publishing to {url} as Sparkplug B edge node {spec}");
                // An edge node is born before it speaks: the first session gets a few seconds to
                // begin, so a fast replay's values go out live rather than all as held history.
                let start = std::time::Instant::now();
                while !connected.load(Ordering::SeqCst) && start.elapsed() < FIRST_SESSION_WAIT {
                    std::thread::sleep(Duration::from_millis(10));
                }
            }
            None => eprintln!("mbtap: mqtt: publishing to {url} under {prefix}/"),
        }
        let health = (health && !sparkplug).then(|| Health::new(profiles.clone()));
        Ok(Some(Arc::new(Self {
            client,
            outbox,
            sparkplug,
            prefix,
            qos: qos(args.mqtt_qos),
            retain: args.mqtt_retain,
            interval_ns: u64::try_from(args.mqtt_interval.as_nanos()).unwrap_or(u64::MAX),
            discovery: match (args.mqtt_discovery.is_some(), writes_on) {
                (false, _) => Announce::Nothing,
                (true, false) => Announce::Sensors,
                (true, true) => Announce::Controls,
            },
            profiles,
            state: Mutex::new(State { health, ..State::default() }),
            connected,
            done: Mutex::new(Some(done_rx)),
        })))
    }

    /// One message to the outbox: out now, held on disk, or dropped (counted).
    fn send(&self, topic: &str, qos: QoS, retain: bool, payload: String) {
        lock(&self.outbox).send(topic, qos, retain, payload.into_bytes());
    }

    fn value_topic(&self, r: &Row) -> String {
        format!("{}/unit/{}/{}/{}", self.prefix, r.unit, r.table.name(), r.address)
    }

    fn publish_row(&self, st: &mut State, r: &Row, t_ns: u64) {
        let mut payload = r.to_json();
        if let Some(o) = payload.as_object_mut() {
            o.insert("t_ns".into(), t_ns.into());
        }
        let topic = self.value_topic(r);
        self.send(&topic, self.qos, self.retain, payload.to_string());
        st.last.insert((r.unit, r.table, r.address), Sent { raw: r.raw, shown: r.shown.clone(), t_ns });
        if self.discovery != Announce::Nothing && r.name.is_some() && st.discovered.insert((r.unit, r.table, r.address))
        {
            self.announce(r, &topic);
        }
    }

    /// Home Assistant MQTT discovery: one entity per named value, grouped by device — a
    /// `binary_sensor` for coils and discrete inputs (on/off), a `sensor` for registers.
    fn announce(&self, r: &Row, state_topic: &str) {
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
        self.send(
            &format!("homeassistant/{component}/{node}/{}/config", discovery_object(r)),
            QoS::AtLeastOnce,
            true,
            config.to_string(),
        );
    }

    /// Takes rows read at bus time `t_ns`: each one published if it changed and its last
    /// publication is an interval old, else held for the next tick.
    fn take_rows(&self, st: &mut State, rows: Vec<Row>, t_ns: u64) {
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
    /// `--mqtt-interval 0` they were computed per event: quadratic over a long capture).
    fn tick(&self, st: &mut State, t_ns: u64) {
        if self.sparkplug {
            let mut ob = lock(&self.outbox);
            let outs = ob.node.as_mut().map(|n| n.tick(t_ns, super::outbox::now_ms())).unwrap_or_default();
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

    fn flush(&self, st: &mut State, last: bool) {
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

    /// Rows from `watch`'s reads.
    pub fn rows(&self, rows: Vec<Row>, t_ns: u64) {
        if let Ok(mut st) = self.state.lock() {
            self.take_rows(&mut st, rows, t_ns);
        }
    }

    /// The end: what is held goes out, `offline` (retained), then the connection closes
    /// (waiting at most 2 s for the broker to take what is queued).
    pub fn finish(&self) {
        if let Ok(mut st) = self.state.lock() {
            self.flush(&mut st, true);
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
                super::outbox::MAX_COMMAND
            );
        }
        if ob.commands.busy_writes > 0 {
            eprintln!(
                "mbtap: mqtt: {} writes from the broker dropped: {} already waited for the line",
                ob.commands.busy_writes,
                super::outbox::COMMANDS_WAITING
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

    /// What became of a write the broker asked for: published on `PREFIX/unit/U/write` (plain;
    /// Sparkplug hosts see the value read back as DDATA), refusals counted.
    pub fn write_result(&self, ask: &mbtap_publish::remote::Ask, outcome: &mbtap_publish::remote::Outcome, t_ns: u64) {
        match outcome {
            Err(why) => lock(&self.outbox).refuse(Some(ask.unit), why),
            Ok(back) => {
                eprintln!("mbtap: mqtt: wrote {} to unit {} as the broker asked", ask.item.text, ask.unit);
                if !self.sparkplug {
                    let body = serde_json::json!({
                        "ok": true, "item": ask.item.text, "t_ns": t_ns,
                        "read_back": back.as_ref().map(mbtap_device::query::rows::Row::to_json),
                    });
                    self.send(
                        &format!("{}/unit/{}/write", self.prefix, ask.unit),
                        QoS::AtLeastOnce,
                        false,
                        body.to_string(),
                    );
                }
                if let Some(r) = back {
                    self.rows(vec![r.clone()], t_ns);
                }
            }
        }
    }

    /// Sparkplug: the rows of one event as samples of their units' devices.
    fn sparkplug_rows(&self, rows: Vec<Row>, t_ns: u64) {
        let mut by_unit: BTreeMap<u8, Vec<mbtap_publish::sparkplug::Sample>> = BTreeMap::new();
        let t_ms = t_ns / 1_000_000;
        for r in rows {
            let name = r.name.clone().unwrap_or_else(|| format!("{} {}", r.table.name(), r.address));
            by_unit.entry(r.unit).or_default().push(mbtap_publish::sparkplug::Sample {
                name: mbtap_publish::sparkplug::node::metric_name(&name),
                value: r.value.clone(),
                bits: mbtap_device::query::is_bits(r.table),
                unit: r.unit_of_measure.clone(),
                t_ms,
            });
        }
        let now = super::outbox::now_ms();
        let mut ob = lock(&self.outbox);
        for (unit, samples) in by_unit {
            let device = match self.profiles.get(&unit) {
                Some(p) => format!("{}-{unit}", p.meta.name),
                None => format!("unit-{unit}"),
            };
            let Some(emit) = ob.node.as_mut().map(|n| n.update(&device, samples, t_ns, now)) else { continue };
            ob.emit(emit);
        }
        let outs = ob.node.as_mut().map(|n| n.tick(t_ns, now)).unwrap_or_default();
        ob.send_outs(outs);
    }
}

impl crate::output::Tap for Mqtt {
    fn event(&self, e: &Event<'_>) {
        let Ok(mut st) = self.state.lock() else { return };
        let st = &mut *st;
        if let Some(h) = st.health.as_mut() {
            h.event(e);
        }
        let t = crate::output::event_time(e);
        if !matches!(e, Event::Transaction(_)) {
            self.tick(st, t);
            return;
        }
        crate::output::update_image(&mut st.image, e);
        // Whole values around each address the transaction set, each once.
        let mut seen = BTreeSet::new();
        let mut out = Vec::new();
        for &(unit, table, a) in st.image.touched() {
            let p = self.profiles.get(&unit);
            let (first, width) = match p.and_then(|p| p.slot(table, a)) {
                Some((slot, def)) if !matches!(table, Table::Coils | Table::DiscreteInputs) => (slot.first, def.width),
                _ => (a, 1),
            };
            if !seen.insert((unit, table, first)) {
                continue;
            }
            let regs: Option<Vec<u16>> = (0..width)
                .map(|i| first.checked_add(i).and_then(|x| st.image.values.get(&(unit, table, x))).map(|k| k.raw))
                .collect();
            // Half of a value heard (the other register never read): not published.
            if let Some(regs) = regs {
                out.extend(rows(unit, table, first, &regs, p).into_iter().take(1));
            }
        }
        self.take_rows(st, out, t);
    }
}
