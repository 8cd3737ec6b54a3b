//! `simulate --values-from URL`: values of emulated devices set from an MQTT broker, on the
//! topics and with the names and scales of `watch --mqtt-writes` (`PREFIX/unit/U/set` with
//! `NAME=VALUE`, or `PREFIX/unit/U/TABLE/ADDRESS/set` with the value) — a meter fed from
//! another meter's readings, a test setting the device's state. Each set is applied at once
//! (the next read sees it) and answered on `PREFIX/unit/U/write`, as `watch` answers.

use std::sync::{Arc, PoisonError};
use std::time::Duration;

use crate::source::simulate::emulated::Emulated;

/// Sets taken per pass, and how often the queue is looked at: a flood of sets is bounded by
/// the broker's own command queue ([`crate::publish::outbox::COMMANDS_WAITING`]), never by memory.
const PER_PASS: usize = 256;
const PASS: Duration = Duration::from_millis(20);

/// Connects to `url` (under `prefix`, or mbtap's default for "simulate") and applies every set
/// until the process ends.
///
/// # Errors
/// A bad URL or prefix (said before serving).
pub fn start(
    url: &str,
    prefix: Option<&str>,
    emulated: Arc<Emulated>,
    audit: Option<Arc<crate::output::audit::Audit>>,
) -> anyhow::Result<()> {
    let mut options = vec!["--mqtt", url, "--mqtt-writes"];
    if let Some(p) = prefix {
        options.extend(["--mqtt-prefix", p]);
    }
    let args = super::mqtt_options::MqttArgs::with(&options)?;
    let profiles = {
        let devices = emulated.devices.lock().unwrap_or_else(PoisonError::into_inner);
        devices
            .iter()
            .filter_map(|d| match d {
                mbtap_sim::Device::Profile(s) | mbtap_sim::Device::Mirror { slave: s, .. } => {
                    Some((s.address(), s.profile().clone()))
                }
                mbtap_sim::Device::Recorded(_) => None,
            })
            .collect()
    };
    let (tx, asks) = std::sync::mpsc::sync_channel(super::outbox::COMMANDS_WAITING);
    let Some(mqtt) = super::mqtt::Mqtt::start_with(&args, "simulate", profiles, false, Some(tx))? else {
        return Ok(());
    };
    tokio::spawn(async move {
        loop {
            tokio::time::sleep(PASS).await;
            for ask in asks.try_iter().take(PER_PASS) {
                let outcome = {
                    let mut devices = emulated.devices.lock().unwrap_or_else(PoisonError::into_inner);
                    match devices.iter_mut().find(|d| d.address() == ask.unit) {
                        Some(d) => mbtap_sim::device::set_value(d, &ask.item),
                        None => Err(format!("{}: no device at unit {} here", ask.item.text, ask.unit)),
                    }
                };
                if let Some(a) = &audit {
                    let who = crate::output::audit::Who { transport: "mqtt", address: None, role: None };
                    a.record_set(
                        &who,
                        ask.unit,
                        &ask.item.text,
                        outcome.as_ref().map_or_else(String::as_str, |_| "done"),
                    );
                }
                mqtt.write_result(&ask, &outcome, crate::io::serial::now().0);
            }
        }
    });
    Ok(())
}
