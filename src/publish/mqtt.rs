//! Publishing to an MQTT broker with rumqttc: per unit and register the latest value (on
//! change, at most every `--mqtt-interval` of bus time), per unit its health figures, the bus's
//! findings when they appear or go, a retained `status` (`online`, and `offline` as the last
//! will), the publisher's own counts, and optionally Home Assistant discovery.
//!
//! Never blocks the analysis: messages go into rumqttc's bounded request queue with
//! `try_publish`; when the queue is full (a slow or absent broker) the message is dropped and
//! counted, and the count is published. The connection runs on its own thread and runtime and
//! reconnects every second while the broker is away.
//!
//! Its `rows` module turns the analysed rows into those messages.

use std::collections::{BTreeMap, BTreeSet};
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

pub use super::mqtt_options::{MqttArgs, topic_level};
use super::mqtt_options::{check_prefix, credentials, default_buffer_dir, hostname, parse_url};

/// The largest MQTT packet sent: a DBIRTH of a big device fits many times over.
pub const MAX_PACKET: usize = 4 << 20;

/// How long a Sparkplug node waits at start for its first session before it analyses on
/// (holding what it measures meanwhile).
/// Home Assistant's birth and last-will topic under its default discovery prefix (Home
/// Assistant MQTT integration, "Birth and last will messages": `online` when it starts).
const HA_BIRTH_TOPIC: &str = "homeassistant/status";
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
    /// The discovery configs announced, for `--mqtt-forget` to take back at the end.
    announced: BTreeSet<String>,
    /// Every value announced to Home Assistant, with its last row and when: announced again,
    /// with its state, when Home Assistant comes back (its birth message).
    discovered: BTreeMap<(u8, Table, u16), (Row, u64)>,
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
    /// `--mqtt-forget`: the end takes back every retained config and value this run announced.
    forget: bool,
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

mod rows;

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
        ob.ha_status = (args.mqtt_discovery.is_some() && !sparkplug).then(|| HA_BIRTH_TOPIC.to_owned());
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
            forget: args.mqtt_forget,
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

    /// Rows from `watch`'s reads.
    pub fn rows(&self, rows: Vec<Row>, t_ns: u64) {
        if let Ok(mut st) = self.state.lock() {
            self.take_rows(&mut st, rows, t_ns);
        }
    }

    /// What became of a write the broker asked for: published on `PREFIX/unit/U/write` (plain;
    /// Sparkplug hosts see the value read back as DDATA), refusals counted.
    pub fn write_result(
        &self,
        ask: &mbtap_publish::remote::Ask,
        outcome: &mbtap_publish::remote::WriteResult,
        t_ns: u64,
    ) {
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
