//! `mbtap bridge --config FILE`: the bridge's settings in a TOML file, with the same names as
//! the command-line options (`listen = "0.0.0.0:502"`, `read-only = true`, `route = [...]`).
//! [`merge`] puts the command line over the file. `mbtap generate-config` prints a commented
//! sample ([`SAMPLE`]).

use std::path::Path;

use anyhow::Context;
use clap::parser::ValueSource;
use clap::{ArgMatches, FromArgMatches};

use crate::cmd::bridge::Args;

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

# Per request: response timeout (ms), retries after a timeout or a bad CRC, extra quiet time
# after t3.5 before the next request (ms).
timeout-ms = 1000
retries = 0
turnaround-ms = 0.0
# broadcast-reply = true  # answer broadcast writes at once, for SCADA that insists

# Safety.
read-only = false
# allow-function = ["3", "4"]
# allow-ip = ["10.0.0.0/24", "127.0.0.1"]
max-connections = 64
idle-timeout = 300.0     # seconds
# rate-limit = 50.0      # requests per second per connection
queue-per-client = 32
# map-unit = ["10=1"]    # TCP unit id = serial address

# Observability.
# metrics = "127.0.0.1:9502"
# monitor = "jsonl"      # text | jsonl | tui
# device = ["1=mk4", "5=display", "17=mkzp"]
"#;

/// `--config FILE` under the command line: every option the command line gave (`matches`)
/// keeps its value, lists included (a `--allow-ip` on the command line replaces the file's list,
/// it does not add to it); every other option takes the file's value, else its default.
///
/// # Errors
/// The file cannot be read, or a setting is unknown or has a value its option refuses — each
/// said with the file, the key and the value.
pub fn merge(path: &Path, cli: Args, matches: Option<&ArgMatches>) -> anyhow::Result<Args> {
    let shown = path.display();
    let text = std::fs::read_to_string(path).with_context(|| format!("reading the configuration {shown}"))?;
    let options = options(&text).map_err(|e| anyhow::anyhow!("{shown}: {e}"))?;
    let command = <Args as clap::Args>::augment_args(clap::Command::new("bridge").no_binary_name(true));
    let file_matches = command.try_get_matches_from(&options).map_err(|e| {
        let message = e.to_string();
        let first = message.lines().next().unwrap_or("").trim_start_matches("error: ");
        anyhow::anyhow!("{shown}: {first}")
    })?;
    let mut merged = Args::from_arg_matches(&file_matches).map_err(|e| anyhow::anyhow!("{shown}: {e}"))?;
    let given: Vec<&str> = matches.map_or_else(Vec::new, |m| {
        m.ids().map(clap::Id::as_str).filter(|id| m.value_source(id) == Some(ValueSource::CommandLine)).collect()
    });
    macro_rules! command_line_wins {
        ($($id:literal => $($field:ident).+),* $(,)?) => {
            $(if given.contains(&$id) { merged.$($field).+ = cli.$($field).+.clone(); })*
            /// Every option's id, so a test can prove none is forgotten.
            #[cfg(test)]
            const MERGED: &[&str] = &[$($id),*];
            #[cfg(test)]
            MERGED_IDS.with(|m| m.set(MERGED));
        };
    }
    command_line_wins! {
        "config" => config,
        "serial" => serial,
        "mode" => line.mode,
        "baud" => line.baud,
        "parity" => line.parity,
        "stop_bits" => line.stop_bits,
        "data_bits" => line.data_bits,
        "latency_ms" => line.latency_ms,
        "link_type" => line.link_type,
        "listen" => listen,
        "listen_rtu" => listen_rtu,
        "routes" => routes,
        "timeout_ms" => timeout_ms,
        "retries" => retries,
        "turnaround_ms" => turnaround_ms,
        "broadcast_reply" => broadcast_reply,
        "read_only" => read_only,
        "allow_functions" => allow_functions,
        "allow_ips" => allow_ips,
        "max_connections" => max_connections,
        "idle_timeout" => idle_timeout,
        "rate_limit" => rate_limit,
        "queue_per_client" => queue_per_client,
        "unit_map" => unit_map,
        "metrics" => metrics,
        "reverse" => reverse,
        "target" => target,
        "answer_as" => answer_as,
        "monitor" => monitor,
        "devices" => devices,
        "duration" => duration,
    }
    merged.config = cli.config;
    Ok(merged)
}

#[cfg(test)]
thread_local! {
    static MERGED_IDS: std::cell::Cell<&'static [&'static str]> = const { std::cell::Cell::new(&[]) };
}

