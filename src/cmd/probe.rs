//! `mbtap probe TARGET`: active, read-only discovery of a device's map
//! ([`mbtap_analysis::learn::probe`] decides; this sends): device identification (2B/0E) and the
//! server ID (11) asked once each, then functions 01–04 over the range, at the rate asked for,
//! stopping at the first sign of distress. Never a write.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use mbtap_analysis::learn::probe::{Probe, Reply, Step};
use mbtap_device::profile::Table;
use mbtap_device::query::plan::Read;

use crate::master::exec::{Answer, Op, send};
use crate::master::link::Link;

/// Find which addresses a device answers, reading only (functions 01–04, plus device
/// identification 2B/0E and report server ID 11): present stretches read in the largest blocks
/// the device accepts (exception 03 halves them), the edges of absent ones found by halves. It
/// never writes, keeps to --rate, and stops at the first timeout or busy exception, saying why.
///
/// Example: `mbtap probe 192.0.2.7:502 --unit 3 --range 0-999 -o skeleton.toml`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The device: a serial port (RTU, with the line options), `HOST:PORT` (Modbus TCP) or
    /// `rtu+tcp://HOST:PORT`.
    pub target: String,
    /// The unit (slave) address.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=247))]
    pub unit: u8,
    /// Tables to probe, comma-separated: holding, input, coils, discrete.
    #[arg(long, default_value = "holding,input", value_delimiter = ',')]
    pub tables: Vec<String>,
    /// Addresses to probe, FIRST-LAST (0-based protocol addresses).
    #[arg(long, default_value = "0-999")]
    pub range: String,
    /// Requests per second at most.
    #[arg(long, default_value_t = 20.0, value_parser = crate::cli::numbers::rate)]
    pub rate: f64,
    /// Read every address of absent stretches too (by default up to 3 at a time are stepped
    /// over, so a present stretch shorter than 4 between absent ones may be missed).
    #[arg(long)]
    pub thorough: bool,
    /// How long to wait for each answer, in ms.
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    pub timeout_ms: u64,
    /// Write a skeleton profile of what answered here.
    #[arg(short, long, value_name = "SKELETON.toml")]
    pub output: Option<PathBuf>,
    /// Replace the file if it is already there (without, it is kept and nothing is written).
    #[arg(long)]
    pub force: bool,
    /// What to print.
    #[arg(long, value_enum, default_value_t = Format::Text)]
    pub format: Format,
    #[command(flatten)]
    pub line: crate::cli::args::SerialLineArgs,
}

/// Output of `probe`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Text,
    Json,
}

fn table_of(word: &str) -> anyhow::Result<Table> {
    Ok(match word.trim() {
        "holding" | "holding_registers" => Table::HoldingRegisters,
        "input" | "input_registers" => Table::InputRegisters,
        "coils" | "coil" => Table::Coils,
        "discrete" | "discrete_inputs" => Table::DiscreteInputs,
        other => anyhow::bail!("--tables {other:?}: expected holding, input, coils or discrete"),
    })
}

fn parse_range(s: &str) -> anyhow::Result<(u16, u16)> {
    let (a, b) = s.split_once('-').with_context(|| format!("--range {s:?}: expected FIRST-LAST, e.g. 0-999"))?;
    let a: u16 = a.trim().parse().with_context(|| format!("--range {s:?}: {a:?} is not an address 0–65535"))?;
    let b: u16 = b.trim().parse().with_context(|| format!("--range {s:?}: {b:?} is not an address 0–65535"))?;
    anyhow::ensure!(a <= b, "--range {s:?}: the first address is after the last");
    Ok((a, b))
}

/// Read Device Identification, basic objects from the first (MAP v1.1b3 §6.21: MEI type 0x0E,
/// read code 01, object id 00).
const READ_DEVICE_ID_BASIC: [u8; 4] = [0x2B, 0x0E, 0x01, 0x00];
/// Report Server ID (MAP v1.1b3 §6.17): the function code alone.
const REPORT_SERVER_ID: [u8; 1] = [0x11];

