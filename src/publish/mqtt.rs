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
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use clap::Args;
use mbtap_core::analyzer::Event;
use mbtap_core::health::Health;
use mbtap_core::profile::image::RegisterImage;
use mbtap_core::profile::{Profiles, Table};
use mbtap_core::query::rows::{Row, rows};
use rumqttc::{AsyncClient, MqttOptions, QoS, Transport};

/// `--mqtt` options (on `sniff`, `tap`, `replay`, `watch` and `bridge --monitor`).
#[derive(Debug, Clone, Args, Default)]
pub struct MqttArgs {
    /// Publish to an MQTT broker: `mqtt://HOST[:PORT]` (1883) or `mqtts://HOST[:PORT]` (8883,
    /// with --mqtt-ca). User and password come from --mqtt-credentials or the environment
    /// (MBTAP_MQTT_USER, MBTAP_MQTT_PASSWORD), never from the command line.
    #[arg(long, value_name = "URL")]
    pub mqtt: Option<String>,
    /// Topic prefix [default: mbtap/HOSTNAME/PORT].
    #[arg(long, value_name = "TOPIC")]
    pub mqtt_prefix: Option<String>,
    /// The CA certificate (PEM) that signed the broker's, for mqtts://.
    #[arg(long, value_name = "FILE")]
    pub mqtt_ca: Option<PathBuf>,
    /// A file holding `USER:PASSWORD` on its first line.
    #[arg(long, value_name = "FILE")]
    pub mqtt_credentials: Option<PathBuf>,
    /// QoS of value, health and findings messages (the status is always QoS 1).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=2))]
    pub mqtt_qos: u8,
    /// Retain value messages (the status and discovery messages always are).
    #[arg(long)]
    pub mqtt_retain: bool,
    /// A value that changes is published at most this often (bus time): `1s`, `250ms`, `0`.
    #[arg(long, default_value = "1s", value_parser = parse_interval, value_name = "INTERVAL")]
    pub mqtt_interval: Duration,
    /// Announce a sensor per register heard that the profile names.
    #[arg(long, value_enum, value_name = "KIND")]
    pub mqtt_discovery: Option<Discovery>,
    /// Messages waiting for the broker at most; more are dropped and counted.
    #[arg(long, default_value_t = 10_000, value_name = "MESSAGES")]
    pub mqtt_queue: usize,
    /// Publish as a Sparkplug B 3.0 edge node GROUP/NODE instead of plain topics: NBIRTH and
    /// NDEATH (the will, with bdSeq), a device per unit with DBIRTH, DDATA on change and
    /// DDEATH when it falls silent, rebirth on the `Node Control/Rebirth` command.
    #[arg(long, value_name = "GROUP/NODE")]
    pub sparkplug: Option<String>,
    /// With --sparkplug: the primary host's id. Until its STATE (`spBv1.0/STATE/ID`) says it is
    /// online, and whenever it says it is offline, nothing is born or published live — what is
    /// measured is held and forwarded as historical data once it is back.
    #[arg(long, value_name = "HOST_ID", requires = "sparkplug")]
    pub sparkplug_host: Option<String>,
    /// Store and forward: while the broker is away, hold messages on disk here and forward them
    /// when it is back (Sparkplug: as historical data with their timestamps). Without DIR:
    /// $XDG_STATE_HOME/mbtap/mqtt-buffer/PREFIX (~/.local/state/…). Without the option,
    /// messages wait in memory (--mqtt-queue) and are dropped when it is full.
    #[arg(long, value_name = "DIR", num_args = 0..=1, default_missing_value = "")]
    pub mqtt_buffer: Option<PathBuf>,
    /// The most the buffer holds on disk (`500MB`, `2GB`, bytes); beyond it the oldest held
    /// messages are dropped, counted and said.
    #[arg(long, default_value = "256MB", value_parser = parse_size, value_name = "SIZE")]
    pub mqtt_buffer_max: u64,
    /// Let the broker write (`watch`, `bridge`): `PREFIX/unit/U/TABLE/ADDRESS/set` (the value) and
    /// `PREFIX/unit/U/set` (`NAME=VALUE`), or Sparkplug DCMD by metric name — through the
    /// profile's names, scale, ranges and access, as `mbtap write`; each outcome published on
    /// `PREFIX/unit/U/write` (Sparkplug: the value read back as DDATA); on the bridge also through
    /// its read-only, allow-lists, routes and `--mqtt-role`. Off: refused and counted.
    #[arg(long)]
    pub mqtt_writes: bool,
}

