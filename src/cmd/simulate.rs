//! `mbtap simulate`: emulated devices — from profiles or recordings — on a pseudo-terminal for
//! a Modbus master, behind the bridge's Modbus TCP/UDP listeners, or the whole line (master
//! too) for a listener (the I/O: [`crate::source::simulate`], [`crate::bridge::emulated`]).

use std::fmt::Write as _;

use anyhow::Context as _;
use std::io;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use mbtap_analysis::framer::LineSettings;

use crate::cli::args::{FaultArg, LineArgs, fault_list};
use crate::source::simulate::emulate_from;

#[derive(Debug, clap::Args)]
// Command-line switches are bools by nature; each is an independent option, not a state.
#[allow(clippy::struct_excessive_bools)]
/// Emulated devices: point a Modbus master (or mbtap) at --link, or a Modbus TCP client at --listen.
pub struct Args {
    /// Where to create the pseudo-terminal link for the master (default /tmp/mbtap-bus when no
    /// --listen is given).
    #[arg(long)]
    pub link: Option<PathBuf>,
    /// A device from a profile, `PROFILE@ADDRESS`: built-in (mk4, display, mkzp), a user or
    /// imported profile's name, or a profile file (repeatable; default: mk4@1 display@5 mkzp@17).
    #[arg(long = "device", value_name = "PROFILE@ADDRESS")]
    pub devices: Vec<String>,
    /// Every unit a recording (pcap/pcapng) showed answering, answering as it did: the values
    /// last heard, the exceptions it gave, its identity answers and its latency;
    /// `CAPTURE@1,5` for some of its units (repeatable).
    #[arg(long = "from", value_name = "CAPTURE[@UNITS]")]
    pub from: Vec<String>,
    /// With --from: serve the recording's values in their recorded time course (as first heard,
    /// changing when they changed, looping) instead of as last heard.
    #[arg(long, requires = "from")]
    pub replay_values: bool,
    /// A device whose values are read from another one: a serial port, `HOST:PORT` (Modbus TCP)
    /// or `rtu+tcp://HOST:PORT`; with --mirror-device, and --as/--map to serve it under
    /// another profile (a serial target's line: --mirror-line, else the line options).
    #[arg(long, value_name = "TARGET", requires = "mirror_device")]
    pub mirror: Option<String>,
    /// The mirrored device's profile and unit on the target: `PROFILE@UNIT`.
    #[arg(long, value_name = "PROFILE@UNIT", requires = "mirror")]
    pub mirror_device: Option<String>,
    /// Serve the mirrored device as this profile at this address (default: as itself, at its
    /// unit): `sdm630@2`. Needs --map unless it is the same profile.
    #[arg(long = "as", value_name = "PROFILE@ADDRESS", requires = "mirror")]
    pub as_device: Option<String>,
    /// Which served value comes from which source value: `V1=voltage,P=power*1000` (names or
    /// addresses of the served profile = of the source's, times or divided by a factor).
    #[arg(long, value_name = "SERVED=SOURCE,…", requires = "as_device")]
    pub map: Option<String>,
    /// The mirrored device's own serial line, apart from the one the devices are served on:
    /// `"9600 8N1"` (baud, data bits, parity, stop bits) [default: the line options].
    #[arg(long, value_name = "SETTINGS", requires = "mirror")]
    pub mirror_line: Option<LineSettings>,
    /// The mirrored device's framing, RTU or ASCII [default: --mode's].
    #[arg(long, value_enum, value_name = "MODE", requires = "mirror")]
    pub mirror_mode: Option<crate::cli::args::SerialModeArg>,
    /// How often the mirrored device is read; no value served is older [default: 1s].
    #[arg(long, value_name = "DURATION", value_parser = crate::cli::args::duration_arg, requires = "mirror")]
    pub fresh: Option<std::time::Duration>,
    /// Set the devices' values from an MQTT broker (`mqtt://HOST[:PORT]`, `mqtts://…`): publish
    /// `NAME=VALUE` to `PREFIX/unit/U/set` (or a value to `PREFIX/unit/U/TABLE/ADDRESS/set`), as
    /// `watch --mqtt-writes` takes them; the next read sees it.
    #[arg(long, value_name = "URL")]
    pub values_from: Option<String>,
    /// The topic prefix for --values-from [default: mbtap/HOSTNAME/simulate].
    #[arg(long, value_name = "TOPIC", requires = "values_from")]
    pub values_prefix: Option<String>,
    /// Serve the devices on this serial port (a USB adapter, a UART), as slaves on its line, with
    /// the line options and --rs485 direction control: the inverter's port of a fake meter.
    #[arg(long, value_name = "PORT")]
    pub serial: Option<String>,
    #[command(flatten)]
    pub rs485: crate::io::rs485::Rs485Args,
    /// Serve the devices to Modbus TCP clients here (`127.0.0.1:1502`; port 0 picks one), through
    /// the bridge's admission, queue and limits.
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen: Option<String>,
    /// Refuse every request that could change a device (writes, diagnostics that restart or
    /// silence it, anything not known to be harmless) with exception 01, on every front: a device
    /// anyone may read and nobody may write.
    #[arg(long)]
    pub read_only: bool,
    #[command(flatten)]
    pub audit: crate::output::audit::AuditArgs,
    /// Let broadcast writes (unit 0) from TCP, UDP and serial-front clients reach the devices, as
    /// `bridge --allow-broadcast` does; without it they are refused with exception 01 (one rule
    /// for both).
    #[arg(long)]
    pub allow_broadcast: bool,
    /// Serve them as RTU frames over TCP here.
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen_rtu: Option<String>,
    /// Serve them to Modbus UDP clients here.
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen_udp: Option<String>,
    #[command(flatten)]
    pub line: LineArgs,
    /// Stop after this long: `90s`, `2min`, `1h`, `500ms` (a bare number is seconds).
    #[arg(long, value_name = "DURATION", value_parser = crate::cli::args::duration_arg)]
    pub duration: Option<std::time::Duration>,
    /// A device's time from the end of a request to its answer, ms (default: a recording's
    /// own median, 3 ms for a profile's device).
    #[arg(long, value_parser = crate::cli::numbers::millis)]
    pub turnaround_ms: Option<f64>,
    /// Take the line's time when answering: requests end when their characters would have
    /// crossed the line, answers leave at the character rate.
    #[arg(long)]
    pub paced: bool,
    /// Echo every byte the master sends back to it before the answer, as a half-duplex adapter
    /// whose receiver stays on does (for `bridge --echo`).
    #[arg(long)]
    pub echo: bool,
    /// Play the master too: poll the devices and put the whole line on the pseudo-terminal,
    /// paced at the line's character rate, for a listener (`mbtap sniff LINK`).
    #[arg(long, conflicts_with_all = ["from", "listen", "listen_rtu", "listen_udp", "serial", "mirror"])]
    pub poll: bool,
    /// With --poll: inject a fault into every fourth transaction (repeatable).
    #[arg(long = "fault", value_enum, requires = "poll")]
    pub faults: Vec<FaultArg>,
    /// With --poll: the listener's UART settings when they are not the line's ("9600 8N1").
    #[arg(long, value_name = "SETTINGS", requires = "poll", conflicts_with = "follow_baud")]
    pub heard_at: Option<LineSettings>,
    /// With --poll: hear the line at the baud rate the listener set on the pseudo-terminal
    /// (as `mbtap scan` reopens it at each rate). A pty keeps the baud rate and odd parity
    /// of its termios but not the character size or parity enable, so only the rate follows.
    #[arg(long, requires = "poll")]
    pub follow_baud: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let Args {
        link,
        devices,
        from,
        replay_values,
        mirror,
        mirror_device,
        as_device,
        map,
        mirror_line,
        mirror_mode,
        fresh,
        values_from,
        values_prefix,
        serial,
        rs485,
        listen,
        listen_rtu,
        listen_udp,
        read_only,
        audit,
        allow_broadcast,
        line,
        duration,
        turnaround_ms,
        paced,
        echo,
        poll,
        faults,
        heard_at,
        follow_baud,
    } = args;
    if let Some(ms) = turnaround_ms {
        anyhow::ensure!(ms.is_finite() && ms >= 0.0, "--turnaround-ms {ms}: expected 0 or more");
    }
    let (mode, settings, _) = line.overrides().resolve();
    let specs: Vec<String> = if devices.is_empty() && from.is_empty() && mirror.is_none() {
        crate::source::simulate::DEFAULT_DEVICES.iter().map(|(n, a)| format!("{n}@{a}")).collect()
    } else {
        devices
    };
    let mut emulated: Vec<mbtap_sim::Device> =
        specs.iter().map(|d| emulate_from::parse_device(d)).collect::<anyhow::Result<_>>()?;
    let mut notes = String::new();
    for spec in &from {
        emulated.extend(emulate_from::from_capture(spec, replay_values, turnaround_ms, &mut notes)?);
    }
    let mirroring = match (&mirror, &mirror_device) {
        (Some(target), Some(source)) => {
            let (device, opts) = crate::master::mirror::prepare(
                target,
                source,
                as_device.as_deref(),
                map.as_deref(),
                fresh.unwrap_or(std::time::Duration::from_secs(1)),
                // The source's own line when given, apart from the served one's.
                match mirror_line {
                    Some(whole) => crate::cli::args::SerialLineArgs::whole(whole, mirror_mode.or(line.serial.mode)),
                    None => crate::cli::args::SerialLineArgs {
                        mode: mirror_mode.or(line.serial.mode),
                        ..line.serial.clone()
                    },
                },
                emulated.len(),
                &mut notes,
            )?;
            emulated.push(device);
            Some(opts)
        }
        _ => None,
    };
    refuse_two_on_one_address(&emulated)?;
    for d in &emulated {
        if let mbtap_sim::Device::Profile(s) = d {
            let _ = writeln!(notes, "mbtap: simulating {} at address {}", s.profile().meta.name, s.address());
        }
    }
    eprint!("{notes}");
    // On a real bus the emulated devices answer at their own addresses only: another unit's
    // request is another slave's to answer, as a real slave stays silent for it.
    let own_units: std::collections::BTreeSet<u8> = emulated.iter().map(mbtap_sim::Device::address).collect();
    let shared = Arc::new(crate::source::simulate::emulated::Emulated {
        devices: Mutex::new(emulated),
        started: Instant::now(),
        turnaround: turnaround_ms.map(|ms| Duration::from_secs_f64(ms / 1000.0)),
        usual_turnaround: crate::source::simulate::DEFAULT_TURNAROUND,
        read_only,
    });
    let listening = listen.is_some() || listen_rtu.is_some() || listen_udp.is_some() || serial.is_some();
    if let Some(port) = &serial {
        rs485.prepare(&crate::io::serial::resolve_port(port).with_context(|| format!("--serial {port}"))?)?;
    }
    let link = link.or_else(|| (!listening).then(|| PathBuf::from("/tmp/mbtap-bus")));
    let audit = audit.open()?;
    let opts = crate::source::simulate::SimulateOptions {
        link: link.clone(),
        devices: Arc::clone(&shared),
        line: settings,
        mode,
        duration,
        paced,
        echo,
        poll: poll.then(|| crate::source::simulate::PollOptions { faults: fault_list(&faults), heard_at, follow_baud }),
        audit: audit.clone(),
    };
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    rt.block_on(async move {
        if let Some(m) = mirroring {
            tokio::spawn(crate::master::mirror::run(m, Arc::clone(&shared)));
        }
        if let Some(url) = &values_from {
            crate::publish::values_from::start(url, values_prefix.as_deref(), Arc::clone(&shared), audit.clone())?;
        }
        let served = async {
            if !listening {
                return std::future::pending().await;
            }
            let fronts = crate::bridge::run::EmulatedFronts {
                listen,
                listen_rtu,
                listen_udp,
                listen_serial: serial.map(|port| crate::bridge::serial_front::SerialFront {
                    port,
                    line: settings,
                    mode,
                    turnaround: Duration::ZERO,
                    rs485,
                    answer_as: own_units,
                    option: "simulate --serial",
                }),
            };
            let policy = mbtap_gateway::admit::Policy { read_only, broadcast: allow_broadcast, ..Default::default() };
            let mut bridge =
                crate::bridge::run::BridgeOptions::emulating(shared, settings, mode, duration, fronts, policy);
            bridge.audit = audit;
            crate::bridge::run::bridge::<io::Sink>(bridge, None, &mut io::stderr()).await
        };
        let on_pty = async {
            match &link {
                Some(path) => crate::source::simulate::simulate(opts, path, &mut io::stderr()).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            r = served => r,
            r = on_pty => r,
        }
    })?;
    Ok(ExitCode::SUCCESS)
}

/// Two devices on one address would both answer: refused before anything is served.
fn refuse_two_on_one_address(devices: &[mbtap_sim::Device]) -> anyhow::Result<()> {
    let mut seen = std::collections::BTreeSet::new();
    for d in devices {
        anyhow::ensure!(
            seen.insert(d.address()),
            "two devices at address {}: each address answers once on a line (give another PROFILE@ADDRESS, or CAPTURE@UNITS to leave one out)",
            d.address()
        );
    }
    Ok(())
}
