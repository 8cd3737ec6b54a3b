//! The `--mqtt` options shared by every command that publishes, and what reads them: the
//! broker's URL, the credentials (never from the command line), the topic prefix's rules, sizes
//! and intervals, and where the store-and-forward buffer goes by default.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context as _;
use clap::Args;

/// `--mqtt` options (on `sniff`, `tap`, `replay`, `watch` and `bridge --monitor`).
#[derive(Debug, Clone, Args)]
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
    /// Retain value messages (the status and discovery messages always are, and with
    /// --mqtt-discovery the values too: Home Assistant starting later gets the current ones).
    #[arg(long)]
    pub mqtt_retain: bool,
    /// A value that changes is published at most this often (bus time): `1s`, `250ms`, `0`.
    #[arg(long, default_value = "1s", value_parser = parse_interval, value_name = "INTERVAL")]
    pub mqtt_interval: Duration,
    /// Announce a sensor per register heard that the profile names.
    #[arg(long, value_enum, value_name = "KIND")]
    pub mqtt_discovery: Option<Discovery>,
    /// At the end, take back what was announced: an empty retained message on every discovery
    /// config this run published, so Home Assistant removes the entities (`demo` does this by
    /// default; without it the entities stay, `unavailable`, until removed).
    #[arg(long)]
    pub mqtt_forget: bool,
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
    mbtap_analysis::duration::parse_duration(s, Duration::ZERO, Duration::from_hours(24))
}

impl MqttArgs {
    /// The options as the command line's defaults make them, with `extra` given (`--mqtt URL`,
    /// …): for a publisher a command starts itself (`simulate --values-from`). The defaults are
    /// clap's, written once on the fields above (a derived `Default` would hold a queue of 0
    /// messages and an interval of 0 where the command line says 10 000 and 1 s).
    ///
    /// # Errors
    /// A value in `extra` the options refuse, as the command line would say it.
    pub fn with(extra: &[&str]) -> anyhow::Result<Self> {
        use clap::{Args as _, FromArgMatches as _};
        let command = Self::augment_args(clap::Command::new("mbtap").no_binary_name(true));
        let matches = command.try_get_matches_from(extra)?;
        Ok(Self::from_arg_matches(&matches)?)
    }
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
/// refused here (`$SYS/x`, a tab, 70 kB: every message dropped, "0 dropped" said).
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

/// This machine's name, for the default prefix.
pub(super) fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map_or_else(|| "host".into(), |h| topic_level(h.trim()))
}

/// `mqtt://host:port` → (tls, host, port).
pub(super) fn parse_url(url: &str) -> anyhow::Result<(bool, String, u16)> {
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

pub(super) fn credentials(args: &MqttArgs) -> anyhow::Result<Option<(String, String)>> {
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

/// The buffer directory when `--mqtt-buffer` is given without one.
pub(super) fn default_buffer_dir(prefix: &str) -> PathBuf {
    let state = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local").join("state")));
    state
        .unwrap_or_else(std::env::temp_dir)
        .join("mbtap")
        .join("mqtt-buffer")
        .join(topic_level(&prefix.replace('/', "_")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `$SYS/x`, a tab or 70 kB would have the broker drop every message silently: refused at
    /// the start.
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
}