/// `256MB`, `2GB`, `64KB` or bytes.
fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (num, mult) = [("GB", 1u64 << 30), ("MB", 1 << 20), ("KB", 1 << 10), ("B", 1)]
        .iter()
        .find_map(|(suffix, m)| t.strip_suffix(suffix).map(|n| (n.trim(), *m)))
        .unwrap_or((t, 1));
    num.parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(mult))
        .filter(|&n| n >= 1 << 20)
        .ok_or_else(|| format!("{s:?}: expected a size of at least 1MB, like 256MB or 2GB"))
}

/// Discovery conventions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Discovery {
    /// Home Assistant's MQTT discovery (`homeassistant/sensor/…/config`).
    Homeassistant,
}

/// From 0 (every change) to a day.
fn parse_interval(s: &str) -> Result<Duration, String> {
    mbtap_core::duration::parse_duration(s, Duration::ZERO, Duration::from_hours(24))
}

/// A topic level from free text: MQTT reserves `/`, `+` and `#` (MQTT v3.1.1 §4.7).
#[must_use]
pub fn topic_level(s: &str) -> String {
    let t: String =
        s.chars().map(|c| if c.is_alphanumeric() || c == '-' || c == '_' || c == '.' { c } else { '_' }).collect();
    if t.is_empty() { "_".into() } else { t }
}

/// Room left after the prefix for the topic levels mbtap adds (`/unit/247/holding_registers/65535`,
/// discovery ids): a whole topic is at most 65 535 bytes (MQTT v3.1.1 §1.5.3, §4.7.3).
const MAX_PREFIX_BYTES: usize = 65_535 - 1_024;

/// Whether `prefix` can start every topic mbtap publishes: the broker drops a publication to a
/// topic it cannot take without telling a QoS 0 publisher, so a prefix it would refuse is
/// refused here (issue 24: `$SYS/x`, a tab, 70 kB: every message dropped, "0 dropped" said).
///
/// # Errors
/// What is wrong, with the rule: no `+`/`#` (MQTT v3.1.1 §4.7.1), no leading `$` (topics
/// starting with `$` are the broker's, §4.7.2), no control characters (U+0000 is forbidden,
/// §1.5.3, and the others never reach a subscriber intact), not empty, not too long (§1.5.3).
pub fn check_prefix(prefix: &str) -> Result<(), String> {
    if prefix.is_empty() {
        return Err("the prefix is empty; give one like site/line1".into());
    }
    if prefix.contains(['+', '#']) {
        return Err("a topic prefix cannot contain + or # (wildcards, MQTT v3.1.1 §4.7.1)".into());
    }
    if prefix.starts_with('$') {
        return Err(
            "topics starting with $ are the broker's own ($SYS…, MQTT v3.1.1 §4.7.2): it drops publications to them"
                .into(),
        );
    }
    if let Some((at, c)) = prefix.char_indices().find(|(_, c)| c.is_control()) {
        return Err(format!(
            "a control character (U+{:04X}) at byte {at}; topics are printable UTF-8 (MQTT v3.1.1 §1.5.3)",
            u32::from(c)
        ));
    }
    if prefix.len() > MAX_PREFIX_BYTES {
        return Err(format!(
            "{} bytes; a topic is at most 65 535 bytes (MQTT v3.1.1 §1.5.3) and mbtap adds levels after the prefix: at most {MAX_PREFIX_BYTES}",
            prefix.len()
        ));
    }
    Ok(())
}

/// The discovery object id of a row: `u1_holding_registers_105`.
fn discovery_object(r: &Row) -> String {
    format!("u{}_{}_{}", r.unit, r.table.name(), r.address)
}

