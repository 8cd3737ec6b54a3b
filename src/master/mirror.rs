//! `simulate --mirror TARGET`: the served device's values read from another device on its
//! freshness period, through the master's link (serial RTU/ASCII, Modbus TCP, RTU over TCP),
//! and set into the emulated device ([`mbtap_sim::mirror`] says what to read and how each
//! value becomes the served registers). A source that stops answering makes the device answer
//! exception 0B to everything — said once a minute, and when it answers again.

use std::collections::BTreeMap;
use std::sync::{Arc, PoisonError};
use std::time::{Duration, Instant};

use mbtap_device::profile::{Profile, Table};
use mbtap_sim::mirror::MirrorMap;

use crate::source::simulate::emulated::Emulated;

/// What to mirror and how.
#[derive(Debug)]
pub struct MirrorOptions {
    pub target: String,
    pub line: crate::cli::args::SerialLineArgs,
    /// The source's unit on the target, and its profile.
    pub unit: u8,
    pub source: Profile,
    /// The served device's profile (the source's when served as itself).
    pub served: Profile,
    pub map: MirrorMap,
    /// How often the source is read; a value is never older than this when served.
    pub fresh: Duration,
    /// Which of the emulated devices is the mirror.
    pub index: usize,
}

/// The mirrored device (answering 0B until its source is first read) and what its reader
/// needs; `notes` says what it will serve.
///
/// # Errors
/// A bad `PROFILE@UNIT`, `--as` without `--map` for another profile, a `--map` naming what a
/// profile lacks.
#[allow(clippy::too_many_arguments)] // one per command-line option, passed once
pub fn prepare(
    target: &str,
    source: &str,
    served: Option<&str>,
    map: Option<&str>,
    fresh: Duration,
    line: crate::cli::args::SerialLineArgs,
    index: usize,
    notes: &mut String,
) -> anyhow::Result<(mbtap_sim::Device, MirrorOptions)> {
    use std::fmt::Write as _;
    anyhow::ensure!(!fresh.is_zero(), "--fresh: expected a period above 0, e.g. 1s");
    let (source_profile, unit) = crate::source::simulate::emulate_from::profile_at(source, "--mirror-device")?;
    let (served_profile, address) = match served {
        Some(spec) => crate::source::simulate::emulate_from::profile_at(spec, "--as")?,
        None => (source_profile.clone(), unit),
    };
    let map = if let Some(spec) = map {
        MirrorMap::parse(spec, &served_profile, &source_profile)?
    } else {
        anyhow::ensure!(
            served_profile.meta.name == source_profile.meta.name,
            "--as {}: another profile than the source's ({}): give --map SERVED=SOURCE,… to say which value comes from which",
            served_profile.meta.name,
            source_profile.meta.name
        );
        MirrorMap::identity(&source_profile)
    };
    let reads = map.reads();
    // A serial source's line is its own (--mirror-line), said so a mismatch is seen at start;
    // a networked one has no line settings of mbtap's.
    let source_line = match crate::io::stream::Transport::of_device(target) {
        crate::io::stream::Transport::Serial(_) | crate::io::stream::Transport::Rfc2217(_) => {
            let (mode, settings, _) = line.overrides().resolve();
            format!(" on a {settings} {} line", mode.name())
        }
        _ => String::new(),
    };
    let _ = writeln!(
        notes,
        "mbtap: mirroring unit {unit} of {target}{source_line} ({}) as {} at address {address}: {} reads every {fresh:?}; exception 0B until it answers",
        source_profile.meta.name,
        served_profile.meta.name,
        reads.len()
    );
    let slave = mbtap_sim::Slave::new(Arc::new(served_profile.clone()), address);
    let device = mbtap_sim::Device::Mirror { slave, fresh: false };
    let opts = MirrorOptions {
        target: target.to_owned(),
        line,
        unit,
        source: source_profile,
        served: served_profile,
        map,
        fresh,
        index,
    };
    Ok((device, opts))
}

/// Source reads that fail in a row before the device answers 0B: a single lost answer on a
/// busy line does not take the device away.
const FAILURES_BEFORE_STALE: u32 = 3;
/// How often a source that stays away is mentioned.
const SAY_EVERY: Duration = Duration::from_mins(1);

/// Reads the source every `fresh` period until the process ends.
pub async fn run(opts: MirrorOptions, emulated: Arc<Emulated>) {
    let timeout = opts.fresh.clamp(Duration::from_millis(200), Duration::from_secs(3));
    let mut link = match super::link::Link::new(&opts.target, &opts.line, timeout, 0) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("mbtap: --mirror {}: {e:#}", opts.target);
            return;
        }
    };
    let reads = opts.map.reads();
    let mut failures = 0u32;
    let mut said: Option<Instant> = None;
    let mut tick = tokio::time::interval(opts.fresh);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        match read_all(&mut link, opts.unit, &reads).await {
            Ok(values) => {
                let (sets, missing) = opts.map.apply(&values, &opts.served, &opts.source);
                update(&emulated, opts.index, &sets, true);
                if said.take().is_some() {
                    eprintln!("mbtap: --mirror {}: answering again; values are current", opts.target);
                }
                if failures > 0 || !missing.is_empty() {
                    for m in missing.iter().take(3) {
                        eprintln!("mbtap: --mirror {}: {m}", opts.target);
                    }
                }
                failures = 0;
            }
            Err(e) => {
                // The link was reset by the request path where the failure called for it.
                failures = failures.saturating_add(1);
                if failures >= FAILURES_BEFORE_STALE {
                    update(&emulated, opts.index, &[], false);
                    if said.is_none_or(|t| t.elapsed() >= SAY_EVERY) {
                        eprintln!("mbtap: --mirror {}: {e:#}; clients get exception 0B until it answers", opts.target);
                        said = Some(Instant::now());
                    }
                }
            }
        }
    }
}

fn update(emulated: &Emulated, index: usize, sets: &[((Table, u16), u16)], fresh: bool) {
    let mut devices = emulated.devices.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(d) = devices.get_mut(index) {
        d.mirrored(sets, fresh);
    }
}

/// Every span read from the source through the master's one request path (`exec::send` over
/// the link's line: the core's answer check, timeout and late-answer rule); the first failure
/// ends the round.
async fn read_all(
    link: &mut super::link::Link,
    unit: u8,
    reads: &[(Table, u16, u16)],
) -> anyhow::Result<BTreeMap<(Table, u16), u16>> {
    use super::exec::{Answer, Op, send};
    let mut values = BTreeMap::new();
    for &(table, address, last) in reads {
        let read = mbtap_device::query::plan::Read { target: 0, table, address, quantity: last - address + 1 };
        match send(link, unit, Op::Read(read)).await.0 {
            Answer::Values(words) => values.extend((address..).zip(words).map(|(a, v)| ((table, a), v))),
            other => anyhow::bail!(
                "unit {unit}, {} {address}..{last}: {}",
                table.name(),
                other.problem().unwrap_or_else(|| "no values".to_owned())
            ),
        }
    }
    Ok(values)
}
