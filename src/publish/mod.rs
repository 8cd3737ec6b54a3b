//! What the sniffer hears, served to others while it listens: a read-only Modbus TCP server
//! answering from the register image ([`spy`], `--serve`) and MQTT ([`mqtt`], `--mqtt`). Both
//! are [`crate::output::Tap`]s fed by the analysing thread; neither ever writes to the serial
//! line, and neither can slow the analysis down.
//!
//! MQTT's pieces: [`mqtt_options`] (the options and their rules), [`discovery`] (Home Assistant
//! discovery), [`outbox`] (where every message goes), [`connection`] (the connection's thread),
//! [`spool`] (store and forward on disk), [`values_from`] (`simulate --values-from`); the spy
//! server's [`expiring`] connections.

pub mod connection;
pub mod discovery;
pub mod expiring;
pub mod mqtt;
pub mod mqtt_options;
pub mod outbox;
pub mod spool;
pub mod spy;
pub mod values_from;

use std::sync::Arc;
use std::time::Duration;

use clap::Args;

/// `--serve` and `--mqtt` options of `sniff`, `tap` and `replay`.
#[derive(Debug, Clone, Args)]
pub struct PublishArgs {
    /// Spy mode: serve the register image the sniffer builds as a read-only Modbus TCP server
    /// at this address (e.g. 127.0.0.1:5020). Reads are answered with the latest value heard;
    /// an address never heard → exception 02, a unit never heard or a value older than
    /// --max-age → 0B, anything else (writes included) → 01. Nothing is ever sent on the line.
    #[arg(long, value_name = "ADDRESS")]
    pub serve: Option<String>,
    /// With --serve: values older than this are answered with exception 0B (`30s`, `500ms`,
    /// `none` to serve any age).
    #[arg(long, default_value = "60s", value_parser = parse_age, value_name = "AGE")]
    pub max_age: MaxAge,
    #[command(flatten)]
    pub mqtt: mqtt::MqttArgs,
}

/// How old a served value may be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MaxAge(pub Option<Duration>);

impl Default for MaxAge {
    fn default() -> Self {
        Self(Some(Duration::from_mins(1)))
    }
}

/// An age (`30s`, `500ms`, …) or `none`.
fn parse_age(s: &str) -> Result<MaxAge, String> {
    if s.trim().eq_ignore_ascii_case("none") {
        return Ok(MaxAge(None));
    }
    mbtap_analysis::duration::parse_duration(s, Duration::ZERO, Duration::from_secs(1_000_000_000))
        .map(|d| MaxAge(Some(d)))
}

/// The publishers the options ask for, started; their taps go into the event writer.
#[derive(Debug, Default)]
pub struct Publishing {
    pub spy: Option<Arc<spy::Spy>>,
    pub mqtt: Option<Arc<mqtt::Mqtt>>,
}

impl Publishing {
    /// Starts what `args` asks for. `live`: the events come from a live line (the server
    /// ages values by the clock) rather than a capture (by the newest bus time heard);
    /// `source` names the line (the MQTT prefix's last level); `profiles` name the values.
    pub fn start(
        args: &PublishArgs,
        live: bool,
        source: &str,
        profiles: &mbtap_device::profile::Profiles,
    ) -> anyhow::Result<Self> {
        let spy = match &args.serve {
            Some(addr) => Some(spy::Spy::start(addr, args.max_age.0, live)?),
            None => None,
        };
        let mqtt = mqtt::Mqtt::start(&args.mqtt, source, profiles.clone(), true)?;
        Ok(Self { spy, mqtt })
    }

    /// The taps to feed.
    #[must_use]
    pub fn taps(&self) -> Vec<Arc<dyn crate::output::Tap>> {
        let mut out: Vec<Arc<dyn crate::output::Tap>> = Vec::new();
        if let Some(s) = &self.spy {
            out.push(Arc::clone(s) as Arc<dyn crate::output::Tap>);
        }
        if let Some(m) = &self.mqtt {
            out.push(Arc::clone(m) as Arc<dyn crate::output::Tap>);
        }
        out
    }

    /// The end of the input: say what each publisher did.
    pub fn finish(&self) {
        if let Some(s) = &self.spy {
            eprintln!("mbtap: {}", s.summary());
        }
        if let Some(m) = &self.mqtt {
            m.finish();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ages_in_the_units_people_write() {
        assert_eq!(parse_age("30s"), Ok(MaxAge(Some(Duration::from_secs(30)))));
        assert_eq!(parse_age("500ms"), Ok(MaxAge(Some(Duration::from_millis(500)))));
        assert_eq!(parse_age("none"), Ok(MaxAge(None)));
        assert!(parse_age("-1").is_err());
        assert!(parse_age("old").is_err());
    }
}