/// A Home Assistant discovery message for `r`: (node id, object id, component, config).
/// Keys without a value are left out (issue 31: `"manufacturer": null` for a profile without a
/// vendor, which Home Assistant's schema refuses: a string or no key); coils and discrete inputs
/// are binary sensors with the raw 1/0 as their state, not numeric sensors.
///
/// Writable registers are announced as sensors, not `number`/`switch`/`select` controls: a
/// control whose commands nothing executes would mislead; they come with writes from the broker.
pub fn discovery(
    prefix: &str,
    r: &Row,
    profile: Option<&mbtap_core::profile::Profile>,
    state_topic: &str,
) -> (String, String, &'static str, serde_json::Value) {
    let node = topic_level(&prefix.replace('/', "_"));
    let object = discovery_object(r);
    let mut device = serde_json::json!({
        "identifiers": [format!("{node}_u{}", r.unit)],
        "name": format!("{} (unit {})", profile.map_or("Modbus device", |p| p.meta.device.as_str()), r.unit),
        "via_device": node,
    });
    if let Some(d) = device.as_object_mut() {
        if let Some(vendor) = profile.and_then(|p| p.meta.vendor.clone()) {
            d.insert("manufacturer".into(), vendor.into());
        }
        if let Some(p) = profile {
            d.insert("model".into(), p.meta.name.clone().into());
        }
    }
    let bits = mbtap_core::query::is_bits(r.table);
    let mut config = serde_json::json!({
        "name": r.name,
        "unique_id": format!("{node}_{object}"),
        "object_id": format!("{node}_{object}"),
        "state_topic": state_topic,
        "availability_topic": format!("{prefix}/status"),
        "device": device,
    });
    if let Some(o) = config.as_object_mut() {
        if bits {
            o.insert("value_template".into(), "{{ value_json.raw }}".into());
            o.insert("payload_on".into(), "1".into());
            o.insert("payload_off".into(), "0".into());
        } else {
            o.insert("value_template".into(), "{{ value_json.value }}".into());
            if let Some(u) = &r.unit_of_measure {
                o.insert("unit_of_measurement".into(), u.clone().into());
            }
        }
    }
    (node, object, if bits { "binary_sensor" } else { "sensor" }, config)
}

/// With writes from the broker on (`watch --mqtt-writes`): a register the profile documents as
/// writable is announced as a control instead of a sensor — a coil as a `switch`, a register
/// with labels as a `select` of them, a numeric holding register as a `number` within its
/// documented range (scaled) — whose commands go to its
/// `…/set` topic and through the profile's checks. `None`: stays a sensor (read-only, labels,
/// text, or no profile).
pub fn control(
    r: &Row,
    profile: Option<&mbtap_core::profile::Profile>,
    state_topic: &str,
    mut config: serde_json::Value,
) -> Option<(&'static str, serde_json::Value)> {
    use mbtap_core::profile::format::Access;
    let (_, def) = profile?.slot(r.table, r.address)?;
    if def.access == Access::Read || !matches!(r.table, Table::Coils | Table::HoldingRegisters) {
        return None;
    }
    let o = config.as_object_mut()?;
    o.insert("command_topic".into(), format!("{state_topic}/set").into());
    if r.table == Table::Coils {
        o.insert("state_on".into(), "1".into());
        o.insert("state_off".into(), "0".into());
        return Some(("switch", config));
    }
    // A register with labels is a choice among them: a select whose option is written by its
    // label (the write path takes labels as `mbtap write` does).
    if !def.labels.is_empty() {
        let options: Vec<serde_json::Value> = def.labels.values().map(|l| l.clone().into()).collect();
        o.insert("options".into(), options.into());
        return Some(("select", config));
    }
    // Text is not a number; a value without a documented range is not offered as one either.
    if !r.value.is_number() {
        return None;
    }
    let (lo, hi) = def.range?;
    let scale = def.scale.unwrap_or(1.0);
    #[allow(clippy::cast_precision_loss)] // documented ranges are far inside f64's exact integers
    let (min, max) = (lo as f64 * scale, hi as f64 * scale);
    o.insert("min".into(), min.min(max).into());
    o.insert("max".into(), max.max(min).into());
    o.insert("step".into(), scale.abs().into());
    o.insert("mode".into(), "box".into());
    Some(("number", config))
}

/// This machine's name, for the default prefix.
fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map_or_else(|| "host".into(), |h| topic_level(h.trim()))
}

/// `mqtt://host:port` → (tls, host, port).
fn parse_url(url: &str) -> anyhow::Result<(bool, String, u16)> {
    let (tls, rest) = if let Some(r) = url.strip_prefix("mqtts://") {
        (true, r)
    } else if let Some(r) = url.strip_prefix("mqtt://") {
        (false, r)
    } else {
        anyhow::bail!("--mqtt {url:?}: expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT]");
    };
    let rest = rest.trim_end_matches('/');
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) if !h.is_empty() => {
            (h, p.parse().with_context(|| format!("--mqtt {url:?}: port {p:?} is not a number 1..=65535"))?)
        }
        _ => (rest, if tls { 8883 } else { 1883 }),
    };
    anyhow::ensure!(!host.is_empty(), "--mqtt {url:?}: no host");
    anyhow::ensure!(
        !host.contains('@'),
        "--mqtt {url:?}: credentials do not go in the URL; use --mqtt-credentials FILE or MBTAP_MQTT_USER/MBTAP_MQTT_PASSWORD"
    );
    Ok((tls, host.trim_matches(['[', ']']).to_owned(), port))
}

