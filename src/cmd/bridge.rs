//! `mbtap bridge`: Modbus TCP clients to serial devices (or, `--reverse`, an RTU master to a
//! TCP device). Settings come from `--config FILE` merged under the command line
//! ([`crate::config::merge`]): an option given on the command line replaces the file's value,
//! lists included.
//!
//! Its pieces: `values` (the configuration file merged under the command line, refusals naming
//! where each came from) and `parts` (the options made into what the bridge runs with).

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::ArgMatches;

use crate::cli::args::{EventFormatArg, LineArgs};
use crate::cli::runner::{EventSource, Input, Runner};
use crate::cmd::runtime;
use crate::output::{EventWriter, SourceError};

mod parts;
mod values;
use parts::{allow_function_codes, caches, check_rs485, reverse_front, usb_serial};
use values::{check_values, merge};

/// Modbus TCP clients to serial devices: a TCP server in front of a serial master.
// Flags, each its own switch on the command line (clap), not states of one machine.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Read settings from this TOML file ([bridge] table; the command line wins).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The line (all units; see --route for several lines): a serial port, or
    /// `rtu-over-tcp://HOST:PORT` (a serial server in transparent mode, e.g. ser2net raw, USR,
    /// Elfin), `rfc2217://HOST:PORT` (a remote port whose settings the bridge sets, e.g.
    /// ser2net telnet(rfc2217), Moxa NPort), `tcp://HOST:PORT` (a Modbus TCP device: every
    /// client through the bridge's one connection).
    #[arg(long)]
    pub serial: Option<String>,
    /// The line's USB adapter by its ids instead of a path, `VID:PID[:SERIAL]` (hex, as lsusb
    /// prints them): found again under whatever /dev/ttyUSBn it comes back as.
    #[arg(long, value_name = "VID:PID[:SERIAL]", conflicts_with = "serial")]
    pub serial_match: Option<String>,
    #[command(flatten)]
    pub line: LineArgs,
    /// Modbus TCP (MBAP) listening address, e.g. 0.0.0.0:502 (port 0 picks a free port).
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen: Option<String>,
    /// Raw RTU frames over TCP on this address too (or instead).
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen_rtu: Option<String>,
    /// Modbus UDP clients (one MBAP request per datagram) on this address too (or instead),
    /// under the same allow-lists, read-only rules, rate limit, queue and cache as TCP clients.
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen_udp: Option<String>,
    /// Answer as the slave on this serial port too (the line's settings), for a master already
    /// on the device's line (an inverter polling its meter): its requests go through the same
    /// admission, cache and queue as a TCP client's, the device is shared.
    #[arg(long, value_name = "PORT")]
    pub listen_serial: Option<String>,
    /// Units FIRST-LAST on another serial port (repeatable): --route 11-20=/dev/ttyUSB1.
    #[arg(long = "route", value_name = "UNITS=PORT")]
    pub routes: Vec<String>,
    /// Response timeout per request, ms; then retries, then exception 0x0B. The default answers
    /// a dead unit's 0x0B before a client's own 1 s timeout (mbpoll's, many SCADAs').
    #[arg(long, default_value_t = crate::bridge::run::DEFAULT_TIMEOUT_MS)]
    pub timeout_ms: u64,
    /// `fixed`: --timeout-ms for every unit. `auto`: each unit's timeout learnt from its
    /// answers (3 × its slowest of the last 32 + 10 ms, at least 20 ms, at most --timeout-ms,
    /// doubled after each timeout), so a dead unit costs little line time and a slow one is not
    /// cut off.
    #[arg(long, value_enum, default_value_t = crate::bridge::modes::TimeoutArg::Fixed, value_name = "MODE")]
    pub timeout: crate::bridge::modes::TimeoutArg,
    /// Whether the adapter hears its own transmission: `auto` finds out from the first request,
    /// `on` consumes each request's echo before the answer (a difference is a collision,
    /// counted), `off` expects none.
    #[arg(long, value_enum, default_value_t = crate::bridge::modes::EchoArg::Auto)]
    pub echo: crate::bridge::modes::EchoArg,
    /// Answer reads of these registers from memory while younger than MAX_AGE (repeatable):
    /// `UNITS:TABLE:FIRST-LAST=MAX_AGE`, e.g. `1:holding:0-9=1s`, `1,5:input:430-433=500ms`.
    /// Writes invalidate what they overlap; exceptions are never cached.
    #[arg(long, value_name = "RULE")]
    pub cache: Vec<String>,
    /// Agent mode: the bridge reads these registers itself every INTERVAL (repeatable),
    /// `UNITS:TABLE:FIRST-LAST@INTERVAL`, e.g. `1:holding:100-109@1s`, spreading its polls over
    /// the interval; clients are answered from the cache (values kept two intervals).
    #[arg(long, value_name = "RULE")]
    pub poll: Vec<String>,
    /// Requests that go before the round-robin (repeatable): `high=ip:NET` (a control room's
    /// network), `high=unit:UNITS`, `high=fc:CODES` (e.g. writes: `high=fc:5,6,15,16`). They
    /// go next, unless the others have been passed over three times in a row: no one starves.
    #[arg(long, value_name = "high=RULE")]
    pub priority: Vec<String>,
    /// A unit's own timeout (repeatable): `--unit-timeout 5=2000` for a slow unit beside fast
    /// ones, `--unit-timeout 10-12=50`. Wins over --timeout auto.
    #[arg(long, value_name = "UNITS=MS")]
    pub unit_timeout: Vec<String>,
    /// Silence the line keeps before each request to a unit, beyond t3.5 and --turnaround-ms
    /// (repeatable): `--unit-gap 1=40` for a device that needs a pause between requests,
    /// `--unit-gap 10-12=100`, `--unit-gap 20` for every unit. Other units wait for no one's
    /// gap; the time waited is in the metrics (`mbtap_bridge_unit_gap_wait_seconds_total`).
    #[arg(long, value_name = "[UNITS=]MS")]
    pub unit_gap: Vec<String>,
    #[command(flatten)]
    pub audit: crate::output::audit::AuditArgs,
    /// A live view of the bridge on this address (`127.0.0.1:8502`; port 0 picks one): lines,
    /// units (requests, answers, exceptions, timeouts, p50/p99, breaker, gap), clients, the last
    /// transactions and latency over time, updating every second; `/api/state` the same as
    /// JSON. Read-only, self-contained. An address that is not loopback needs --web-allow-ip.
    #[arg(long, value_name = "ADDR:PORT")]
    pub web: Option<String>,
    /// Who may open the web view (repeatable): `10.0.0.0/24`, `192.0.2.7`. Needed for a --web
    /// address that is not loopback.
    #[arg(long = "web-allow-ip", value_name = "NET", value_parser = crate::cli::numbers::ip_net, requires = "web")]
    pub web_allow_ips: Vec<mbtap_gateway::admit::IpNet>,
    /// Retries after a timeout or a failed CRC.
    #[arg(long, default_value_t = 0)]
    pub retries: u32,
    /// Extra quiet time after t3.5 before the next request, ms.
    #[arg(long, default_value_t = 0.0, value_parser = crate::cli::numbers::millis)]
    pub turnaround_ms: f64,
    /// Answer broadcast writes (unit 0) at once instead of not at all (implies --allow-broadcast).
    #[arg(long)]
    pub broadcast_reply: bool,
    /// Let writes to unit 0 through as broadcasts to every device on the line. Without it unit 0
    /// is refused (exception 01) from every front, the broker's writes included.
    #[arg(long)]
    pub allow_broadcast: bool,
    /// Refuse writes (exception 0x01); they never reach the line.
    #[arg(long)]
    pub read_only: bool,
    /// Only these function codes pass (repeatable; 3 or 0x03).
    #[arg(long = "allow-function", value_name = "CODE")]
    pub allow_functions: Vec<String>,
    /// Only these clients may connect (repeatable; 10.0.0.5 or 10.0.0.0/24).
    #[arg(long = "allow-ip", value_name = "NET", value_parser = crate::cli::numbers::ip_net)]
    pub allow_ips: Vec<mbtap_gateway::admit::IpNet>,
    /// Connections open at once; more are refused.
    #[arg(long, default_value_t = 64)]
    pub max_connections: usize,
    /// Close a connection silent this long: `300s`, `5min` (a bare number is seconds).
    #[arg(long, default_value = "300s", value_name = "DURATION", value_parser = crate::cli::args::duration_arg)]
    pub idle_timeout: std::time::Duration,
    /// Requests per second per connection; above it exception 0x06 (busy).
    #[arg(long, value_parser = crate::cli::numbers::rate)]
    pub rate_limit: Option<f64>,
    /// Requests a client may have waiting; more get exception 0x06.
    #[arg(long, default_value_t = 32)]
    pub queue_per_client: usize,
    /// TCP unit id → serial address (repeatable): --map-unit 10=1.
    #[arg(long = "map-unit", value_name = "TCP=SERIAL")]
    pub unit_map: Vec<String>,
    /// Serve Prometheus metrics on this address (GET /metrics).
    #[arg(long, value_name = "ADDR:PORT")]
    pub metrics: Option<String>,
    /// Reverse: answer as serial slaves (--answer-as) on --serial and forward to the Modbus TCP
    /// server --target (or the RTU-over-TCP server --target-rtu), so an RTU master reaches TCP
    /// devices. The same as `--listen-serial PORT --serial tcp://TARGET`: every option of the
    /// bridge works with it (timeouts, retries, cache, --listen for TCP clients beside the master).
    #[arg(long, requires = "reverse_target", conflicts_with = "listen_serial")]
    pub reverse: bool,
    /// Reverse mode: the Modbus TCP server to forward to.
    #[arg(long, value_name = "HOST:PORT", group = "reverse_target")]
    pub target: Option<String>,
    /// Reverse mode: an RTU-over-TCP server to forward to instead (a serial device server, a
    /// cheap Ethernet-to-RS-485 converter): RTU frames with their CRC over the TCP stream.
    #[arg(long, value_name = "HOST:PORT", group = "reverse_target")]
    pub target_rtu: Option<String>,
    /// The serial front's (reverse mode's, --listen-serial's) addresses to answer as, e.g.
    /// 1,5,10-20 (default: every unit a line serves).
    #[arg(long, value_name = "UNITS")]
    pub answer_as: Option<String>,
    /// Show the bridged traffic: text, jsonl or tui.
    #[arg(long, value_enum)]
    pub monitor: Option<EventFormatArg>,
    /// Annotate unit UNIT's values in the monitor: `UNIT=NAME` or `UNIT=FILE.toml`.
    #[arg(long = "device", value_name = "UNIT=PROFILE")]
    pub devices: Vec<String>,
    /// Stop after this long: `90s`, `2min`, `1h`, `500ms` (a bare number is seconds).
    #[arg(long, value_name = "DURATION", value_parser = crate::cli::args::duration_arg)]
    pub duration: Option<std::time::Duration>,
    /// RS-485 direction control of the serial lines.
    #[command(flatten)]
    pub rs485: crate::io::rs485::Rs485Args,
    /// Modbus/TCP Security: the TLS listener, its certificates and the clients' roles.
    #[command(flatten)]
    pub tls: crate::bridge::tls::TlsArgs,
    /// Publish what the monitor hears (values, unit health, findings) to MQTT.
    #[command(flatten)]
    pub mqtt: crate::publish::mqtt::MqttArgs,
    /// With --mqtt-writes: the role (one of --role) whose rules also judge the broker's writes;
    /// without it they pass the plain listeners' rules (--read-only, --allow-function, routes).
    #[arg(long, value_name = "NAME", requires = "mqtt_writes")]
    pub mqtt_role: Option<String>,
}

