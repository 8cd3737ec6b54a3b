//! The connection's life as the outbox sees it: born (Sparkplug births, then what was held
//! forwarded in batches), gone (held from then on), and what the broker sends on a subscribed
//! topic — a node command, a device command or a plain set — taken as an ask or refused.

use super::{FORWARD_BATCH, Forward, MAX_COMMAND, Outbox, now_ms, qos};
use crate::publish::spool::Spool;
use mbtap_publish::remote::{parse_dcmd, parse_set};
use mbtap_publish::spool::{Kind, parse_mqtt_body};

impl Outbox {
    /// Whether a primary host can hear: none configured, or its STATE says online.
    pub(super) fn host_hears(&self) -> bool {
        self.host.as_ref().is_none_or(|(_, online)| *online)
    }

    /// Connected and heard: the node's births (Sparkplug), then forwarding whatever was held
    /// (live once it is all out).
    pub(super) fn born(&mut self) {
        if let Some(node) = self.node.as_mut() {
            let births = node.online(now_ms());
            self.send_outs(births);
        }
        self.live = !self.holding();
        if !self.live {
            self.forward_start = Some((std::time::Instant::now(), self.forwarded));
        }
    }

    /// The connection is gone: hold from now on; the node's next session has the next bdSeq.
    pub(in crate::publish) fn disconnected(&mut self) {
        self.connected = false;
        self.live = false;
        self.forwarding = None;
        if let Some(node) = self.node.as_mut() {
            node.offline();
        }
    }

    /// Forwards up to [`FORWARD_BATCH`] held records: whether more wait, and whether the
    /// connection's queue was full.
    pub(in crate::publish) fn forward_some(&mut self) -> Forward {
        if !self.connected || !self.host_hears() {
            return Forward::Idle;
        }
        for _ in 0..FORWARD_BATCH {
            if self.forwarding.is_none()
                && let Some(body) = self.memory.pop_front()
            {
                self.forwarded += 1;
                let outs = self.node.as_mut().map(|n| n.historical(&body, now_ms())).unwrap_or_default();
                self.send_outs(outs);
                continue;
            }
            if self.forwarding.is_none() {
                let Some((n, recs)) = self.spool.as_mut().and_then(Spool::oldest) else {
                    self.live = true;
                    if let Some((at, before)) = self.forward_start.take() {
                        let n = self.forwarded - before;
                        let secs = at.elapsed().as_secs_f64();
                        eprintln!(
                            "mbtap: mqtt: forwarded {n} held message(s) in {secs:.2} s ({:.0} per second); live again",
                            f64::from(u32::try_from(n).unwrap_or(u32::MAX)) / secs.max(1e-6)
                        );
                    }
                    return Forward::Idle;
                };
                self.forwarding = Some((n, recs.into()));
            }
            let Some((n, recs)) = self.forwarding.as_mut() else { return Forward::Idle };
            let n = *n;
            let Some((kind, body)) = recs.pop_front() else {
                self.forwarding = None;
                if let Some(s) = self.spool.as_mut() {
                    s.forwarded(n);
                }
                continue;
            };
            self.forwarded += 1;
            match kind {
                Kind::Mqtt => {
                    if let Some((topic, q, retain, payload)) = parse_mqtt_body(&body) {
                        if self.client.try_publish(topic, qos(q), retain, payload.to_vec()).is_err() {
                            // The connection's queue is full: this record again next turn.
                            self.forwarded -= 1;
                            if let Some((_, recs)) = self.forwarding.as_mut() {
                                recs.push_front((kind, body));
                            }
                            return Forward::Full;
                        }
                        self.published += 1;
                    }
                }
                Kind::Sparkplug => {
                    let outs = self.node.as_mut().map(|n| n.historical(&body, now_ms())).unwrap_or_default();
                    self.send_outs(outs);
                }
                // A newer mbtap's record: not ours to send.
                Kind::Other(_) => {}
            }
        }
        Forward::More
    }

    /// A message arrived: a command to the Sparkplug node (NCMD), a write to one of its devices
    /// (DCMD), or a plain `…/set`.
    /// A message from the broker on a subscribed topic; `retained`: the broker kept it from
    /// before this session.
    pub(in crate::publish) fn incoming(&mut self, topic: &str, payload: &[u8], retained: bool) {
        if payload.len() > MAX_COMMAND {
            self.commands.oversized += 1;
            if self.commands.oversized == 1 {
                eprintln!(
                    "mbtap: mqtt: a message of {} bytes on {topic} dropped: commands are at most {MAX_COMMAND} bytes (said once; counted)",
                    payload.len()
                );
            }
            return;
        }
        // Home Assistant's birth message (MQTT discovery: `homeassistant/status` `online`, sent
        // when it starts): it has forgotten what it was told, so everything is said again.
        if self.ha_status.as_deref() == Some(topic) {
            if payload.trim_ascii() == b"online" {
                self.ha_birth = true;
            }
            return;
        }
        if let Some((state, online)) = self.host.as_mut()
            && topic == state.as_str()
        {
            let now = mbtap_publish::sparkplug::host_online(payload);
            match (now, *online) {
                (Some(true), false) => {
                    *online = true;
                    eprintln!("mbtap: mqtt: the primary host is online: births, then what was held");
                    if self.connected {
                        self.born();
                    }
                }
                (Some(false), true) => {
                    *online = false;
                    self.live = false;
                    self.forwarding = None;
                    if let Some(node) = self.node.as_mut() {
                        node.pause();
                    }
                    eprintln!("mbtap: mqtt: the primary host is offline: holding what is measured until it is back");
                }
                _ => {}
            }
            return;
        }
        if retained {
            // A command is an act of now: a retained one would be carried out again at every
            // start and reconnect by whoever once left it (Sparkplug B 3.0 §6.4.13:
            // NCMD/DCMD are published with retain false). Ignored, said once.
            if !self.commands.said_retained {
                self.commands.said_retained = true;
                eprintln!(
                    "mbtap: mqtt: a retained command on {topic} ignored (commands are carried out only when sent, never from what the broker kept); clear it with an empty retained message"
                );
            }
            return;
        }
        if let Some(node) = self.node.as_mut() {
            if let Some(device) = node.dcmd_device(topic) {
                for ask in parse_dcmd(device, payload, &self.profiles) {
                    self.ask(ask);
                }
                return;
            }
            let outs = node.command(topic, payload, now_ms());
            self.send_outs(outs);
            return;
        }
        if let Some(ask) = parse_set(&self.prefix, topic, payload) {
            self.ask(ask);
        }
    }
}