fn credentials(args: &MqttArgs) -> anyhow::Result<Option<(String, String)>> {
    if let Some(path) = &args.mqtt_credentials {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("--mqtt-credentials {}: cannot read it", path.display()))?;
        let line = text.lines().next().unwrap_or_default();
        let (u, p) = line
            .split_once(':')
            .with_context(|| format!("--mqtt-credentials {}: line 1: expected USER:PASSWORD", path.display()))?;
        return Ok(Some((u.to_owned(), p.to_owned())));
    }
    match (std::env::var("MBTAP_MQTT_USER"), std::env::var("MBTAP_MQTT_PASSWORD")) {
        (Ok(u), Ok(p)) => Ok(Some((u, p))),
        (Ok(_), Err(_)) => anyhow::bail!("MBTAP_MQTT_USER is set but MBTAP_MQTT_PASSWORD is not"),
        _ => Ok(None),
    }
}

/// The largest MQTT packet sent or taken: a DBIRTH of a big device fits many times over.
const MAX_PACKET: usize = 4 << 20;

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

/// The buffer directory when `--mqtt-buffer` is given without one.
fn default_buffer_dir(prefix: &str) -> PathBuf {
    let state = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local").join("state")));
    state
        .unwrap_or_else(std::env::temp_dir)
        .join("mbtap")
        .join("mqtt-buffer")
        .join(topic_level(&prefix.replace('/', "_")))
}

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
        writes: Option<std::sync::mpsc::Sender<mbtap_core::query::remote::Ask>>,
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
                Some(mbtap_core::sparkplug::EdgeNode::new(group, node, 5_000_000_000))
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
        options.set_max_packet_size(MAX_PACKET, MAX_PACKET);
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
        ob.host = args.sparkplug_host.as_deref().map(|h| (mbtap_core::sparkplug::state_topic(h), false));
        let outbox = Arc::new(Mutex::new(ob));
        let connected = Arc::new(AtomicBool::new(false));
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().context("--mqtt: a runtime")?;
        let (loop_outbox, loop_connected) = (Arc::clone(&outbox), Arc::clone(&connected));
        let broker = format!("{host}:{port}");
        std::thread::Builder::new()
            .name("mqtt".into())
            .spawn(move || {
                rt.block_on(super::outbox::run(eventloop, loop_outbox, loop_connected, broker));
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
                let end = match ob.node.as_ref().map(mbtap_core::sparkplug::EdgeNode::will) {
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
        let held = match &ob.spool {
            Some(s) if !s.is_empty() => format!("; {} held on disk for the next run ({} bytes)", ob.held, s.bytes()),
            Some(s) if s.dropped > 0 => format!("; {} held messages dropped (the buffer was full)", s.dropped),
            _ => String::new(),
        };
        eprintln!(
            "mbtap: mqtt: {} messages queued for the broker, {} dropped (queue full or broker away){held}",
            ob.published, ob.dropped
        );
    }

    /// What became of a write the broker asked for: published on `PREFIX/unit/U/write` (plain;
    /// Sparkplug hosts see the value read back as DDATA), refusals counted.
    pub fn write_result(
        &self,
        ask: &mbtap_core::query::remote::Ask,
        outcome: &mbtap_core::query::remote::Outcome,
        t_ns: u64,
    ) {
        match outcome {
            Err(why) => lock(&self.outbox).refuse(Some(ask.unit), why),
            Ok(back) => {
                eprintln!("mbtap: mqtt: wrote {} to unit {} as the broker asked", ask.item.text, ask.unit);
                if !self.sparkplug {
                    let body = serde_json::json!({
                        "ok": true, "item": ask.item.text, "t_ns": t_ns,
                        "read_back": back.as_ref().map(mbtap_core::query::rows::Row::to_json),
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
        let mut by_unit: BTreeMap<u8, Vec<mbtap_core::sparkplug::Sample>> = BTreeMap::new();
        let t_ms = t_ns / 1_000_000;
        for r in rows {
            let name = r.name.clone().unwrap_or_else(|| format!("{} {}", r.table.name(), r.address));
            by_unit.entry(r.unit).or_default().push(mbtap_core::sparkplug::Sample {
                name: mbtap_core::sparkplug::node::metric_name(&name),
                value: r.value.clone(),
                bits: mbtap_core::query::is_bits(r.table),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 31: the MKZP (a profile without a vendor) was announced with `"manufacturer":
    /// null`, which Home Assistant's schema refuses, and coils as numeric sensors.
    #[test]
    fn discovery_leaves_out_absent_keys_and_announces_bits_as_binary_sensors() {
        use mbtap_core::profile::Table;
        let mkzp = mbtap_core::profile::builtin::get("mkzp").unwrap().unwrap();
        assert!(mkzp.meta.vendor.is_none(), "the test needs a profile without a vendor");
        let regs = mbtap_core::query::rows::rows(17, Table::HoldingRegisters, 50, &[123], Some(&mkzp));
        let (_, _, component, config) = discovery("mbtap/site", &regs[0], Some(&mkzp), "t");
        assert_eq!(component, "sensor");
        assert!(!config.to_string().contains("null"), "{config}");
        assert!(config["device"].get("manufacturer").is_none(), "{config}");
        let mk4 = mbtap_core::profile::builtin::get("mk4").unwrap().unwrap();
        let coil = mbtap_core::query::rows::rows(1, Table::Coils, 0, &[1], Some(&mk4));
        let (_, _, component, config) = discovery("mbtap/site", &coil[0], Some(&mk4), "t");
        assert_eq!(component, "binary_sensor");
        assert_eq!((config["payload_on"].as_str(), config["payload_off"].as_str()), (Some("1"), Some("0")));
        assert_eq!(config["value_template"], "{{ value_json.raw }}");
        assert!(config.get("unit_of_measurement").is_none());
        assert!(config["device"]["manufacturer"].is_string(), "the MK4 has a vendor: {config}");
    }

    /// Issue 24: `$SYS/x`, a tab or 70 kB were accepted and every message silently dropped.
    #[test]
    fn a_prefix_the_broker_would_drop_is_refused() {
        assert!(check_prefix("mbtap/site/line1").is_ok());
        for (bad, why) in [
            ("$SYS/x", "broker"),
            ("a\tb", "U+0009"),
            ("", "empty"),
            ("a/+/b", "wildcards"),
            ("a/#", "wildcards"),
            ("a\u{0}b", "U+0000"),
        ] {
            let e = check_prefix(bad).unwrap_err();
            assert!(e.contains(why), "{bad:?}: {e}");
        }
        assert!(check_prefix(&"x".repeat(70_000)).unwrap_err().contains("65 535"));
    }

    #[test]
    fn broker_urls_and_topic_levels() {
        assert_eq!(parse_url("mqtt://127.0.0.1:1884").unwrap(), (false, "127.0.0.1".into(), 1884));
        assert_eq!(parse_url("mqtts://broker").unwrap(), (true, "broker".into(), 8883));
        assert!(parse_url("http://x").is_err());
        assert!(parse_url("mqtt://user:pw@host:1883").is_err(), "credentials never on the command line");
        assert_eq!(topic_level("ttyUSB0"), "ttyUSB0");
        assert_eq!(topic_level("a/b+c#"), "a_b_c_");
    }

    /// Issue 30: with writes on, writable registers become Home Assistant controls — a rw coil a
    /// switch, a ranged set point a number within its scaled range — and the rest stay sensors.
    #[test]
    fn writable_registers_are_announced_as_controls() {
        use mbtap_core::profile::Table;
        let mk4 = mbtap_core::profile::builtin::get("mk4").unwrap().unwrap();
        let row = |table, address, raw: u16| {
            mbtap_core::query::rows::rows(1, table, address, &[raw], Some(&mk4)).into_iter().next().unwrap()
        };
        let announce = |r: &Row| {
            let (_, _, _, config) = discovery("p", r, Some(&mk4), "p/unit/1/x");
            control(r, Some(&mk4), "p/unit/1/x", config)
        };
        let (component, config) = announce(&row(Table::Coils, 0, 1)).unwrap();
        assert_eq!(component, "switch");
        assert_eq!(config["command_topic"], "p/unit/1/x/set");
        assert!(announce(&row(Table::Coils, 3, 1)).is_none(), "coil 3 is documented read-only");
        let (component, config) = announce(&row(Table::HoldingRegisters, 105, 250)).unwrap();
        assert_eq!(component, "number");
        assert_eq!(
            (config["min"].as_f64(), config["max"].as_f64(), config["step"].as_f64()),
            (Some(0.0), Some(100.0), Some(0.01))
        );
        let (component, config) = announce(&row(Table::HoldingRegisters, 101, 0)).unwrap();
        assert_eq!(component, "select", "an enumeration is a choice");
        assert_eq!(config["options"][1], "fill by level sensors");
        assert!(announce(&row(Table::InputRegisters, 430, 2305)).is_none(), "input registers are read-only");
    }
}