/// The `[bridge]` table as command-line options.
///
/// # Errors
/// A TOML error (with its line), an unknown setting (with the known ones), or a value of a
/// type no option takes.
pub fn options(text: &str) -> Result<Vec<String>, String> {
    let doc: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
    let table = match doc.get("bridge") {
        Some(toml::Value::Table(t)) => t.clone(),
        Some(_) => return Err("[bridge] must be a table".into()),
        None => doc,
    };
    let bridge = <Args as clap::Args>::augment_args(clap::Command::new("bridge"));
    let known: Vec<String> =
        bridge.get_arguments().filter_map(|a| a.get_long().map(str::to_owned)).filter(|l| l != "config").collect();
    let mut out = Vec::new();
    for (key, value) in &table {
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
            toml::Value::Array(items) if items.is_empty() && matches!(long.as_str(), "allow-ip" | "allow-function") => {
                return Err(format!(
                    "{key} = []: an empty allow-list would let every client (or function) through; list what is allowed, or remove the key to allow all"
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

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, Parser};

    use super::*;
    use crate::cmd::{Cli, Command};

    /// The bridge options of a command line, and which it gave.
    fn parse(args: &[&str]) -> (Args, ArgMatches) {
        let matches = Cli::command().try_get_matches_from(args).unwrap_or_else(|e| panic!("{e}"));
        let Command::Bridge(b) = Cli::from_arg_matches(&matches).unwrap().command else { panic!("not the bridge") };
        let sub = matches.subcommand_matches("bridge").unwrap().clone();
        (*b, sub)
    }

    fn file(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("mbtap-config-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("bridge.toml");
        std::fs::write(&file, text).unwrap();
        file
    }

    #[test]
    fn the_sample_is_a_valid_configuration() {
        let mut args = vec!["mbtap".to_owned(), "bridge".to_owned()];
        args.extend(options(SAMPLE).unwrap());
        let cli = Cli::try_parse_from(&args).unwrap_or_else(|e| panic!("{e}"));
        let Command::Bridge(b) = cli.command else { panic!("not the bridge") };
        assert_eq!(b.serial.as_deref(), Some("/dev/ttyUSB0"));
        assert_eq!(b.listen.as_deref(), Some("0.0.0.0:502"));
        assert_eq!(b.timeout_ms, 1000);
        assert!(!b.read_only);
    }

    #[test]
    fn the_command_line_wins_over_the_file() {
        let file = file("wins", "[bridge]\nserial = \"/dev/ttyS0\"\nlisten = \"127.0.0.1:1502\"\nread-only = true\n");
        let path = file.to_str().unwrap();
        let (cli, m) = parse(&["mbtap", "bridge", "--config", path, "--listen", "127.0.0.1:2502"]);
        let b = merge(&file, cli, Some(&m)).unwrap();
        assert_eq!(b.listen.as_deref(), Some("127.0.0.1:2502"));
        assert_eq!(b.serial.as_deref(), Some("/dev/ttyS0"));
        assert!(b.read_only);
    }

    #[test]
    fn a_list_on_the_command_line_replaces_the_files_list() {
        let file = file("lists", "[bridge]\nallow-ip = [\"10.0.0.0/8\"]\nroute = [\"11-20=/dev/ttyS1\"]\n");
        let path = file.to_str().unwrap();
        let (cli, m) = parse(&["mbtap", "bridge", "--config", path, "--allow-ip", "127.0.0.1"]);
        let b = merge(&file, cli, Some(&m)).unwrap();
        assert_eq!(b.allow_ips, ["127.0.0.1"]);
        assert_eq!(b.routes, ["11-20=/dev/ttyS1"]);
    }

    #[test]
    fn a_negative_number_in_the_file_is_refused_naming_the_file_the_key_and_the_value() {
        let file = file("negative", "[bridge]\ntimeout-ms = -5\n");
        let (cli, m) = parse(&["mbtap", "bridge", "--config", file.to_str().unwrap()]);
        let e = merge(&file, cli, Some(&m)).unwrap_err().to_string();
        assert!(e.contains(file.to_str().unwrap()) && e.contains("timeout-ms") && e.contains("-5"), "{e}");
        assert!(!e.contains("unexpected argument"), "{e}");
    }

    #[test]
    fn an_empty_allow_list_refuses_to_start() {
        let file = file("empty-allow", "[bridge]\nallow-ip = []\n");
        let (cli, m) = parse(&["mbtap", "bridge", "--config", file.to_str().unwrap()]);
        let e = format!("{:#}", merge(&file, cli, Some(&m)).unwrap_err());
        assert!(e.contains("allow-ip = []") && e.contains(file.to_str().unwrap()), "{e}");
    }

    #[test]
    fn every_bridge_option_is_merged() {
        let file = file("all", "");
        let (cli, m) = parse(&["mbtap", "bridge", "--config", file.to_str().unwrap()]);
        merge(&file, cli, Some(&m)).unwrap();
        let merged = MERGED_IDS.with(std::cell::Cell::get);
        let bridge = <Args as clap::Args>::augment_args(clap::Command::new("bridge"));
        for arg in bridge.get_arguments() {
            assert!(merged.contains(&arg.get_id().as_str()), "--config merge forgets {}", arg.get_id());
        }
    }

    #[test]
    fn mistakes_name_the_file_the_line_and_the_setting() {
        assert!(options("[bridge]\nlisten = \"x\"\nbaud = \n").unwrap_err().contains("line 3"));
        let e = options("[bridge]\nlisten-port = 502\n").unwrap_err();
        assert!(e.contains("listen-port") && e.contains("listen"), "{e}");
        let path = std::path::Path::new("/nonexistent/bridge.toml");
        let (cli, m) = parse(&["mbtap", "bridge", "--config", "/nonexistent/bridge.toml"]);
        let e = format!("{:#}", merge(path, cli, Some(&m)).unwrap_err());
        assert!(e.contains("/nonexistent/bridge.toml"), "{e}");
    }
}
