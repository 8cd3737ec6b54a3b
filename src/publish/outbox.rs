//! Where every MQTT message goes, shared by the analysing thread and the connection thread:
//! straight to the connection while the broker is there and nothing held waits; to the on-disk
//! buffer ([`super::spool`], `--mqtt-buffer`) while it is away or the held messages are being
//! forwarded (so the order holds); dropped and counted when neither can take it. The Sparkplug
//! edge node lives here too: the connection thread starts and ends its sessions (births, the
//! will's bdSeq) and carries out its commands.
//!
//! The connection's thread ([`super::connection`]) starts and ends sessions here: on each
//! connection the births (or the `online` status), then the held messages, oldest first, in
//! small batches so the connection keeps flowing.

use std::sync::{Mutex, PoisonError};
use std::time::{SystemTime, UNIX_EPOCH};

use mbtap_device::profile::Profiles;
use mbtap_publish::remote::Ask;
use mbtap_publish::sparkplug::{EdgeNode, Emit, Out};
use mbtap_publish::spool::{Kind, mqtt_body};
use rumqttc::{AsyncClient, LastWill, QoS};

use super::spool::{Record, Spool};

mod session;

/// Writes from the broker that may wait for the line at once (watch and the bridge): a bound,
/// so a flood of commands costs at most this many line writes.
pub const COMMANDS_WAITING: usize = 32;

/// The largest packet taken from the broker. Larger than anything mbtap acts on
/// ([`MAX_COMMAND`]), so an oversized message on a command topic is read and
/// dropped without losing the connection — MQTT 3.1.1 has no other way to refuse one, and a
/// retained one would come again at every subscription. Past this, the connection
/// is lost with it and the command topics are paused instead (`Outbox::oversized_message`).
pub const MAX_INCOMING: usize = 32 << 20;

/// The largest command payload acted on (a set's value, a DCMD's metrics, a host's STATE):
/// larger ones are dropped, counted in [`Commands::oversized`] and said once.
pub const MAX_COMMAND: usize = 64 << 10;

/// What the outbox keeps about the broker's commands.
#[derive(Debug, Default)]
pub struct Commands {
    /// Command topics not subscribed until then: a message over the packet limit came on one
    /// (a retained one comes again at every subscription, and MQTT 3.1.1 has no way to refuse
    /// it but to drop the connection), and how long the next pause lasts.
    paused: Option<(std::time::Instant, std::time::Duration)>,
    /// The command topics are subscribed in this connection.
    subscribed: bool,
    /// A retained command was said (once per run).
    said_retained: bool,
    /// A drop streak was said (cleared when a write is queued again).
    said_busy: bool,
    /// Writes dropped because [`COMMANDS_WAITING`] already waited, since start.
    pub busy_writes: u64,
    /// Messages over the packet limit the broker sent, since start.
    pub oversized: u64,
}

/// Held records forwarded per turn before the connection gets to send them.
const FORWARD_BATCH: usize = 64;

/// Milliseconds since the epoch, for Sparkplug payload timestamps.
pub fn now_ms() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
}

pub fn qos(n: u8) -> QoS {
    match n {
        0 => QoS::AtMostOnce,
        1 => QoS::AtLeastOnce,
        _ => QoS::ExactlyOnce,
    }
}

/// The shared outbox.
pub struct Outbox {
    pub client: AsyncClient,
    /// Connected, and nothing held waits: messages go straight out.
    live: bool,
    connected: bool,
    pub spool: Option<Spool>,
    pub node: Option<EdgeNode>,
    /// The status topic of plain MQTT (`PREFIX/status`), `online` on each connection.
    pub status: Option<String>,
    /// A held segment being forwarded: its number and the records left.
    forwarding: Option<(u64, std::collections::VecDeque<Record>)>,
    pub published: u64,
    pub dropped: u64,
    pub held: u64,
    pub forwarded: u64,
    /// Since when held messages are being forwarded, and how many were forwarded before.
    forward_start: Option<(std::time::Instant, u64)>,
    /// `--mqtt-writes`: where writes asked for go (the master that carries them out).
    pub writes: Option<std::sync::mpsc::SyncSender<Ask>>,
    /// The plain topic prefix (`…/unit/U/…/set` topics are under it).
    pub prefix: String,
    /// Profiles by unit, to find a DCMD metric's register.
    pub profiles: Profiles,
    /// Writes refused (off, unreadable, refused by the profile or the device).
    pub refused_writes: u64,
    /// `--sparkplug-host`: the primary host's STATE topic, and whether it said it is online
    /// (until it does, nothing is born or published live: Sparkplug 3.0 edge nodes wait for their
    /// primary host).
    pub host: Option<(String, bool)>,
    /// With Home Assistant discovery: its birth topic (`homeassistant/status`), subscribed at
    /// each connection; an `online` there asks for discovery and the current states again.
    pub ha_status: Option<String>,
    /// Home Assistant said `online` since the last [`Outbox::take_ha_birth`].
    pub(super) ha_birth: bool,
    /// A retained command was ignored and said so (said once a session).
    /// The broker's commands: subscriptions and what became of floods.
    pub commands: Commands,
    /// Sparkplug updates held in memory when there is no disk buffer (at most `memory_cap`,
    /// the oldest dropped and counted): forwarded as historical data like the disk's.
    pub(super) memory: std::collections::VecDeque<Vec<u8>>,
    pub memory_cap: usize,
}

