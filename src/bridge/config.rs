//! `mbtap bridge --config FILE`: the bridge's settings in a TOML file, with the same names as
//! the command-line options (`listen = "0.0.0.0:502"`, `read-only = true`, `route = [...]`).
//! The bridge command puts its command line over the file (`cmd::bridge`). `mbtap
//! generate-config` prints a commented sample ([`SAMPLE`]).

/// A commented sample configuration: every setting, with its default or an example.
pub const SAMPLE: &str = r#"# mbtap bridge configuration. Run: mbtap bridge --config /etc/mbtap/bridge.toml
# Every setting has the name of its command-line option; options given on the command line win.

[bridge]
# The serial line (all units not routed elsewhere) and its settings (Serial Line v1.02 default 19200 8E1).
serial = "/dev/ttyUSB0"
baud = 19200
parity = "even"          # none | even | odd
stop-bits = 1
mode = "rtu"             # rtu | ascii

# More lines, routed by unit:
# route = ["11-20=/dev/ttyUSB1"]

# Where Modbus TCP clients connect (502 needs root or CAP_NET_BIND_SERVICE), and raw RTU over TCP.
listen = "0.0.0.0:502"
# listen-rtu = "0.0.0.0:5020"
# A serial port on which the bridge answers as the slave, for a master already on the line:
# listen-serial = "/dev/ttyUSB1"

# Per request: response timeout (ms), retries after a timeout or a bad CRC, extra quiet time
# after t3.5 before the next request (ms).
timeout-ms = 800
retries = 0
turnaround-ms = 0.0
# A pause of a unit's own before each request to it, beyond t3.5 (ms): a slow device's.
# unit-gap = ["1=40"]     # or ["20"] for every unit
# allow-broadcast = true  # let writes to unit 0 through to every device (refused otherwise)
# broadcast-reply = true  # answer broadcast writes at once, for SCADA that insists

# Safety. The sample starts closed to writes: every client on the network may read, none may
# write (exception 01, counted). To let your SCADA write, name its addresses in allow-ip and set
# read-only = false.
read-only = true
# allow-function = ["3", "4"]
# allow-ip = ["10.0.0.0/24", "127.0.0.1"]
max-connections = 64
idle-timeout = "300s"    # 250ms, 90s, 5min, 1h
# rate-limit = 50.0      # requests per second per connection
queue-per-client = 32
# map-unit = ["10=1"]    # TCP unit id = serial address

# Observability.
# metrics = "127.0.0.1:9502"
# web = "127.0.0.1:8502"  # a live read-only page; another address needs web-allow-ip
# web-allow-ip = ["10.0.0.0/24"]
# audit = "/var/log/mbtap/audit.jsonl"   # every write, who and how it ended (JSON lines)
# audit-max-bytes = 16777216
# monitor = "jsonl"      # text | jsonl | tui
# device = ["1=mk4", "5=display", "17=mkzp"]
# Modbus/TCP Security: TLS with client certificates; the role in a client's certificate
# (extension 1.3.6.1.4.1.50316.802.1) says what it may do.
# listen-tls = "0.0.0.0:802"
# cert = "/etc/mbtap/bridge.pem"
# key = "/etc/mbtap/bridge.key"
# client-ca = "/etc/mbtap/clients-ca.pem"
# [roles.operator]
# functions = [3, 4, 6, 16]
# units = ["1-20"]
# [roles.viewer]
# read-only = true

# mqtt = "mqtt://127.0.0.1:1883"   # publish what the monitor hears (needs monitor)
# mqtt-prefix = "mbtap/site/line"
"#;

