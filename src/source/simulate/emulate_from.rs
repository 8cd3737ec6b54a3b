//! What `mbtap simulate` emulates, from what the user names: a profile at an address
//! (`--device PROFILE@UNIT`: built-in, user, imported or a file) or every unit a recording
//! showed answering (`--from CAPTURE`, `--from CAPTURE@UNITS`), each said on stderr with what
//! it will answer and what it will refuse.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

use anyhow::Context;
use mbtap_device::profile::Table;
use mbtap_sim::{Device, RecordedDevicesBuilder, Slave};

/// Parses `PROFILE@ADDRESS` (`mk4@1`, `./meter.toml@3`, an imported profile's name).
///
/// # Errors
/// When the form, the address (1–247) or the profile is wrong, saying which.
pub fn parse_device(spec: &str) -> anyhow::Result<Device> {
    let (profile, address) = profile_at(spec, "device")?;
    Ok(Device::Profile(Slave::new(Arc::new(profile), address)))
}

/// `PROFILE@ADDRESS`: the profile (built-in, user, imported or a file) and the address 1–247.
///
/// # Errors
/// When the form, the address or the profile is wrong, saying which (`what` names the option).
pub fn profile_at(spec: &str, what: &str) -> anyhow::Result<(mbtap_device::profile::Profile, u8)> {
    let (name, address) =
        spec.rsplit_once('@').with_context(|| format!("{what} {spec:?}: expected PROFILE@ADDRESS, e.g. mk4@1"))?;
    let address: u8 = address
        .parse()
        .ok()
        .filter(|a| (1..=247).contains(a))
        .with_context(|| format!("{what} {spec:?}: the address must be 1–247 (Serial Line v1.02 §2.2)"))?;
    let profile = crate::config::devices::resolve_profile(name).with_context(|| format!("{what} {spec:?}"))?;
    Ok((profile, address))
}

/// Every unit `spec` (`CAPTURE` or `CAPTURE@UNITS`, units as `1,5,17` or `1-4`) showed
/// answering, each a device answering as it did; `notes` gets one paragraph per device.
///
/// # Errors
/// The capture cannot be read; no unit answered in it; a unit asked for is not in it.
pub fn from_capture(
    spec: &str,
    replay_values: bool,
    turnaround_ms: Option<f64>,
    notes: &mut String,
) -> anyhow::Result<Vec<Device>> {
    let (path, wanted) = split_units(spec)?;
    if let Some(image) = crate::source::image_file::load(path)? {
        return from_image(path, &image, wanted.as_ref(), turnaround_ms, notes);
    }
    let input = crate::output::progress::open_capture(path, false)?;
    let mut recorder = RecordedDevicesBuilder::default();
    mbtap_analysis::replay::replay_into(input, mbtap_analysis::line_args::LineOverrides::default(), &mut recorder)
        .with_context(|| format!("--from {}: reading the capture", path.display()))?;
    for w in &recorder.warnings {
        let _ = writeln!(notes, "mbtap: --from {}: {w}", path.display());
    }
    let mut devices = recorder.take_devices();
    for said in recorder.bounds_said() {
        let _ = writeln!(notes, "mbtap: --from {}: {said}", path.display());
    }
    let silent = recorder.silent_units();
    // A capture the reader stopped in (a damaged block) is said as the reader says it, as
    // `replay` does, not as a line where nobody answered.
    if devices.is_empty()
        && let Some(damage) = recorder.warnings.first()
    {
        anyhow::bail!("--from {}: {damage}", path.display());
    }
    anyhow::ensure!(
        !devices.is_empty(),
        "--from {}: no unit answered in this capture ({}): nothing to emulate; record the line while the devices answer",
        path.display(),
        if silent.is_empty() {
            "no requests either".to_owned()
        } else {
            format!("units {} were asked and never answered", join(silent.iter()))
        }
    );
    if let Some(wanted) = &wanted {
        let heard: BTreeSet<u8> = devices.iter().map(mbtap_sim::RecordedDevice::address).collect();
        require_units(path, wanted, &heard, "did not answer in this capture; units that did")?;
        devices.retain(|d| wanted.contains(&d.address()));
    }
    if let Some(said) = recorder.course_said().filter(|_| replay_values) {
        let _ = writeln!(notes, "mbtap: --from {}: {said}", path.display());
    }
    for d in &mut devices {
        if replay_values {
            let course = recorder.course(d.address());
            let _ = writeln!(
                notes,
                "mbtap: unit {}: {} recorded values replayed in their time course, looping",
                d.address(),
                course.len()
            );
            d.replay_values(course);
        }
        describe(path, d, turnaround_ms, notes);
    }
    Ok(devices.into_iter().map(Device::Recorded).collect())
}