/// Identification, asked once each through the link (the one path, answer check included);
/// `None` where the device does not answer it.
async fn identify(link: &mut Link, unit: u8) -> (Option<Vec<(u8, String)>>, Option<String>) {
    use mbtap_proto::response::{Response, parse_response};
    let mut ident = None;
    if let Ok(pdu) = link.ask(unit, READ_DEVICE_ID_BASIC.to_vec()).await
        && let Ok((_, Response::ReadDeviceIdentification { objects, .. })) = parse_response(&pdu)
    {
        ident = Some(
            objects
                .iter()
                .map(|o| {
                    (o.id, std::str::from_utf8(o.value).map_or_else(|_| format!("{:02X?}", o.value), str::to_owned))
                })
                .collect(),
        );
    }
    let mut server = None;
    if let Ok(pdu) = link.ask(unit, REPORT_SERVER_ID.to_vec()).await
        && let Ok((_, Response::ReportServerId { data })) = parse_response(&pdu)
    {
        // The server id's length is the device's own (§6.17): the first byte is read as the id,
        // the run indicator (0x00 off, 0xFF on) as the second, the rest as text.
        if let [id, running, rest @ ..] = data {
            server = Some(format!(
                "server id 0x{id:02X}, {}, {} byte(s) more: {}",
                if *running == 0xFF { "running" } else { "stopped" },
                rest.len(),
                String::from_utf8_lossy(rest).trim_end_matches('\0')
            ));
        }
    }
    (ident, server)
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let tables = args.tables.iter().map(|t| table_of(t)).collect::<anyhow::Result<Vec<_>>>()?;
    let (first, last) = parse_range(&args.range)?;
    anyhow::ensure!(
        args.rate > 0.0 && args.rate.is_finite(),
        "--rate {}: expected requests per second above 0",
        args.rate
    );
    let timeout = Duration::from_millis(args.timeout_ms);
    // No retries: a device that does not answer is not asked again.
    let mut link = Link::new(&args.target, &args.line, timeout, 0)?;
    let mut probe = Probe::new(&tables, first, last, args.rate);
    if args.thorough {
        probe.max_skip = 0;
    }
    let started = Instant::now();
    let (ident, server) = crate::cmd::runtime()?.block_on(async {
        let id = identify(&mut link, args.unit).await;
        loop {
            let now = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
            match probe.next(now) {
                Step::Read { table, address, quantity } => {
                    let read = Read { target: 0, table, address, quantity };
                    let reply = match send(&mut link, args.unit, Op::Read(read)).await.0 {
                        Answer::Values(v) => Reply::Values(v),
                        Answer::Exception(c) => Reply::Exception(c),
                        Answer::Failed(why) if why.closed() => Reply::Closed(why.to_string()),
                        Answer::Failed(why) => Reply::NoAnswer(why.to_string()),
                        Answer::Done => Reply::NoAnswer("an answer of a write to a read".into()),
                    };
                    probe.reply(&reply);
                }
                Step::WaitUntil(t) => tokio::time::sleep(Duration::from_nanos(t.saturating_sub(now))).await,
                Step::Done => break,
            }
        }
        id
    });
    let took = started.elapsed();
    if let Some(out) = &args.output {
        let skeleton = probe.skeleton(args.unit, &args.target);
        mbtap_device::profile::load("skeleton", &skeleton)
            .context("the skeleton does not load (a bug: please report it)")?;
        crate::output::whole_file::write_whole(
            out,
            skeleton.as_bytes(),
            crate::output::whole_file::Existing::forced(args.force),
        )?;
        eprintln!("mbtap: wrote {}", out.display());
    }
    let mut stdout = std::io::stdout().lock();
    match args.format {
        Format::Text => {
            if let Some(objects) = &ident {
                let shown: Vec<String> = objects.iter().map(|(id, v)| format!("0x{id:02X} {v:?}")).collect();
                writeln!(stdout, "identification: {}", mbtap_analysis::report::format::printable(&shown.join(", ")))?;
            }
            if let Some(s) = &server {
                writeln!(stdout, "report server id: {}", mbtap_analysis::report::format::printable(s))?;
            }
            write!(stdout, "{}", probe.text())?;
            writeln!(stdout, "took {:.1} s at up to {} requests/s", took.as_secs_f64(), args.rate)?;
        }
        Format::Json => {
            let tables: serde_json::Map<String, serde_json::Value> = probe
                .found
                .iter()
                .map(|(t, f)| {
                    let runs: Vec<[u16; 2]> = probe.runs(*t).into_iter().map(|(a, b)| [a, b]).collect();
                    (
                        t.name().to_owned(),
                        serde_json::json!({
                            "unsupported": f.unsupported, "present": runs, "max_block": f.max_block,
                            "refused_block": f.refused_block,
                        }),
                    )
                })
                .collect();
            // Every value read, as `replay --image FILE.json` writes an image: two probe dumps
            // (this output, saved) are what `mbtap diff` compares.
            let image: Vec<serde_json::Value> = probe
                .found
                .iter()
                .flat_map(|(t, f)| {
                    f.present.iter().map(move |(&address, &raw)| {
                        serde_json::json!({"unit": args.unit, "table": t.name(), "address": address, "raw": raw})
                    })
                })
                .collect();
            let doc = serde_json::json!({
                "unit": args.unit, "identification": ident.map(|o| o.into_iter().map(|(id, v)| serde_json::json!({"id": id, "value": v})).collect::<Vec<_>>()),
                "server_id": server, "tables": tables, "requests": probe.requests,
                "assumed_absent": probe.assumed_absent, "stopped": probe.stopped, "seconds": took.as_secs_f64(),
                "image": image,
            });
            writeln!(stdout, "{doc}")?;
        }
    }
    Ok(if probe.stopped.is_some() { ExitCode::FAILURE } else { ExitCode::SUCCESS })
}