/// Runs the bridge; `matches` tells which options the command line gave, for `--config`.
pub fn run(args: Args, matches: Option<&ArgMatches>) -> anyhow::Result<ExitCode> {
    let args = match &args.config {
        Some(path) => merge(path, args.clone(), matches)?,
        None => args,
    };
    check_values(&args, matches)?;
    let Args {
        config: _,
        serial,
        serial_match,
        line,
        listen,
        listen_rtu,
        listen_udp,
        listen_serial,
        routes,
        timeout_ms,
        timeout,
        unit_timeout,
        unit_gap,
        audit,
        web,
        web_allow_ips,
        echo,
        cache,
        poll,
        priority,
        retries,
        turnaround_ms,
        broadcast_reply,
        allow_broadcast,
        read_only,
        allow_functions,
        allow_ips,
        max_connections,
        idle_timeout,
        rate_limit,
        queue_per_client,
        unit_map,
        metrics,
        reverse,
        target,
        target_rtu,
        answer_as,
        monitor,
        devices,
        duration,
        rs485,
        tls,
        mqtt,
        mqtt_role,
    } = args;
    let serial = usb_serial(serial, serial_match)?;
    // The port name the MQTT prefix ends with.
    let source = serial.clone().unwrap_or_else(|| "bridge".to_owned());
    let (mode, settings, latency_ns) = line.overrides().resolve();
    // What a request may do, built once for every front and reverse mode alike (the routes are
    // filled from the lines when they start).
    let policy = mbtap_gateway::admit::Policy {
        read_only,
        allow_functions: allow_function_codes(&allow_functions)?,
        unit_map: mbtap_gateway::parse::parse_unit_map(&unit_map)?,
        priority: priority.iter().map(|p| mbtap_gateway::admit::parse_priority(p)).collect::<Result<_, _>>()?,
        routes: Vec::new(),
        broadcast: allow_broadcast || broadcast_reply,
    };
    let (serial, listen_serial) = reverse_front(reverse, serial, listen_serial, target, target_rtu)?;
    let answer_as = mbtap_gateway::parse::parse_units(answer_as.as_deref().unwrap_or(""))?;
    anyhow::ensure!(
        listen.is_some()
            || listen_rtu.is_some()
            || listen_udp.is_some()
            || listen_serial.is_some()
            || tls.listen_tls.is_some(),
        "nothing to listen on: give --listen ADDR:PORT (Modbus TCP), --listen-rtu ADDR:PORT, --listen-udp ADDR:PORT and/or --listen-tls ADDR:PORT"
    );
    anyhow::ensure!(
        turnaround_ms.is_finite() && turnaround_ms >= 0.0,
        "--turnaround-ms {turnaround_ms}: expected 0 or more"
    );
    let turnaround = std::time::Duration::from_secs_f64(turnaround_ms / 1000.0);
    anyhow::ensure!(!idle_timeout.is_zero(), "--idle-timeout {idle_timeout:?}: expected a duration above 0, e.g. 300s");
    let unit_timeouts = mbtap_gateway::timeouts::parse_unit_timeouts(&unit_timeout)?;
    let unit_gaps = mbtap_gateway::line::UnitGaps::parse(&unit_gap)?;
    let (cache, polls) = caches(&cache, &poll)?;
    let line_for = |port: String| crate::bridge::line::LineOptions {
        line: settings,
        mode,
        timeout: std::time::Duration::from_millis(timeout_ms),
        timeout_mode: timeout.into(),
        unit_timeouts: unit_timeouts.clone(),
        unit_gaps: unit_gaps.clone(),
        echo: echo.into(),
        rs485,
        cache: cache.clone(),
        polls: polls.clone(),
        retries,
        turnaround,
        broadcast_reply,
        // A serial server's TCP stream keeps no timing: silences shorter than its latency are
        // not taken as the end of an answer whose length the structure does not give.
        latency: std::time::Duration::from_nanos(
            crate::io::stream::Transport::of(&port).latency_ns(latency_ns).unwrap_or(0),
        ),
        port,
        emulated: None,
    };
    let mut lines = Vec::new();
    for r in &routes {
        let (units, port) = mbtap_gateway::parse::parse_route(r)?;
        lines.push((units, line_for(port)));
    }
    if let Some(port) = serial {
        // The plain --serial line serves every unit the routes do not.
        lines.push((1..=247, line_for(port)));
    }
    anyhow::ensure!(!lines.is_empty(), "no serial line: give --serial PORT or --route UNITS=PORT");
    check_rs485(&rs485, lines.iter().map(|(_, l)| l.port.as_str()).chain(listen_serial.as_deref()))?;
    let mut opts = crate::bridge::run::BridgeOptions {
        lines,
        listen,
        listen_rtu,
        listen_udp,
        server: crate::bridge::request::ServerOptions {
            rtu_over_tcp: false,
            policy,
            allow_ips,
            max_connections,
            idle_timeout,
            rate_limit,
        },
        queue_per_client,
        metrics,
        duration,
        monitor_front: reverse,
        roles: std::sync::Arc::new(crate::bridge::tls::parse_roles(&tls.role)?),
        tls,
        broker_writes: None,
        audit: audit.open()?,
        web: web.map(|addr| crate::bridge::web::WebOptions { addr, allow: web_allow_ips }),
        listen_serial: listen_serial.map(|port| crate::bridge::serial_front::SerialFront {
            port,
            line: settings,
            mode,
            turnaround,
            rs485,
            answer_as,
            option: if reverse { "--reverse" } else { "--listen-serial" },
        }),
    };
    let profiles = crate::config::devices::load_devices(&devices)?;
    anyhow::ensure!(
        mqtt.mqtt.is_none() || monitor.is_some(),
        "--mqtt on the bridge publishes what its monitor hears: add --monitor (text, jsonl or tui)"
    );
    let (publisher, broker_writes) =
        crate::bridge::broker::start_publisher(&mqtt, mqtt_role.as_deref(), &source, &profiles, &opts.roles)?;
    opts.broker_writes = broker_writes;
    let Some(format) = monitor else {
        runtime()?.block_on(crate::bridge::run::bridge::<io::Sink>(opts, None, &mut io::stderr()))?;
        return Ok(ExitCode::SUCCESS);
    };
    let mut runner = Runner::new(
        "bridge".into(),
        Input::Live,
        format,
        profiles,
        mbtap_device::profile::annotate::Lang::En,
        settings,
    );
    runner.publishing = crate::publish::Publishing { spy: None, mqtt: publisher };
    runner.run(Monitor(opts))
}

