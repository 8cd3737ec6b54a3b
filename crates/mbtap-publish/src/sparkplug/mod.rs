//! Sparkplug B 3.0 (Eclipse Sparkplug Specification v3.0.0): the protobuf payload
//! ([`payload`]) and the edge node's state machine ([`node`]). Pure: the MQTT client, the
//! clock and the on-disk buffer are the binary's.

pub mod node;
pub mod payload;

pub use node::{EdgeNode, Emit, Held, Out, Sample};
pub use payload::{DataType, Metric, Payload, Value};

/// The primary host's STATE topic (Sparkplug 3.0 §6.4.x, `spBv1.0/STATE/HOST_ID`).
#[must_use]
pub fn state_topic(host: &str) -> String {
    format!("{}/STATE/{}", node::NAMESPACE, node::level(host))
}

/// Whether a STATE payload says the host is online: Sparkplug 3.0's JSON
/// (`{"online": true, "timestamp": …}`) or 2.2's `ONLINE`/`OFFLINE` text. `None`: unreadable.
#[must_use]
pub fn host_online(payload: &[u8]) -> Option<bool> {
    let text = std::str::from_utf8(payload).ok()?.trim();
    match text {
        "ONLINE" => return Some(true),
        "OFFLINE" => return Some(false),
        _ => {}
    }
    serde_json::from_str::<serde_json::Value>(text).ok()?.get("online")?.as_bool()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_state_in_both_spellings() {
        assert_eq!(state_topic("scada/1"), "spBv1.0/STATE/scada_1");
        assert_eq!(host_online(br#"{"online": true, "timestamp": 1}"#), Some(true));
        assert_eq!(host_online(br#"{"online":false,"timestamp":1}"#), Some(false));
        assert_eq!(host_online(b"ONLINE"), Some(true));
        assert_eq!(host_online(b"OFFLINE"), Some(false));
        assert_eq!(host_online(b"maybe"), None);
        assert_eq!(host_online(b"{\"online\": 1}"), None);
    }
}
