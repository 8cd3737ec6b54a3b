//! Writes from the broker through the bridge (`bridge --mqtt-writes`): each write the broker asks
//! for is checked by the profile as `mbtap write` checks it (name, scale, documented range,
//! access), then by the bridge's own admission policy — read-only, `--allow-function`, routes and,
//! with `--mqtt-role`, that role's rules — exactly as a Modbus TCP client's request would be, and
//! only then queued on its line like any client's, under the same `--rate-limit` a connection
//! gets and the same queue bound. A refusal never reaches the line; it is counted with the
//! bridge's refusals and published back. Each write waits for its own answer (the line answers
//! every request it takes: the device's reply, 0x0B at its timeout, 0x0A without a port), one at
//! a time: no answer can reach another write.

use std::sync::{Arc, Mutex, PoisonError};

use tokio::sync::oneshot;
use tokio::time::Instant;

use super::request::{Routes, ServerOptions};
use super::shared::Job;
use crate::publish::mqtt::Mqtt;
use mbtap_device::profile::Profiles;
use mbtap_device::query::encode::encode_write;
use mbtap_device::query::resolve;
use mbtap_gateway::admit::{Asked, Role, RoleRules};
use mbtap_gateway::queue::ClientId;
use mbtap_gateway::transaction::Reply;
use mbtap_publish::remote::{Ask, Outcome};

/// The queue's client id of the broker's writes: a client of its own, taking its turn.
const BROKER_CLIENT: ClientId = ClientId::MAX - 1;

/// What the bridge needs to carry out the broker's writes.
pub struct BrokerWrites {
    /// The asks, taken once by the bridge when it starts.
    pub asks: Mutex<Option<std::sync::mpsc::Receiver<Ask>>>,
    pub publisher: Arc<Mqtt>,
    pub profiles: Profiles,
    /// `--mqtt-role`: the role whose rules also judge the broker's writes.
    pub role: Option<RoleRules>,
}

impl std::fmt::Debug for BrokerWrites {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BrokerWrites").field("role", &self.role).finish_non_exhaustive()
    }
}

/// Starts carrying out the broker's writes on `routes`, on a thread of its own (the asks arrive
/// on a blocking channel), for as long as the bridge runs.
pub fn start(writes: &Arc<BrokerWrites>, routes: Arc<Routes>, opts: Arc<ServerOptions>) {
    let Some(asks) = writes.asks.lock().unwrap_or_else(PoisonError::into_inner).take() else { return };
    let writes = Arc::clone(writes);
    let handle = tokio::runtime::Handle::current();
    let _ = std::thread::Builder::new().name("broker-writes".into()).spawn(move || {
        // The broker is one client: `--rate-limit` holds for it as for a connection.
        let now = || routes.first().map_or(std::time::Duration::ZERO, |r| r.line.now());
        let mut bucket = opts.rate_limit.map(|rate| mbtap_gateway::admit::RateLimit::new(rate, now()));
        for ask in asks {
            if crate::signals::stop_requested() {
                // Stopping: what still waits is not carried out (the bound keeps it short).
                break;
            }
            let outcome = handle.block_on(apply(&ask, &writes, &routes, &opts, bucket.as_mut()));
            writes.publisher.write_result(&ask, &outcome, crate::source::serial::now().0);
        }
    });
}