impl std::fmt::Debug for Outbox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Outbox")
            .field("live", &self.live)
            .field("connected", &self.connected)
            .field("spool", &self.spool)
            .field("node", &self.node)
            .field("published", &self.published)
            .field("dropped", &self.dropped)
            .field("held", &self.held)
            .finish_non_exhaustive()
    }
}

impl Outbox {
    pub fn new(client: AsyncClient, spool: Option<Spool>, node: Option<EdgeNode>, status: Option<String>) -> Self {
        Self {
            client,
            live: false,
            connected: false,
            spool,
            node,
            status,
            forwarding: None,
            published: 0,
            dropped: 0,
            held: 0,
            forwarded: 0,
            forward_start: None,
            writes: None,
            prefix: String::new(),
            profiles: Profiles::new(),
            refused_writes: 0,
            host: None,
            ha_status: None,
            ha_birth: false,
            commands: Commands::default(),
            memory: std::collections::VecDeque::new(),
            memory_cap: 10_000,
        }
    }

    pub fn publish_now(&mut self, topic: &str, qos: QoS, retain: bool, payload: Vec<u8>) -> bool {
        let ok = self.client.try_publish(topic, qos, retain, payload).is_ok();
        if ok {
            self.published += 1;
        } else {
            self.dropped += 1;
        }
        ok
    }

    /// One plain message: out now, held, or (no buffer) queued for rumqttc.
    pub fn send(&mut self, topic: &str, qos: QoS, retain: bool, payload: Vec<u8>) {
        if self.live || self.spool.is_none() {
            self.publish_now(topic, qos, retain, payload);
            return;
        }
        let held = mqtt_body(topic, qos as u8, retain, &payload)
            .and_then(|body| self.spool.as_mut().map(|s| s.append(Kind::Mqtt, &body)));
        match held {
            Some(Ok(())) => self.held += 1,
            _ => self.dropped += 1,
        }
    }

    /// What the edge node said: messages out at once (their seq is counted now), updates held.
    pub fn emit(&mut self, e: Emit) {
        match e {
            Emit::Send(outs) => self.send_outs(outs),
            Emit::Hold(body) => match self.spool.as_mut().map(|s| s.append(Kind::Sparkplug, &body)) {
                Some(Ok(())) => self.held += 1,
                Some(Err(_)) => self.dropped += 1,
                None => {
                    if self.memory.len() >= self.memory_cap.max(1) {
                        self.memory.pop_front();
                        self.dropped += 1;
                    }
                    self.memory.push_back(body);
                    self.held += 1;
                }
            },
        }
    }

    pub fn send_outs(&mut self, outs: Vec<Out>) {
        for o in outs {
            self.publish_now(&o.topic, qos(o.qos), o.retain, o.payload);
        }
    }

    /// Whether held messages wait (forwarding or on disk).
    pub(super) fn holding(&self) -> bool {
        self.forwarding.is_some() || !self.memory.is_empty() || self.spool.as_ref().is_some_and(|s| !s.is_empty())
    }

    /// The connection is up: births or status first, then forwarding if anything is held.
    pub(super) fn connected(&mut self) {
        self.connected = true;
        self.forwarding = None;
        if let Some((topic, _)) = &self.host {
            let _ = self.client.try_subscribe(topic.clone(), QoS::AtLeastOnce);
        }
        if let Some(topic) = &self.ha_status {
            let _ = self.client.try_subscribe(topic.clone(), QoS::AtLeastOnce);
        }
        self.commands.subscribed = false;
        self.subscribe_commands();
        if let Some(status) = self.status.clone() {
            // Retained, so a late subscriber sees it; replaces the will.
            self.publish_now(&status, QoS::AtLeastOnce, true, b"online".to_vec());
        }
        if self.host_hears() {
            self.born();
        }
    }

    /// Whether Home Assistant announced itself (`online` on its birth topic) since last asked.
    pub fn take_ha_birth(&mut self) -> bool {
        std::mem::take(&mut self.ha_birth)
    }

