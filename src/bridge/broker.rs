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

use super::request::{Admission, Client, Routes, ServerOptions, admit};
use crate::publish::mqtt::Mqtt;
use mbtap_device::profile::Profiles;
use mbtap_device::query::encode::encode_write;
use mbtap_device::query::resolve;
use mbtap_gateway::admit::{Role, RoleRules};
use mbtap_gateway::clients::BROKER;
use mbtap_gateway::transaction::Reply;
use mbtap_publish::remote::{Ask, WriteResult};

/// What the bridge needs to carry out the broker's writes.
pub struct BrokerWrites {
    /// The asks, taken once by the bridge when it starts.
    pub asks: Mutex<Option<std::sync::mpsc::Receiver<Ask>>>,
    pub publisher: Arc<Mqtt>,
    pub profiles: Profiles,
    /// `--mqtt-role`: the role whose rules also judge the broker's writes.
    pub role: Option<RoleRules>,
    /// That role's name, for the audit.
    pub role_name: Option<String>,
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
        let mut client = Client::local(BROKER, Role::Broker(writes.role.as_ref()), &routes, &opts)
            .known_as("mqtt", writes.role_name.clone());
        for ask in asks {
            if crate::io::signals::stop_requested() {
                // Stopping: what still waits is not carried out (the bound keeps it short).
                break;
            }
            let outcome = handle.block_on(apply(&ask, &writes, &routes, &opts, &mut client));
            writes.publisher.write_result(&ask, &outcome, crate::io::serial::now().0);
        }
    });
}

/// One write: the profile's checks, then the one path every request takes ([`admit`]).
async fn apply(
    ask: &Ask,
    writes: &BrokerWrites,
    routes: &Routes,
    opts: &ServerOptions,
    client: &mut Client<'_>,
) -> WriteResult {
    let text = &ask.item.text;
    let profile = writes.profiles.get(&ask.unit);
    let target = resolve::resolve(&ask.item, profile).map_err(|e| e.to_string())?;
    let w = encode_write(&target, profile, false).map_err(|e| e.to_string())?;
    let reply = match admit(client, ask.unit, w.pdu(), routes, opts) {
        Admission::Refused(why) => {
            return Err(format!("{text}: refused by the bridge ({}, exception {})", why.reason(), why.exception()));
        }
        Admission::Now(reply) => Ok(reply),
        Admission::Later(rx) => rx.await,
    };
    match reply {
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
    // Fails closed: with roles, the broker's writes must be given one too — otherwise
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
            role_name: mqtt_role.map(str::to_owned),
        }));
    }
    Ok((publisher, writes))
}
