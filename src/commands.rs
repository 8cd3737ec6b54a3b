//! The commands at the edge: each takes the parsed command line, does its I/O (files,
//! stdout, serial ports, the runtime) and calls into the library. `main` only dispatches.

use std::io::{self, BufRead, IsTerminal, Write};
use std::process::ExitCode;

use anyhow::Context;

use crate::cli::{
    Command, EventFormatArg, FormatArg, LineArgs, ModeArg, ObserveArg, ParityArg, ProfilesCommand, SerialModeArg,
};
use crate::replay_cmd::{EventFormat, EventWriter};
use mbtap_core::analyzer::SerialMode;
use mbtap_core::decode::{self as decode_cmd, Format};
use mbtap_core::framer::Parity;
use mbtap_core::line_args::LineOverrides;
use mbtap_core::proto::Mode;
use mbtap_core::traffic::{Observation, TrafficConfig};

/// Runs one command; the exit code on success.
///
/// # Errors
/// What went wrong, with context, for `main` to print once.
pub fn run(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::Decode { frames, mode, format, devices, lang } => {
            let profiles = load_devices(&devices)?;
            let lines = if frames.is_empty() {
                io::stdin()
                    .lock()
                    .lines()
                    .collect::<Result<Vec<_>, _>>()
                    .context("reading frames from stdin")?
                    .into_iter()
                    .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
                    .collect()
            } else {
                frames
            };
            let mode = mode.map(|m| match m {
                ModeArg::Rtu => Mode::Rtu,
                ModeArg::Ascii => Mode::Ascii,
                ModeArg::Tcp => Mode::Tcp,
            });
            let format = match format {
                FormatArg::Text => Format::Text,
                FormatArg::Jsonl => Format::Jsonl,
            };
            let stdout = io::stdout();
            let mut out = io::BufWriter::new(stdout.lock());
            let outcome = decode_cmd::run_with_profiles(
                &lines,
                mode,
                format,
                &profiles,
                lang.into(),
                &mut out,
                &mut io::stderr(),
            )?;
            out.flush()?;
            Ok(ExitCode::from(outcome as u8))
        }
        Command::Replay { file, image, line, output } => {
            let input = std::fs::File::open(&file).with_context(|| format!("opening {}", file.display()))?;
            if output.format == EventFormatArg::Tui {
                let (_, settings, _) = overrides(&line).resolve();
                let source = file.display().to_string();
                let ui = TuiSource {
                    profiles: load_devices(&output.devices)?,
                    lang: output.lang.into(),
                    line: settings,
                    pacing: true,
                };
                return ui.run(&source, move |writer, err| {
                    writer.pacer = Some(crate::tui::terminal::Pacer::default());
                    crate::replay_cmd::replay(input, overrides(&line), writer, err)
                        .with_context(|| format!("replaying {}", file.display()))
                });
            }
            let stdout = io::stdout();
            let mut writer = event_writer(io::BufWriter::with_capacity(1 << 16, stdout.lock()), &output)?;
            if image.is_some() {
                writer.image = Some(mbtap_core::profile::image::RegisterImage::default());
            }
            crate::replay_cmd::replay(input, overrides(&line), &mut writer, &mut io::stderr())
                .with_context(|| format!("replaying {}", file.display()))?;
            if let (Some(path), Some(img)) = (&image, writer.image.take()) {
                let text = if path.extension().is_some_and(|e| e == "json") {
                    serde_json::to_string_pretty(&img.to_json(&writer.profiles))?
                } else {
                    img.to_csv(&writer.profiles)
                };
                std::fs::write(path, text).with_context(|| format!("writing the register image {}", path.display()))?;
            }
            writer.finish()?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Sniff { port, line, output, record, duration } => {
            let (mode, settings, latency_ns) = overrides(&line).resolve();
            let opts = crate::sniff_cmd::SniffOptions {
                port,
                mode,
                line: settings,
                latency_ns: line.latency_ms.is_some().then_some(latency_ns),
                record,
                duration: seconds(duration),
            };
            if output.format == EventFormatArg::Tui {
                let source = opts.port.clone();
                let ui = TuiSource {
                    profiles: load_devices(&output.devices)?,
                    lang: output.lang.into(),
                    line: settings,
                    pacing: false,
                };
                return ui
                    .run(&source, move |writer, err| runtime()?.block_on(crate::sniff_cmd::sniff(opts, writer, err)));
            }
            let stdout = io::stdout();
            let mut writer = event_writer(io::LineWriter::new(stdout.lock()), &output)?;
            runtime()?.block_on(crate::sniff_cmd::sniff(opts, &mut writer, &mut io::stderr()))?;
            writer.finish()?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Tap { port, link, line, output, record, duration } => {
            let (mode, settings, latency_ns) = overrides(&line).resolve();
            let opts = crate::tap_cmd::TapOptions {
                port,
                link,
                mode,
                line: settings,
                latency_ns: line.latency_ms.is_some().then_some(latency_ns),
                record,
                duration: seconds(duration),
            };
            if output.format == EventFormatArg::Tui {
                let source = format!("{} ⇄ {}", opts.port, opts.link.display());
                let ui = TuiSource {
                    profiles: load_devices(&output.devices)?,
                    lang: output.lang.into(),
                    line: settings,
                    pacing: false,
                };
                return ui.run(&source, move |writer, err| runtime()?.block_on(crate::tap_cmd::tap(opts, writer, err)));
            }
            let stdout = io::stdout();
            let mut writer = event_writer(io::LineWriter::new(stdout.lock()), &output)?;
            runtime()?.block_on(crate::tap_cmd::tap(opts, &mut writer, &mut io::stderr()))?;
            writer.finish()?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Play { file, port, line, speed } => {
            let (_, settings, _) = overrides(&line).resolve();
            let (packets, bytes) = crate::play_cmd::play(&file, &port, settings, speed)?;
            eprintln!("mbtap: played {packets} packets ({bytes} bytes) into {port}");
            Ok(ExitCode::SUCCESS)
        }
        Command::Demo { format, lang, duration, faults, speed, heard_at } => {
            let faults = fault_list(&faults);
            anyhow::ensure!(speed.is_finite() && speed >= 0.0, "--speed {speed}: expected 0 (no waiting) or more");
            let duration = seconds(duration);
            let opts = crate::demo_cmd::DemoOptions { duration, faults, speed, heard_at };
            let format = format
                .unwrap_or_else(|| if io::stdout().is_terminal() { EventFormatArg::Tui } else { EventFormatArg::Text });
            if format == EventFormatArg::Tui {
                let line = heard_at.unwrap_or_default();
                let ui =
                    TuiSource { profiles: mbtap_core::sim::demo_profiles()?, lang: lang.into(), line, pacing: true };
                return ui.run("demo (simulated bus)", move |writer, _| {
                    runtime()?.block_on(crate::demo_cmd::demo(opts, writer))
                });
            }
            let stdout = io::stdout();
            let mut writer = EventWriter::new(io::LineWriter::new(stdout.lock()), event_format(format));
            writer.lang = lang.into();
            runtime()?.block_on(crate::demo_cmd::demo(opts, &mut writer))?;
            writer.finish()?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Report { file, line, format, devices } => {
            let input = std::fs::File::open(&file).with_context(|| format!("opening {}", file.display()))?;
            let mut health = mbtap_core::health::Health::new(load_devices(&devices)?);
            let mut warnings = Vec::new();
            {
                let mut sink = HealthSink { health: &mut health, warnings: &mut warnings };
                mbtap_core::replay::replay_into(input, overrides(&line), &mut sink)
                    .context("reading the capture")
                    .with_context(|| format!("reading {}", file.display()))?;
            }
            for w in &warnings {
                eprintln!("mbtap: warning: {w}");
            }
            let report = health.report();
            let text = match format {
                crate::cli::ReportFormatArg::Text => report.text(),
                crate::cli::ReportFormatArg::Json => serde_json::to_string_pretty(&report.json())? + "\n",
                crate::cli::ReportFormatArg::Html => {
                    mbtap_core::health::html::render(&report, &file.display().to_string())
                }
            };
            io::stdout().lock().write_all(text.as_bytes())?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Scan { port, bauds, dwell_ms } => {
            if std::fs::metadata(&port).is_ok_and(|m| m.is_file()) {
                let (text, ok) = crate::scan_cmd::scan_file(std::path::Path::new(&port))?;
                io::stdout().lock().write_all(text.as_bytes())?;
                return Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) });
            }
            let dwell = std::time::Duration::from_millis(dwell_ms.max(1));
            let scores = runtime()?.block_on(crate::scan_cmd::scan(&port, &bauds, dwell, &mut io::stderr()))?;
            io::stdout().lock().write_all(crate::scan_cmd::describe(&scores).as_bytes())?;
            Ok(if scores.first().is_some_and(|b| b.valid_frames > 0) { ExitCode::SUCCESS } else { ExitCode::from(1) })
        }
        Command::GenerateConfig => {
            io::stdout().lock().write_all(crate::bridge_config::SAMPLE.as_bytes())?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bridge(args) => {
            let crate::cli::BridgeArgs {
                config: _,
                serial,
                line,
                listen,
                listen_rtu,
                routes,
                timeout_ms,
                retries,
                turnaround_ms,
                broadcast_reply,
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
                answer_as,
                monitor,
                devices,
                duration,
            } = *args;
            let (mode, settings, latency_ns) = overrides(&line).resolve();
            let reverse = if reverse {
                let port = serial.clone().context("--reverse needs --serial PORT: the line to answer on")?;
                let target = target.context("--reverse needs --target HOST:PORT: the Modbus TCP server to reach")?;
                Some(crate::bridge::reverse::ReverseOptions {
                    port,
                    line: settings,
                    mode,
                    units: crate::bridge_cmd::parse_units(answer_as.as_deref().unwrap_or(""))?,
                    target,
                    timeout: std::time::Duration::from_millis(timeout_ms),
                    turnaround: std::time::Duration::from_secs_f64(turnaround_ms.max(0.0) / 1000.0),
                })
            } else {
                None
            };
            anyhow::ensure!(
                reverse.is_some() || listen.is_some() || listen_rtu.is_some(),
                "nothing to listen on: give --listen ADDR:PORT (Modbus TCP) and/or --listen-rtu ADDR:PORT"
            );
            anyhow::ensure!(
                turnaround_ms.is_finite() && turnaround_ms >= 0.0,
                "--turnaround-ms {turnaround_ms}: expected 0 or more"
            );
            anyhow::ensure!(
                idle_timeout.is_finite() && idle_timeout > 0.0,
                "--idle-timeout {idle_timeout}: expected seconds above 0"
            );
            let line_for = |port: String| crate::bridge::line::LineOptions {
                port,
                line: settings,
                mode,
                timeout: std::time::Duration::from_millis(timeout_ms),
                retries,
                turnaround: std::time::Duration::from_secs_f64(turnaround_ms / 1000.0),
                broadcast_reply,
                latency: std::time::Duration::from_nanos(latency_ns),
            };
            let mut lines = Vec::new();
            for r in &routes {
                let (units, port) = crate::bridge_cmd::parse_route(r)?;
                lines.push((units, line_for(port)));
            }
            if let (Some(port), None) = (serial, &reverse) {
                // The plain --serial line serves every unit the routes do not.
                lines.push((1..=247, line_for(port)));
            }
            anyhow::ensure!(
                reverse.is_some() || !lines.is_empty(),
                "no serial line: give --serial PORT or --route UNITS=PORT"
            );
            let allow_functions = if allow_functions.is_empty() {
                None
            } else {
                Some(
                    allow_functions
                        .iter()
                        .map(|f| {
                            let parsed = match f.strip_prefix("0x").or_else(|| f.strip_prefix("0X")) {
                                Some(hex) => u8::from_str_radix(hex, 16).ok(),
                                None => f.parse().ok(),
                            };
                            parsed
                                .with_context(|| format!("--allow-function {f:?}: expected a function code, 3 or 0x03"))
                        })
                        .collect::<anyhow::Result<Vec<u8>>>()?,
                )
            };
            let allow_ips = allow_ips
                .iter()
                .map(|s| s.parse().map_err(|e: String| anyhow::anyhow!("--allow-ip: {e}")))
                .collect::<anyhow::Result<Vec<_>>>()?;
            let opts = crate::bridge_cmd::BridgeOptions {
                lines,
                listen,
                listen_rtu,
                server: crate::bridge::server::ServerOptions {
                    rtu_over_tcp: false,
                    read_only,
                    allow_functions,
                    allow_ips,
                    max_connections,
                    idle_timeout: std::time::Duration::from_secs_f64(idle_timeout),
                    rate_limit,
                    unit_map: crate::bridge_cmd::parse_unit_map(&unit_map)?,
                },
                queue_per_client,
                metrics,
                duration: seconds(duration),
                reverse,
            };
            let profiles = load_devices(&devices)?;
            match monitor {
                Some(EventFormatArg::Tui) => {
                    let ui = TuiSource {
                        profiles,
                        lang: mbtap_core::profile::annotate::Lang::En,
                        line: settings,
                        pacing: false,
                    };
                    ui.run("bridge", move |writer, err| {
                        runtime()?.block_on(crate::bridge_cmd::bridge(opts, Some(writer), err))
                    })
                }
                Some(format) => {
                    let stdout = io::stdout();
                    let mut writer = EventWriter::new(io::LineWriter::new(stdout.lock()), event_format(format));
                    writer.profiles = profiles;
                    runtime()?.block_on(crate::bridge_cmd::bridge(opts, Some(&mut writer), &mut io::stderr()))?;
                    writer.finish()?;
                    Ok(ExitCode::SUCCESS)
                }
                None => {
                    runtime()?.block_on(crate::bridge_cmd::bridge::<io::Sink>(opts, None, &mut io::stderr()))?;
                    Ok(ExitCode::SUCCESS)
                }
            }
        }
        Command::Simulate {
            link,
            devices,
            line,
            duration,
            turnaround_ms,
            paced,
            poll,
            faults,
            heard_at,
            follow_baud,
        } => {
            anyhow::ensure!(
                turnaround_ms.is_finite() && turnaround_ms >= 0.0,
                "--turnaround-ms {turnaround_ms}: expected 0 or more"
            );
            let (mode, settings, _) = overrides(&line).resolve();
            let specs: Vec<String> = if devices.is_empty() {
                crate::simulate_cmd::DEFAULT_DEVICES.iter().map(|(n, a)| format!("{n}@{a}")).collect()
            } else {
                devices
            };
            let devices = specs.iter().map(|d| crate::simulate_cmd::parse_device(d)).collect::<anyhow::Result<_>>()?;
            let opts = crate::simulate_cmd::SimulateOptions {
                link,
                devices,
                line: settings,
                mode,
                duration: seconds(duration),
                turnaround: std::time::Duration::from_secs_f64(turnaround_ms / 1000.0),
                paced,
                poll: poll.then(|| crate::simulate_cmd::PollOptions {
                    faults: fault_list(&faults),
                    heard_at,
                    follow_baud,
                }),
            };
            let rt = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
            rt.block_on(crate::simulate_cmd::simulate(opts, &mut io::stderr()))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Profiles(ProfilesCommand::Check { file }) => {
            let p = load_profile_file(&file)?;
            let count = |t| p.addresses(t).count();
            println!(
                "{}: ok — {} ({}): {} coils, {} discrete inputs, {} holding registers, {} input registers, {} reserved ranges",
                file.display(),
                p.meta.name,
                p.meta.device,
                count(mbtap_core::profile::Table::Coils),
                count(mbtap_core::profile::Table::DiscreteInputs),
                count(mbtap_core::profile::Table::HoldingRegisters),
                count(mbtap_core::profile::Table::InputRegisters),
                p.reserved.len()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Profiles(ProfilesCommand::List) => {
            for name in mbtap_core::profile::builtin::names() {
                if let Some(Ok(p)) = mbtap_core::profile::builtin::get(name) {
                    println!("{name:<8} built-in  {} — {}", p.meta.device, p.meta.document.as_deref().unwrap_or(""));
                }
            }
            if let Some(dir) = user_profile_dir()
                && let Ok(entries) = std::fs::read_dir(&dir)
            {
                let mut files: Vec<_> = entries
                    .flatten()
                    .map(|e| e.path())
                    .filter(|p| p.extension().is_some_and(|e| e == "toml"))
                    .collect();
                files.sort();
                for f in files {
                    let name = f.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
                    match load_profile_file(&f) {
                        Ok(p) => println!("{name:<8} user      {} — {}", p.meta.device, f.display()),
                        Err(e) => println!("{name:<8} user      does not load: {e:#}"),
                    }
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Profiles(ProfilesCommand::Show { profile }) => {
            let p = resolve_profile(&profile)?;
            println!("{} — {}", p.meta.name, p.meta.device);
            for t in [
                mbtap_core::profile::Table::Coils,
                mbtap_core::profile::Table::DiscreteInputs,
                mbtap_core::profile::Table::HoldingRegisters,
                mbtap_core::profile::Table::InputRegisters,
            ] {
                println!("[{}]", t.name());
                for a in p.addresses(t) {
                    if let Some((slot, def)) = p.slot(t, a)
                        && slot.part == 0
                    {
                        let ru = def.name_ru.as_deref().map(|r| format!(" ({r})")).unwrap_or_default();
                        let unit = def.unit.as_deref().map(|u| format!(" [{u}]")).unwrap_or_default();
                        println!("  {a:>5} {}{ru}{unit}", slot.name);
                    }
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Export { file, out, line } => {
            let input = std::fs::File::open(&file).with_context(|| format!("opening {}", file.display()))?;
            let output = std::fs::File::create(&out).with_context(|| format!("creating {}", out.display()))?;
            let export = mbtap_core::capture::export::WiresharkExport::new(io::BufWriter::new(output))?;
            let mut sink = ExportSink { export, error: None };
            mbtap_core::replay::replay_into(input, overrides(&line), &mut sink)
                .context("reading the capture")
                .with_context(|| format!("reading {}", file.display()))?;
            if let Some(e) = sink.error {
                return Err(e).with_context(|| format!("writing {}", out.display()));
            }
            let frames = sink.export.frames;
            sink.export.finish().with_context(|| format!("writing {}", out.display()))?;
            eprintln!("mbtap: exported {frames} frames to {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Generate { out, transactions, seed, line, observe, noise, corrupt, slow, frames: Some(list) } => {
            let _ = (transactions, seed, observe, noise, corrupt, slow);
            let (mode, settings, _) = overrides(&line).resolve();
            let text = std::fs::read_to_string(&list).with_context(|| format!("reading {}", list.display()))?;
            let mut frames = Vec::new();
            for (i, l) in text.lines().enumerate() {
                let l = l.trim();
                if l.is_empty() || l.starts_with('#') {
                    continue;
                }
                let wire = mbtap_core::proto::hexinput::parse_frame_text(l)
                    .map_err(|e| anyhow::anyhow!("{}:{}: {e}", list.display(), i + 1))?;
                frames.push(wire);
            }
            let file = std::fs::File::create(&out).with_context(|| format!("creating {}", out.display()))?;
            let n = crate::generate_cmd::write_frames(
                io::BufWriter::new(file),
                &frames,
                mode,
                settings,
                1_700_000_000_000_000_000,
            )
            .with_context(|| format!("writing {}", out.display()))?;
            eprintln!(
                "mbtap: wrote {} ({} frames, {n} bytes, {settings} {})",
                out.display(),
                frames.len(),
                mode.name()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Generate { out, transactions, seed, line, observe, noise, corrupt, slow, frames: None } => {
            let (_, settings, _) = overrides(&line).resolve();
            let cfg =
                TrafficConfig { seed, line: settings, transactions, noise, corrupt, slow, ..TrafficConfig::default() };
            let model = match observe {
                ObserveArg::PerByte => Observation::PerByte,
                ObserveArg::PerFrame => Observation::PerFrame,
                ObserveArg::Fifo => Observation::FIFO_16550,
                ObserveArg::Usb1 => Observation::USB_1MS,
                ObserveArg::Usb16 => Observation::USB_16MS,
            };
            let file = std::fs::File::create(&out).with_context(|| format!("creating {}", out.display()))?;
            let (chunks, bytes) = crate::generate_cmd::write_capture(io::BufWriter::new(file), &cfg, model)
                .with_context(|| format!("writing {}", out.display()))?;
            eprintln!(
                "mbtap: wrote {} ({transactions} transactions, {bytes} bytes in {chunks} packets, {settings}, {})",
                out.display(),
                model.name()
            );
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Collects frames for the Wireshark export.
struct ExportSink<W: Write> {
    export: mbtap_core::capture::export::WiresharkExport<W>,
    error: Option<io::Error>,
}

impl<W: Write> mbtap_core::analyzer::Sink for ExportSink<W> {
    fn event(&mut self, e: &mbtap_core::analyzer::Event<'_>) {
        if let mbtap_core::analyzer::Event::Frame { frame, role, .. } = *e
            && self.error.is_none()
            && let Err(err) = self.export.frame(frame.t_start, frame.bytes, role, frame.check_ok)
        {
            self.error = Some(err);
        }
    }

    fn warning(&mut self, message: &str) {
        eprintln!("mbtap: warning: {message}");
    }
}

fn load_profile_file(path: &std::path::Path) -> anyhow::Result<mbtap_core::profile::Profile> {
    let src = std::fs::read_to_string(path).with_context(|| format!("reading profile {}", path.display()))?;
    Ok(mbtap_core::profile::load(&path.display().to_string(), &src)?)
}

/// Where users keep their own profiles: `$MBTAP_PROFILE_DIR`, else
/// `$XDG_CONFIG_HOME/mbtap/profiles`, else `~/.config/mbtap/profiles` (the Linux config dir).
fn user_profile_dir() -> Option<std::path::PathBuf> {
    if let Some(d) = std::env::var_os("MBTAP_PROFILE_DIR") {
        return Some(d.into());
    }
    let base = std::env::var_os("XDG_CONFIG_HOME")
        .map(std::path::PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| std::path::PathBuf::from(h).join(".config")))?;
    Some(base.join("mbtap").join("profiles"))
}

/// A built-in profile by name, a user profile by name (`NAME.toml` in the user profile
/// directory), or a profile file by path.
fn resolve_profile(spec: &str) -> anyhow::Result<mbtap_core::profile::Profile> {
    if let Some(p) = mbtap_core::profile::builtin::get(spec) {
        return Ok(p?);
    }
    let path = std::path::Path::new(spec);
    if path.exists() {
        return load_profile_file(path);
    }
    if let Some(dir) = user_profile_dir() {
        let user = dir.join(format!("{spec}.toml"));
        if user.exists() {
            return load_profile_file(&user);
        }
    }
    let dir = user_profile_dir().map_or_else(|| "(no config directory)".to_owned(), |d| d.display().to_string());
    anyhow::bail!(
        "no profile named {spec:?}: built-in profiles are {}; user profiles are NAME.toml files in {dir}; or give the path of a profile file (see docs/profiles.md)",
        mbtap_core::profile::builtin::names().join(", ")
    )
}

/// `--device UNIT=PROFILE` values: a unit address and a built-in name or a profile file.
/// The configuration file's `[devices]` come first; `--device` replaces them unit by unit.
fn load_devices(devices: &[String]) -> anyhow::Result<mbtap_core::profile::Profiles> {
    let mut out = mbtap_core::profile::Profiles::new();
    if let Some(path) = crate::config::default_path() {
        let config = crate::config::load(&path)?;
        for (unit, profile) in &config.devices {
            let u: u8 = unit.trim().parse().with_context(|| format!("{}: unit {unit:?}", path.display()))?;
            out.insert(
                u,
                resolve_profile(profile).with_context(|| format!("{}: device {unit} = {profile:?}", path.display()))?,
            );
        }
    }
    for d in devices {
        let (unit, profile) =
            d.split_once('=').with_context(|| format!("--device {d:?}: expected UNIT=PROFILE, e.g. --device 1=mk4"))?;
        let unit: u8 = unit.trim().parse().with_context(|| format!("--device {d:?}: unit {unit:?} is not 0..=255"))?;
        out.insert(unit, resolve_profile(profile.trim()).with_context(|| format!("--device {d:?}"))?);
    }
    Ok(out)
}

fn event_format(f: EventFormatArg) -> EventFormat {
    match f {
        EventFormatArg::Text => EventFormat::Text,
        EventFormatArg::Jsonl => EventFormat::Jsonl,
        // The UI is set up by the command itself; its writer only counts.
        EventFormatArg::Summary | EventFormatArg::Tui => EventFormat::Summary,
    }
}

/// A single-threaded runtime for one command's I/O.
fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread().enable_all().build().context("starting the runtime")
}

/// What the terminal UI needs to know about a source.
struct TuiSource {
    profiles: mbtap_core::profile::Profiles,
    lang: mbtap_core::profile::annotate::Lang,
    line: mbtap_core::framer::LineSettings,
    /// Recorded or simulated input the UI may pace; live input it can only freeze.
    pacing: bool,
}

impl TuiSource {
    /// Runs `produce` on its own thread, feeding the UI, until the user quits.
    fn run<F>(self, source: &str, produce: F) -> anyhow::Result<ExitCode>
    where
        F: FnOnce(&mut EventWriter<io::Sink>, &mut dyn Write) -> anyhow::Result<()> + Send + 'static,
    {
        use crate::tui::terminal::{NoticeWriter, Shared, run};
        anyhow::ensure!(
            io::stdout().is_terminal(),
            "the terminal UI needs a terminal on stdout; use --format text or jsonl in pipes"
        );
        let model =
            crate::tui::Model::new(self.profiles.clone(), self.lang, self.line, crate::tui::model::DEFAULT_SCROLLBACK);
        let shared = Shared::new(model);
        let feeder = std::sync::Arc::clone(&shared);
        let (profiles, lang) = (self.profiles, self.lang);
        run(&shared, source, self.pacing, move || {
            let mut writer = EventWriter::new(io::sink(), EventFormat::Summary);
            writer.profiles = profiles;
            writer.lang = lang;
            writer.tui = Some(std::sync::Arc::clone(&feeder));
            let mut notices = NoticeWriter(feeder);
            produce(&mut writer, &mut notices)
        })?;
        Ok(ExitCode::SUCCESS)
    }
}

fn overrides(a: &LineArgs) -> LineOverrides {
    LineOverrides {
        mode: a.mode.map(|m| match m {
            SerialModeArg::Rtu => SerialMode::Rtu,
            SerialModeArg::Ascii => SerialMode::Ascii,
        }),
        baud: a.baud,
        data_bits: a.data_bits,
        parity: a.parity.map(|p| match p {
            ParityArg::None => Parity::None,
            ParityArg::Even => Parity::Even,
            ParityArg::Odd => Parity::Odd,
        }),
        stop_bits: a.stop_bits,
        // Milliseconds given by a person; negative or absurd values clamp to 0..=10 s.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        latency_ns: a.latency_ms.map(|ms| (ms.clamp(0.0, 10_000.0) * 1e6) as u64),
    }
}

/// The event writer `sniff`, `tap` and `replay` print through, as their output options say.
fn event_writer<W: io::Write>(out: W, o: &crate::cli::OutputArgs) -> anyhow::Result<EventWriter<W>> {
    let mut writer = EventWriter::new(out, event_format(o.format));
    writer.profiles = load_devices(&o.devices)?;
    writer.lang = o.lang.into();
    if let Some(every) = o.report_every {
        anyhow::ensure!(
            every.is_finite() && every > 0.0,
            "--report-every {every}: expected a number of seconds above 0, e.g. 60"
        );
        // Capped at a year: the report then comes at the end only.
        writer.report_every_ns = Some(std::time::Duration::from_secs_f64(every.min(3.2e7)).as_nanos().try_into()?);
    }
    if o.report || o.report_every.is_some() {
        writer.health = Some(mbtap_core::health::Health::new(writer.profiles.clone()));
    }
    Ok(writer)
}

/// `--duration SECONDS` as a duration (negative as 0, absurdly large capped).
fn seconds(s: Option<f64>) -> Option<std::time::Duration> {
    s.map(|s| std::time::Duration::from_secs_f64(s.clamp(0.0, 1e9)))
}

/// The faults named on the command line (`all`: every one, taking turns).
fn fault_list(args: &[crate::cli::FaultArg]) -> Vec<mbtap_core::sim::bus::Fault> {
    use crate::cli::FaultArg;
    use mbtap_core::sim::bus::Fault;
    args.iter()
        .flat_map(|f| match f {
            FaultArg::Corrupt => vec![Fault::Corrupt],
            FaultArg::Noise => vec![Fault::Noise],
            FaultArg::SlowSlave => vec![Fault::SlowSlave],
            FaultArg::SilentSlave => vec![Fault::SilentSlave],
            FaultArg::Collision => vec![Fault::Collision],
            FaultArg::FastMaster => vec![Fault::FastMaster],
            FaultArg::SecondMaster => vec![Fault::SecondMaster],
            FaultArg::PumpTrip => vec![Fault::PumpTrip],
            FaultArg::All => Fault::ALL.to_vec(),
        })
        .collect()
}

/// The health report as an analyzer sink.
struct HealthSink<'a> {
    health: &'a mut mbtap_core::health::Health,
    warnings: &'a mut Vec<String>,
}

impl mbtap_core::analyzer::Sink for HealthSink<'_> {
    fn event(&mut self, event: &mbtap_core::analyzer::Event<'_>) {
        self.health.event(event);
    }

    fn warning(&mut self, message: &str) {
        self.warnings.push(message.to_owned());
    }
}