    /// Subscribes to the command topics, unless a pause after an oversized message still runs.
    /// Called at every connection and, while connected, as time passes (the pause ends).
    pub(super) fn subscribe_commands(&mut self) {
        if self.commands.subscribed || !self.connected {
            return;
        }
        if self.commands.paused.is_some_and(|(until, _)| std::time::Instant::now() < until) {
            return;
        }
        let mut topics = Vec::new();
        if let Some(node) = self.node.as_ref() {
            topics.extend(node.command_topics());
        }
        if self.writes.is_some() && self.node.is_none() {
            topics.extend([format!("{}/unit/+/set", self.prefix), format!("{}/unit/+/+/+/set", self.prefix)]);
        }
        for t in topics {
            let _ = self.client.try_subscribe(t, QoS::AtLeastOnce);
        }
        self.commands.subscribed = true;
    }

    /// The broker sent a message of `bytes` over the packet limit (the connection is lost with
    /// it): commands are not subscribed for a while — 1 min, doubling to 30 min while it comes
    /// again — so publishing goes on with one reconnection per pause, not one a second.
    pub(super) fn oversized_message(&mut self, bytes: usize, limit: usize) {
        const FIRST: std::time::Duration = std::time::Duration::from_mins(1);
        const LONGEST: std::time::Duration = std::time::Duration::from_mins(30);
        self.commands.oversized += 1;
        let pause = self.commands.paused.map_or(FIRST, |(_, p)| (p * 2).min(LONGEST));
        self.commands.paused = Some((std::time::Instant::now() + pause, pause));
        eprintln!(
            "mbtap: mqtt: the broker sent a message of {bytes} bytes, over the {limit} taken (a retained command?): commands not taken for {} s, publishing goes on; clear it on the broker (an empty retained message on its topic)",
            pause.as_secs()
        );
    }

    /// A write asked for: to the master, or refused.
    fn ask(&mut self, ask: Result<Ask, String>) {
        match (ask, &self.writes) {
            (Ok(ask), Some(tx)) => match tx.try_send(ask) {
                Ok(()) => self.commands.said_busy = false,
                // A flood of sets (any publisher of an anonymous broker) must not become hours of
                // line writes with the polling stopped: past the bound a write is dropped,
                // counted and said once per streak — no answer is published for each, so the
                // flood is not echoed back either.
                Err(std::sync::mpsc::TrySendError::Full(_)) => {
                    self.commands.busy_writes += 1;
                    if !self.commands.said_busy {
                        self.commands.said_busy = true;
                        eprintln!(
                            "mbtap: mqtt: {COMMANDS_WAITING} writes from the broker already wait for the line: further ones dropped (counted) until they are done"
                        );
                    }
                }
                Err(std::sync::mpsc::TrySendError::Disconnected(_)) => self.refuse(None, "the master has stopped"),
            },
            (Ok(ask), None) => {
                let why = format!("{}: writes from the broker are off (start with --mqtt-writes)", ask.item.text);
                self.refuse(Some(ask.unit), &why);
            }
            (Err(why), _) => self.refuse(None, &why),
        }
    }

    /// A write refused: counted, said, and (plain MQTT) published on `PREFIX/unit/U/write`.
    pub fn refuse(&mut self, unit: Option<u8>, why: &str) {
        self.refused_writes += 1;
        eprintln!("mbtap: mqtt: write refused: {why}");
        if self.node.is_none() {
            let topic = match unit {
                Some(u) => format!("{}/unit/{u}/write", self.prefix),
                None => format!("{}/write", self.prefix),
            };
            let body = serde_json::json!({"ok": false, "refused": why}).to_string();
            self.send(&topic, QoS::AtLeastOnce, false, body.into_bytes());
        }
    }

    /// The will of the next connection: the node's NDEATH (with the next bdSeq), or `offline`.
    pub(super) fn will(&self) -> Option<LastWill> {
        Self::will_of(self.node.as_ref(), self.status.as_deref())
    }

    /// The will for `node` (its NDEATH, QoS 1, not retained: Sparkplug 3.0 §7.2) or for the
    /// plain `status` topic (`offline`, retained).
    pub fn will_of(node: Option<&EdgeNode>, status: Option<&str>) -> Option<LastWill> {
        if let Some(node) = node {
            let w = node.will();
            return Some(LastWill::new(w.topic, w.payload, QoS::AtLeastOnce, false));
        }
        status.map(|s| LastWill::new(s, "offline", QoS::AtLeastOnce, true))
    }
}

/// Locks the outbox (a panicked holder leaves it usable: counters and queues stay consistent).
pub fn lock(outbox: &Mutex<Outbox>) -> std::sync::MutexGuard<'_, Outbox> {
    outbox.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What a forwarding turn left.
pub(super) enum Forward {
    /// Nothing held, or not connected.
    Idle,
    /// A batch went out; more wait.
    More,
    /// The connection's queue is full: wait for it to drain.
    Full,
}