/// The `[bridge]` table as command-line options.
///
/// # Errors
/// A TOML error (with its line), an unknown setting (with the known ones), or a value of a
/// type no option takes.
pub fn options(text: &str, known: &[String]) -> Result<Vec<String>, String> {
    let doc: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
    let roles = doc.get("roles").cloned();
    let table = match doc.get("bridge") {
        Some(toml::Value::Table(t)) => {
            // The file defines `[bridge]` and `[roles.NAME]` only, and anything else stops the
            // start: a key above `[bridge]` (`read-only = true` at the top of the file) would
            // otherwise look set and do nothing.
            let mut outside: Vec<(usize, &String)> = doc
                .keys()
                .filter(|k| !matches!(k.as_str(), "bridge" | "roles"))
                .map(|k| (line_of(text, k), k))
                .collect();
            outside.sort();
            if !outside.is_empty() {
                let named: Vec<String> = outside.iter().map(|(l, k)| format!("line {l}: {k:?}")).collect();
                return Err(format!(
                    "{} outside [bridge]; this file defines [bridge] and [roles.NAME] only — move the settings under [bridge]",
                    named.join(", ")
                ));
            }
            t.clone()
        }
        Some(_) => return Err("[bridge] must be a table".into()),
        None => doc,
    };
    let mut out = Vec::new();
    // `[roles.NAME]` tables (MODBUS/TCP Security roles) become `--role NAME=RULES`.
    if let Some(roles) = &roles {
        out.extend(role_options(roles)?);
    }
    for (key, value) in &table {
        if key == "roles" {
            continue;
        }
        let long = key.replace('_', "-");
        if !known.contains(&long) {
            return Err(format!("unknown setting {key:?} in [bridge]; known: {}", known.join(", ")));
        }
        let flag = format!("--{long}");
        let scalar = |v: &toml::Value| match v {
            toml::Value::String(s) => Ok(s.clone()),
            toml::Value::Integer(i) => Ok(i.to_string()),
            toml::Value::Float(f) => Ok(f.to_string()),
            other => Err(format!("{key} = {other}: expected a string or a number")),
        };
        match value {
            toml::Value::Boolean(true) => out.push(flag),
            toml::Value::Boolean(false) => {}
            // `--key=value` in one token: a value such as `-5` stays a value, and clap's
            // refusal then names the key and the value.
            // An empty allow-list would let everyone in (the lists restrict only when given):
            // refuse it rather than fail open.
            // One rule for every list (`tls-allow-ip = []` and `crl = []` passed
            // silently): an empty list is refused, naming the key and its line.
            toml::Value::Array(items) if items.is_empty() => {
                let what = if matches!(long.as_str(), "allow-ip" | "allow-function" | "tls-allow-ip") {
                    "an empty allow-list would let every client (or function) through"
                } else {
                    "an empty list says nothing and may hide a setting that was meant to be there"
                };
                return Err(format!(
                    "line {}: {key} = []: {what}; list what is meant, or remove the key",
                    line_of(text, key)
                ));
            }
            toml::Value::Array(items) => {
                for item in items {
                    out.push(format!("{flag}={}", scalar(item)?));
                }
            }
            v => out.push(format!("{flag}={}", scalar(v)?)),
        }
    }
    Ok(out)
}

/// The 1-based line where `key` is set or opens a table (`key =`, `"key" =`, `[key]`,
/// `[key.…]`), for error messages; 0 when not found.
fn line_of(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| {
            let l = l.trim_start();
            let rest = l.strip_prefix('[').map_or(l, str::trim_start);
            let rest = rest.strip_prefix('"').unwrap_or(rest);
            rest.strip_prefix(key).is_some_and(|r| {
                let r = r.trim_start_matches('"').trim_start();
                r.starts_with('=') || r.starts_with(']') || r.starts_with('.')
            })
        })
        .map_or(0, |i| i + 1)
}

/// `[roles.operator] functions = [3, 4, 6] units = ["1-20"] read-only = false` as `--role`
/// options.
fn role_options(roles: &toml::Value) -> Result<Vec<String>, String> {
    let toml::Value::Table(roles) = roles else { return Err("[roles] must hold tables, e.g. [roles.operator]".into()) };
    let mut out = Vec::new();
    for (name, rules) in roles {
        let toml::Value::Table(rules) = rules else { return Err(format!("roles.{name} must be a table")) };
        let mut parts = Vec::new();
        for (key, value) in rules {
            let list = |v: &toml::Value| -> Result<String, String> {
                let items = v.as_array().ok_or_else(|| format!("roles.{name}.{key} = {v}: expected a list"))?;
                items
                    .iter()
                    .map(|i| match i {
                        toml::Value::Integer(n) => Ok(n.to_string()),
                        toml::Value::String(s) => Ok(s.clone()),
                        other => Err(format!("roles.{name}.{key}: {other} is not a number or a range")),
                    })
                    .collect::<Result<Vec<_>, _>>()
                    .map(|v| v.join(","))
            };
            match (key.as_str(), value) {
                ("functions", v) => parts.push(format!("functions:{}", list(v)?)),
                ("units", v) => parts.push(format!("units:{}", list(v)?)),
                ("read-only" | "read_only", toml::Value::Boolean(true)) => parts.push("read-only".into()),
                ("read-only" | "read_only", toml::Value::Boolean(false)) => {}
                _ => return Err(format!("roles.{name}.{key}: known keys are functions, units and read-only")),
            }
        }
        out.push(format!("--role={name}={}", parts.join(";")));
    }
    Ok(out)
}