/// The units of a register image file (a probe dump, `replay --image`), each a device holding
/// the image's values.
fn from_image(
    path: &Path,
    image: &mbtap_analysis::learn::diff::Image,
    wanted: Option<&BTreeSet<u8>>,
    turnaround_ms: Option<f64>,
    notes: &mut String,
) -> anyhow::Result<Vec<Device>> {
    let units: BTreeSet<u8> = image.keys().map(|&(u, _, _)| u).filter(|u| (1..=247).contains(u)).collect();
    anyhow::ensure!(
        !units.is_empty(),
        "--from {}: no values of units 1–247 in this image: nothing to emulate",
        path.display()
    );
    if let Some(wanted) = wanted {
        require_units(path, wanted, &units, "has no values in this image; units that have")?;
    }
    let mut out = Vec::new();
    for unit in units.into_iter().filter(|u| wanted.is_none_or(|w| w.contains(u))) {
        let values = image
            .range((unit, Table::Coils, 0)..=(unit, Table::InputRegisters, u16::MAX))
            .map(|(&(_, t, a), &raw)| ((t, a), raw))
            .collect();
        let d = mbtap_sim::RecordedDevice::from_image(unit, values);
        describe(path, &d, turnaround_ms, notes);
        out.push(Device::Recorded(d));
    }
    Ok(out)
}

/// `CAPTURE@1,5` → the path and the units; a path that exists as given is taken whole (a file
/// name may hold `@`).
fn split_units(spec: &str) -> anyhow::Result<(&Path, Option<BTreeSet<u8>>)> {
    if Path::new(spec).exists() {
        return Ok((Path::new(spec), None));
    }
    let Some((path, units)) = spec.rsplit_once('@') else {
        anyhow::bail!("--from {spec}: no such file");
    };
    anyhow::ensure!(Path::new(path).exists(), "--from {spec}: no such file {path}");
    let units = mbtap_gateway::parse::parse_units(units)
        .with_context(|| format!("--from {spec}: after @, the units to emulate (1,5,17 or 1-4)"))?;
    anyhow::ensure!(
        !units.is_empty(),
        "--from {spec}: no units after @; give them as 1,5,17 or 1-4, or leave @ out for all"
    );
    Ok((Path::new(path), Some(units.into_iter().collect())))
}

/// Every unit of `wanted` is in `have`, else the error names the missing ones and those there.
fn require_units(path: &Path, wanted: &BTreeSet<u8>, have: &BTreeSet<u8>, why: &str) -> anyhow::Result<()> {
    let missing: Vec<u8> = wanted.difference(have).copied().collect();
    anyhow::ensure!(
        missing.is_empty(),
        "--from {}: unit {} {why}: {}",
        path.display(),
        join(missing.iter()),
        join(have.iter())
    );
    Ok(())
}

fn join<'a>(units: impl Iterator<Item = &'a u8>) -> String {
    units.map(u8::to_string).collect::<Vec<_>>().join(", ")
}

/// `unit 17 (from site.pcapng): holding registers 100–139, input registers 430–441 as last
/// heard; 2 requests refused as recorded; answers after 4.1 ms (median of 80); anything
/// else: exception 02`.
fn describe(path: &Path, d: &mbtap_sim::RecordedDevice, turnaround_ms: Option<f64>, notes: &mut String) {
    let mut held = Vec::new();
    for (table, n) in d.counts() {
        if n > 0 {
            held.push(format!("{n} {}", table_name(table)));
        }
    }
    let refused = d.refusals().count();
    // What it does, not what the recording says, when --turnaround-ms says otherwise.
    let recorded = || {
        d.latency.map_or_else(
            || "no latency measured in it: answers after 3 ms (--turnaround-ms to change)".to_owned(),
            |l| {
                format!(
                    "answers after {:.1} ms (median of {}; 10–90 % {:.1}–{:.1} ms)",
                    ms(l.median_ns),
                    l.samples,
                    ms(l.p10_ns),
                    ms(l.p90_ns)
                )
            },
        )
    };
    let latency = turnaround_ms.map_or_else(recorded, |t| format!("answers after {t} ms (--turnaround-ms)"));
    let _ = writeln!(
        notes,
        "mbtap: emulating unit {} as {} showed it: {} as last heard; {refused} requests refused as recorded; {latency}; what it never showed: exception 02 (01 for a function)",
        d.address(),
        path.display(),
        if held.is_empty() { "no values".to_owned() } else { held.join(", ") },
    );
}

#[allow(clippy::cast_precision_loss)] // a latency in ms, shown to a tenth
fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

const fn table_name(t: Table) -> &'static str {
    match t {
        Table::Coils => "coils",
        Table::DiscreteInputs => "discrete inputs",
        Table::InputRegisters => "input registers",
        Table::HoldingRegisters => "holding registers",
    }
}