/// The bridge as the runner's source: what its lines carry, shown by `--monitor`.
struct Monitor(crate::bridge::run::BridgeOptions);

impl EventSource for Monitor {
    fn run<W: Write>(self, writer: &mut EventWriter<W>, err: &mut dyn Write) -> Result<(), SourceError> {
        // The bridge fails only while it sets up (a listener that cannot bind, a port that will
        // not open); once serving, it serves until stopped.
        let started = crate::runtime()?.block_on(crate::bridge::run::bridge(self.0, Some(writer), err));
        started.map_err(SourceError::NotStarted)
    }
}

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, FromArgMatches, Parser};

    use super::*;
    use crate::bridge::config::{SAMPLE, options};
    use crate::cmd::{Cli, Command};

    /// The long names of the bridge's options a configuration file may set.
    fn known_keys() -> Vec<String> {
        crate::config::merge::known_keys::<Args>()
    }

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
        args.extend(options(SAMPLE, &known_keys()).unwrap());
        let cli = Cli::try_parse_from(&args).unwrap_or_else(|e| panic!("{e}"));
        let Command::Bridge(b) = cli.command else { panic!("not the bridge") };
        assert_eq!(b.serial.as_deref(), Some("/dev/ttyUSB0"));
        assert_eq!(b.listen.as_deref(), Some("0.0.0.0:502"));
        assert_eq!(b.timeout_ms, 800);
        // The packaged sample opened a writable gateway to the whole network.
        assert!(b.read_only, "the sample starts closed to writes");
    }

    #[test]
    fn roles_tables_in_the_file_become_role_rules() {
        let file = file(
            "roles",
            "[bridge]\nserial = \"/dev/ttyS0\"\nlisten-tls = \"127.0.0.1:802\"\ncert = \"c.pem\"\nkey = \"k.pem\"\nclient-ca = \"ca.pem\"\n\
             [roles.operator]\nfunctions = [3, 4, 6]\nunits = [\"1-20\"]\n[roles.viewer]\nread-only = true\n",
        );
        let path = file.to_str().unwrap();
        let (cli, m) = parse(&["mbtap", "bridge", "--config", path]);
        let b = merge(&file, cli, Some(&m)).unwrap();
        assert_eq!(b.tls.role, ["operator=functions:3,4,6;units:1-20", "viewer=read-only"]);
        let roles = crate::bridge::tls::parse_roles(&b.tls.role).unwrap();
        assert!(roles["viewer"].read_only);
        let bad = file_bad();
        assert!(merge(&bad, parse(&["mbtap", "bridge", "--config", bad.to_str().unwrap()]).0, None).is_err());
    }

    fn file_bad() -> std::path::PathBuf {
        file("roles-bad", "[bridge]\nserial = \"/dev/ttyS0\"\n[roles.operator]\nwrites = true\n")
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
        assert_eq!(b.allow_ips, ["127.0.0.1".parse().unwrap()]);
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

    /// `read-only = true` and `allow-ip` above `[bridge]` would look set and do nothing: the
    /// start is refused, naming the file, the line and the key.
    #[test]
    fn keys_outside_the_bridge_table_refuse_to_start() {
        let file =
            file("outside", "read-only = true\nallow-ip = [\"10.9.9.9\"]\n\n[bridge]\nserial = \"/dev/ttyS0\"\n");
        let (cli, m) = parse(&["mbtap", "bridge", "--config", file.to_str().unwrap()]);
        let e = format!("{:#}", merge(&file, cli, Some(&m)).unwrap_err());
        assert!(e.contains(file.to_str().unwrap()) && e.contains("line 1") && e.contains("read-only"), "{e}");
        let e = options("[bridge]\nlisten = \"x\"\n[bridg]\nread-only = true\n", &known_keys()).unwrap_err();
        assert!(e.contains("line 3") && e.contains("bridg"), "{e}");
    }

    /// Every empty list (`tls-allow-ip = []`, `crl = []`, …) is refused as `allow-ip = []` is,
    /// and so is an empty `[roles.admin]`, which would let a client do everything.
    #[test]
    fn every_empty_list_and_empty_role_is_refused() {
        for (key, line) in [("tls-allow-ip", 3), ("crl", 3), ("allow-function", 3), ("route", 3)] {
            let e = options(&format!("[bridge]\nlisten = \"x\"\n{key} = []\n"), &known_keys()).unwrap_err();
            assert!(e.contains(&format!("{key} = []")) && e.contains(&format!("line {line}")), "{e}");
        }
        let opts = options("[bridge]\nlisten = \"x\"\n[roles.admin]\n", &known_keys()).unwrap();
        let roles: Vec<String> = opts.iter().filter_map(|o| o.strip_prefix("--role=")).map(str::to_owned).collect();
        assert!(crate::bridge::tls::parse_roles(&roles).is_err(), "{roles:?}");
    }

    /// The merge gives the command line's options again by their long name: every bridge option
    /// must have one, and be a flag set once or take values (a counted flag or a positional
    /// argument would not survive it).
    #[test]
    fn every_option_can_be_given_again() {
        let bridge = <Args as clap::Args>::augment_args(clap::Command::new("bridge"));
        for arg in bridge.get_arguments() {
            assert!(arg.get_long().is_some(), "{} has no long name", arg.get_id());
            assert!(
                matches!(arg.get_action(), clap::ArgAction::SetTrue | clap::ArgAction::Set | clap::ArgAction::Append),
                "{}: {:?}",
                arg.get_id(),
                arg.get_action()
            );
        }
    }

    /// Every kind of option the command line gives wins over the file: a flag, a value, a list,
    /// options of the flattened groups (TLS, RS-485, MQTT); the file's others stay.
    #[test]
    fn the_command_line_wins_for_every_kind_of_option() {
        let f = file(
            "kinds",
            "[bridge]\nserial = \"/dev/ttyS0\"\nlisten = \"127.0.0.1:1502\"\nallow-ip = [\"10.0.0.1\", \"10.0.0.2\"]\n\
             timeout-ms = 700\nmqtt-prefix = \"file/prefix\"\nrs485-delay-before-us = 5\n",
        );
        let path = f.to_str().unwrap();
        let (cli, m) = parse(&[
            "mbtap",
            "bridge",
            "--config",
            path,
            "--read-only",
            "--allow-ip",
            "127.0.0.1",
            "--timeout-ms",
            "300",
            "--mqtt-prefix",
            "cli/prefix",
        ]);
        let b = merge(&f, cli, Some(&m)).unwrap();
        assert!(b.read_only);
        assert_eq!(b.allow_ips, ["127.0.0.1".parse().unwrap()]);
        assert_eq!(b.timeout_ms, 300);
        assert_eq!(b.mqtt.mqtt_prefix.as_deref(), Some("cli/prefix"));
        assert_eq!(b.rs485.rs485_delay_before_us, 5);
        assert_eq!(b.listen.as_deref(), Some("127.0.0.1:1502"));
        assert_eq!(b.config.as_deref(), Some(f.as_path()));
    }

    #[test]
    fn mistakes_name_the_file_the_line_and_the_setting() {
        assert!(options("[bridge]\nlisten = \"x\"\nbaud = \n", &known_keys()).unwrap_err().contains("line 3"));
        let e = options("[bridge]\nlisten-port = 502\n", &known_keys()).unwrap_err();
        assert!(e.contains("listen-port") && e.contains("listen"), "{e}");
        let path = std::path::Path::new("/nonexistent/bridge.toml");
        let (cli, m) = parse(&["mbtap", "bridge", "--config", "/nonexistent/bridge.toml"]);
        let e = format!("{:#}", merge(path, cli, Some(&m)).unwrap_err());
        assert!(e.contains("/nonexistent/bridge.toml"), "{e}");
    }
}
