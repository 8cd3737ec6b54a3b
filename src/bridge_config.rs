//! `mbtap bridge --config FILE`: the bridge's settings in a TOML file, with the same names as
//! the command-line options (`listen = "0.0.0.0:502"`, `read-only = true`, `route = [...]`).
//! The file's settings become options placed before the command line's, so the command line
//! wins. `mbtap generate-config` prints a commented sample ([`SAMPLE`]).

use std::ffi::OsString;

use clap::CommandFactory;

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

/// Replaces `--config FILE` after `bridge` with the file's settings as options.
///
/// # Errors
/// What is wrong with the file, naming it (and the line, for TOML errors).
pub fn expand(args: Vec<OsString>) -> Result<Vec<OsString>, String> {
    if args.get(1).and_then(|a| a.to_str()) != Some("bridge") {
        return Ok(args);
    }
    let mut path = None;
    let mut rest = Vec::with_capacity(args.len());
    let mut it = args.into_iter();
    while let Some(a) = it.next() {
        match a.to_str() {
            Some("--config") => path = Some(it.next().ok_or("--config needs a file")?),
            Some(s) if s.starts_with("--config=") => path = Some(OsString::from(&s["--config=".len()..])),
            _ => rest.push(a),
        }
    }
    let Some(path) = path else { return Ok(rest) };
    let shown = path.to_string_lossy().into_owned();
    let text = std::fs::read_to_string(&path).map_err(|e| format!("reading the configuration {shown}: {e}"))?;
    let options = options(&text).map_err(|e| format!("{shown}: {e}"))?;
    // After `mbtap bridge`, before the command line's own options.
    let mut out: Vec<OsString> = rest.drain(..2.min(rest.len())).collect();
    out.extend(options.into_iter().map(OsString::from));
    out.extend(rest);
    Ok(out)
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
    let command = crate::cli::Cli::command();
    let bridge = command.find_subcommand("bridge").ok_or("no bridge command (a build defect)")?;
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
            toml::Value::Array(items) => {
                for item in items {
                    out.push(flag.clone());
                    out.push(scalar(item)?);
                }
            }
            v => {
                out.push(flag);
                out.push(scalar(v)?);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    fn os(v: &[&str]) -> Vec<OsString> {
        v.iter().map(OsString::from).collect()
    }

    #[test]
    fn the_sample_is_a_valid_configuration() {
        let mut args = vec!["mbtap".to_owned(), "bridge".to_owned()];
        args.extend(options(SAMPLE).unwrap());
        let cli = crate::cli::Cli::try_parse_from(&args).unwrap_or_else(|e| panic!("{e}"));
        let crate::cli::Command::Bridge(b) = cli.command else { panic!("not the bridge") };
        assert_eq!(b.serial.as_deref(), Some("/dev/ttyUSB0"));
        assert_eq!(b.listen.as_deref(), Some("0.0.0.0:502"));
        assert_eq!(b.timeout_ms, 1000);
        assert!(!b.read_only);
    }

    #[test]
    fn the_command_line_wins_over_the_file() {
        let dir = std::env::temp_dir().join(format!("mbtap-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("bridge.toml");
        std::fs::write(&file, "[bridge]\nserial = \"/dev/ttyS0\"\nlisten = \"127.0.0.1:1502\"\nread-only = true\n")
            .unwrap();
        let args =
            expand(os(&["mbtap", "bridge", "--config", file.to_str().unwrap(), "--listen", "127.0.0.1:2502"])).unwrap();
        let cli = crate::cli::Cli::try_parse_from(&args).unwrap_or_else(|e| panic!("{e}"));
        let crate::cli::Command::Bridge(b) = cli.command else { panic!("not the bridge") };
        assert_eq!(b.listen.as_deref(), Some("127.0.0.1:2502"));
        assert_eq!(b.serial.as_deref(), Some("/dev/ttyS0"));
        assert!(b.read_only);
    }

    #[test]
    fn mistakes_name_the_file_the_line_and_the_setting() {
        assert!(options("[bridge]\nlisten = \"x\"\nbaud = \n").unwrap_err().contains("line 3"));
        let e = options("[bridge]\nlisten-port = 502\n").unwrap_err();
        assert!(e.contains("listen-port") && e.contains("listen"), "{e}");
        let e = expand(os(&["mbtap", "bridge", "--config", "/nonexistent/bridge.toml"])).unwrap_err();
        assert!(e.contains("/nonexistent/bridge.toml"), "{e}");
        assert_eq!(expand(os(&["mbtap", "sniff", "--config", "x"])).unwrap(), os(&["mbtap", "sniff", "--config", "x"]));
    }
}