/// One write: the profile's checks, the bridge's admission, the line.
async fn apply(
    ask: &Ask,
    writes: &BrokerWrites,
    routes: &Routes,
    opts: &ServerOptions,
    bucket: Option<&mut mbtap_gateway::admit::RateLimit>,
) -> Outcome {
    let text = &ask.item.text;
    let profile = writes.profiles.get(&ask.unit);
    let target = resolve::resolve(&ask.item, profile).map_err(|e| e.to_string())?;
    let w = encode_write(&target, profile, false).map_err(|e| e.to_string())?;
    let pdu = w.pdu();
    let role = Role::Broker(writes.role.as_ref());
    let first = routes.first().ok_or_else(|| format!("{text}: the bridge has no serial line"))?;
    let asked = Asked { unit: ask.unit, pdu: &pdu, role, peer_high: false };
    let admitted = opts.policy.admit(asked, bucket, first.line.now()).map_err(|why| {
        routes.server.refused(why.reason());
        format!("{text}: refused by the bridge ({}, exception {})", why.reason(), why.exception())
    })?;
    let route = routes.get(admitted.route).ok_or_else(|| format!("{text}: no line serves unit {}", ask.unit))?;
    let (tx, rx) = oneshot::channel();
    let write = route.line.write_pending(admitted.target, &pdu);
    let job = Job { unit: admitted.target, pdu, reply: tx, queued: Instant::now(), high: false, write };
    route.line.submit(BROKER_CLIENT, job).map_err(|_| format!("{text}: the line's queue is full"))?;
    match rx.await {
        Ok(Reply::Pdu(answer)) if answer.first().is_some_and(|f| f & mbtap_proto::EXCEPTION_FLAG == 0) => Ok(None),
        Ok(Reply::Pdu(answer)) => Err(format!(
            "{text}: the device answered exception {}",
            mbtap_proto::ExceptionCode::from(answer.get(1).copied().unwrap_or(0))
        )),
        Ok(Reply::Gateway(code)) => Err(format!("{text}: the bridge answered exception {code}")),
        Ok(Reply::Silence) => Ok(None),
        Err(_) => Err(format!("{text}: no answer from the line")),
    }
}

/// The broker's writes as the bridge's server takes them.
pub type Writes = Arc<BrokerWrites>;

/// Starts the bridge's MQTT publisher (`--mqtt`) and, with `--mqtt-writes`, the broker's writes:
/// they go through the bridge's admission like a client's, judged by `--mqtt-role`'s rules
/// where `roles` are given.
///
/// # Errors
/// Roles without `--mqtt-role` under `--mqtt-writes` (fails closed), a role no `--role` defines,
/// a publisher that cannot start.
pub fn start_publisher(
    mqtt: &crate::publish::mqtt_options::MqttArgs,
    mqtt_role: Option<&str>,
    source: &str,
    profiles: &Profiles,
    roles: &super::tls::Roles,
) -> anyhow::Result<(Option<Arc<Mqtt>>, Option<Writes>)> {
    use anyhow::Context as _;
    // Fails closed (issue 38): with roles, the broker's writes must be given one too — otherwise
    // anyone on the broker would pass under the plain listeners' rules.
    anyhow::ensure!(
        !mqtt.mqtt_writes || roles.is_empty() || mqtt_role.is_some(),
        "--mqtt-writes with --role rules needs --mqtt-role NAME: the role whose rules judge the broker's writes (e.g. --role ops=functions:6,16 --mqtt-role ops); without one, anyone who can publish on the broker would write under the plain listeners' rules"
    );
    // The broker's writes (`--mqtt-writes`) go through the bridge's admission like a client's.
    let (asks_tx, asks) = std::sync::mpsc::sync_channel(crate::publish::outbox::COMMANDS_WAITING);
    let writer = Some(asks_tx);
    let publisher = Mqtt::start_with(mqtt, source, profiles.clone(), true, writer)?;
    let mut writes = None;
    if let Some(p) = publisher.as_ref().filter(|_| mqtt.mqtt_writes) {
        let role = match mqtt_role {
            None => None,
            Some(name) => Some(
                roles
                    .get(name)
                    .cloned()
                    .with_context(|| format!("--mqtt-role {name:?}: no --role {name}=… defines it"))?,
            ),
        };
        writes = Some(Arc::new(BrokerWrites {
            asks: Mutex::new(Some(asks)),
            publisher: Arc::clone(p),
            profiles: profiles.clone(),
            role,
        }));
    }
    Ok((publisher, writes))
}
