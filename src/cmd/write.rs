//! `mbtap write`: values written by the profile's names, every one checked before anything is
//! sent, and each echoed back by a read.

use std::io::Write as _;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use mbtap_analysis::report::format::printable;
use mbtap_device::query::encode::{Write, encode_write};
use mbtap_device::query::plan::{Plan, Read};
use mbtap_device::query::rows::{rows, short_table};
use mbtap_device::query::{QueryError, items, resolve};

use crate::io::stream::Transport;
use crate::master::link::Link;
use crate::master::{MasterArgs, MasterFormat, exec, show};

/// Write values to a device by the profile's names or by address.
///
/// Every value is checked against the profile before anything is sent (read-only register,
/// documented range, enumeration labels, what the scale can represent); a refusal says why.
/// Each write is read back; the exit status is 1 when any write failed or the device kept
/// another value than the one written (a device that clamps).
/// Example: `mbtap write /dev/ttyUSB0 --device mk4 "Level 2 set point=1.50"`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub master: MasterArgs,
    /// What to write: NAME=VALUE or [TABLE] ADDRESS=VALUE (coils and holding registers); a
    /// label (`"Operating mode=fill by level sensors"`), a number at the profile's scale
    /// (`1.50`), on/off for coils, text for strings; without a profile,
    /// `holding FIRST..LAST=V1,V2,…`.
    #[arg(required = true, value_name = "ITEM=VALUE")]
    pub items: Vec<String>,
    /// Print the frames that would be sent (hex and decoded) and send nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Send values the profile's checks refuse (out of range, read-only, undocumented). Values
    /// that cannot be encoded at all are refused even so.
    #[arg(long)]
    pub force: bool,
}

fn frame(target: &str, unit: u8, pdu: &[u8]) -> (Vec<u8>, mbtap_proto::Mode) {
    let mut out = Vec::new();
    if let Transport::ModbusTcp(_) = Transport::of_device(target) {
        mbtap_proto::encode_tcp(1, unit, pdu, &mut out);
        (out, mbtap_proto::Mode::Tcp)
    } else {
        mbtap_proto::encode_rtu(unit, pdu, &mut out);
        (out, mbtap_proto::Mode::Rtu)
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
}

fn describe(w: &Write, target: &resolve::Target, profile: Option<&mbtap_device::profile::Profile>, unit: u8) -> String {
    let shown = rows(unit, w.table, w.address, &w.words, profile)
        .first()
        .map(|r| format!("{} = {}", r.name.as_deref().unwrap_or("-"), r.shown))
        .unwrap_or_default();
    let raw = w.words.iter().map(u16::to_string).collect::<Vec<_>>().join(",");
    format!("{} {} {shown} (raw {raw}, from {:?})", short_table(w.table), w.address, target.item.text)
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let m = &args.master;
    let profile = m.profile()?;
    let p = profile.as_ref();
    let unit = m.unit(p);
    let parsed = items::parse_items(&args.items)?;
    if let Some(i) = parsed.iter().find(|i| i.value.is_none()) {
        return Err(
            QueryError::Syntax { item: i.text.clone(), problem: "nothing to write: give NAME=VALUE".into() }.into()
        );
    }
    // Every item checked before the first is sent.
    let mut writes = Vec::new();
    for item in &parsed {
        let target = resolve::resolve(item, p)?;
        let w = encode_write(&target, p, args.force)?;
        for o in &w.overridden {
            eprintln!("mbtap: {}: --force: {o}", item.text);
        }
        writes.push((target, w));
    }
    // Unit 0 is a broadcast (Serial Line v1.02 §2.1): every device on the line executes it,
    // none answers, nothing can be read back. Never by accident.
    if unit == 0 && !args.force && !args.dry_run {
        anyhow::bail!(
            "unit 0 is a broadcast: every device on the line would execute this write and none would answer or be read back; give the unit's own address, or add --force to broadcast on purpose"
        );
    }
    let mut out = std::io::stdout().lock();
    if args.dry_run {
        let profiles: mbtap_device::profile::Profiles = p.map(|p| (unit, p.clone())).into_iter().collect();
        for (target, w) in &writes {
            let (bytes, mode) = frame(&m.target, unit, &w.pdu());
            writeln!(out, "would send to unit {unit}: {}", printable(&describe(w, target, p, unit)))?;
            writeln!(out, "  {}", hex(&bytes))?;
            mbtap_analysis::decode::run_with_profiles(
                &[hex(&bytes)],
                Some(mode),
                mbtap_analysis::decode::Format::Text,
                &profiles,
                mbtap_device::profile::annotate::Lang::En,
                &mut out,
                &mut std::io::sink(),
            )?;
        }
        writeln!(out, "dry run: nothing sent")?;
        return Ok(ExitCode::SUCCESS);
    }
    let timeout = Duration::from_millis(m.timeout_ms);
    let mut link = Link::new(&m.target, &m.line, timeout, m.retries)?;
    let format = m.format();
    let rt = crate::cmd::runtime()?;
    let mut failed = false;
    for (target, w) in &writes {
        if unit == 0 {
            // No answer comes to a broadcast: sent once, said as such, nothing read back.
            let _ = rt.block_on(exec::send(&mut link, 0, exec::Op::Write(w)));
            let what = describe(w, target, p, 0);
            writeln!(out, "broadcast {} (no device answers a broadcast; nothing read back)", printable(&what))?;
            continue;
        }
        let (answer, _) = rt.block_on(exec::send(&mut link, unit, exec::Op::Write(w)));
        let what = describe(w, target, p, unit);
        if let Some(problem) = answer.problem() {
            failed = true;
            let f = show::Failure {
                unit,
                item: target.item.text.clone(),
                read: None,
                problem: format!("write refused or lost: {problem}"),
            };
            show::print(format, &[], &[f], &[], &mut out)?;
            continue;
        }
        if format == MasterFormat::Text {
            writeln!(out, "wrote {}", printable(&what))?;
        }
        // The echo: read the same registers back and show what the device kept.
        let quantity = u16::try_from(w.words.len()).unwrap_or(1);
        let plan = Plan {
            reads: vec![Read { target: 0, table: w.table, address: w.address, quantity }],
            skipped: vec![],
            unmapped: vec![],
        };
        let (back, failures) = rt.block_on(exec::read_all(&mut link, unit, std::slice::from_ref(target), &plan, p));
        let kept = back.first().map(|r| r.raw);
        let written = rows(unit, w.table, w.address, &w.words, p).first().map(|r| r.raw);
        let differs = kept.is_some() && kept != written;
        // A write the device did not keep as written (clamped, refused silently) fails the run.
        failed |= !failures.is_empty() || differs;
        match format {
            MasterFormat::Text => {
                for r in &back {
                    let note = if differs { "  ← the device kept another value" } else { "" };
                    writeln!(out, "read back {}{note}", r.line())?;
                }
            }
            MasterFormat::Jsonl => {
                let o = serde_json::json!({
                    "event": "write", "unit": unit, "table": w.table.name(), "address": w.address,
                    "function": w.function, "words": w.words, "item": target.item.text,
                    "read_back": back.iter().map(mbtap_device::query::rows::Row::to_json).collect::<Vec<_>>(),
                    "kept_as_written": !differs,
                });
                writeln!(out, "{o}")?;
            }
        }
        show::print(format, &[], &failures, &[], &mut out)?;
    }
    out.flush().context("writing the results")?;
    Ok(if failed { ExitCode::FAILURE } else { ExitCode::SUCCESS })
}
