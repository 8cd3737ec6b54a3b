//! `mbtap read`: values from a device, by the profile's names or by address, once.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use mbtap_device::query::{items, plan, resolve};

use crate::master::{MasterArgs, exec, link::Link, show};

/// Read values from a device by the profile's names, addresses or ranges.
///
/// Examples: `mbtap read /dev/ttyUSB0 --device mk4 "Phase A (L1) voltage" 430..433 "Operating mode"`,
/// `mbtap read 10.0.0.5:502 --unit 17 --device mkzp holding 50..60`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub master: MasterArgs,
    /// What to read: a name from the profile (any case, English or the document's language),
    /// an ADDRESS or a range FIRST..LAST (LAST included), each optionally after a table word:
    /// coils, discrete, holding, input (needed when the profile does not settle it).
    #[arg(required = true, value_name = "ITEM")]
    pub items: Vec<String>,
}

/// The plan for `items`, or the first problem with one of them.
pub fn prepare(
    items: &[String],
    profile: Option<&mbtap_device::profile::Profile>,
) -> anyhow::Result<(Vec<resolve::Target>, plan::Plan)> {
    let parsed = items::parse_items(items)?;
    let targets = parsed.iter().map(|i| resolve::resolve(i, profile)).collect::<Result<Vec<_>, _>>()?;
    let plan = plan::plan(&targets, profile)?;
    for &(i, table, a, b) in &plan.skipped {
        let item = targets.get(i).map(|t| t.item.text.as_str()).unwrap_or_default();
        eprintln!(
            "mbtap: {item}: {} {a}..{b} reserved by the device's document, not read",
            mbtap_device::query::rows::short_table(table)
        );
    }
    for &(i, table, a, b) in &plan.unmapped {
        let item = targets.get(i).map(|t| t.item.text.as_str()).unwrap_or_default();
        eprintln!(
            "mbtap: {item}: {} {a}..{b} not in the profile's map, not read",
            mbtap_device::query::rows::short_table(table)
        );
    }
    Ok((targets, plan))
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let m = &args.master;
    if m.sunspec() {
        return run_sunspec(args);
    }
    let profile = m.profile()?;
    let unit = m.unit(profile.as_ref());
    let (targets, plan) = prepare(&args.items, profile.as_ref())?;
    let timeout = Duration::from_millis(m.timeout_ms);
    let mut link = Link::new(&m.target, &m.line, timeout, m.retries)?;
    let (rows, failures) =
        crate::cmd::runtime()?.block_on(exec::read_all(&mut link, unit, &targets, &plan, profile.as_ref()));
    let mut failures = failures;
    if let Some(hint) = m.unit_hint(profile.as_ref()) {
        // Every read failed at an address the user did not choose: the device may be elsewhere,
        // not the register wrong (the error blamed the register).
        if rows.is_empty() {
            for f in &mut failures {
                f.problem = format!("{}; {hint}", f.problem);
            }
        }
    }
    show::print(m.format(), &rows, &failures, &[], &mut std::io::stdout().lock()).context("writing the values")?;
    Ok(if failures.is_empty() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

/// `read --device sunspec`: the chain discovered, the points read by `MODEL.POINT`.
fn run_sunspec(args: &Args) -> anyhow::Result<ExitCode> {
    let m = &args.master;
    let unit = m.unit.unwrap_or(1);
    let timeout = Duration::from_millis(m.timeout_ms);
    let mut link = Link::new(&m.target, &m.line, timeout, m.retries)?;
    let (rows, failures) =
        crate::cmd::runtime()?.block_on(crate::master::sunspec::read_items(&mut link, unit, &args.items))?;
    show::print(m.format(), &rows, &failures, &[], &mut std::io::stdout().lock()).context("writing the values")?;
    Ok(if failures.is_empty() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}
