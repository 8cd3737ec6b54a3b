//! What the built-in master (`simulate --poll`, `demo`) reads from each device: a SCADA-like
//! poll list for the built-in devices, and for any other profile its mapped runs.

/// What a master typically polls on each built-in device (function, start, quantity).
fn builtin(profile: &str) -> &'static [(u8, u16, u16)] {
    match profile {
        // Phase voltages and their average; state and alarm words; holding set points; coils.
        // The newest alarm-log record.
        "mk4" => &[(0x04, 430, 4), (0x04, 400, 10), (0x03, 100, 10), (0x01, 0, 19), (0x04, 500, 17)],
        // Phase currents, then the first trip record (MKZP: holding registers only).
        "mkzp" => &[(0x03, 50, 8), (0x03, 128, 17)],
        // Totals, the first level-sensor slot, the first flow meter.
        "display" => &[(0x04, 0, 4), (0x04, 4, 4), (0x04, 44, 22)],
        _ => &[],
    }
}

/// What a master polls on a device whose profile has no poll list here (an imported or user
/// profile): its mapped runs, table by table, each read within the spec's limits (MAP v1.1b3
/// §6.1–§6.4: 2000 bits, 125 registers) — at most [`GENERIC_POLLS`], a SCADA's poll list, not a scan.
fn runs_of(profile: &mbtap_device::profile::Profile) -> Vec<(u8, u16, u16)> {
    use mbtap_device::profile::Table;
    let mut out = Vec::new();
    for (table, function, limit) in [
        (Table::Coils, 0x01, 2000u16),
        (Table::DiscreteInputs, 0x02, 2000),
        (Table::HoldingRegisters, 0x03, 125),
        (Table::InputRegisters, 0x04, 125),
    ] {
        let mut run: Option<(u16, u16)> = None;
        for a in profile.addresses(table) {
            run = match run {
                Some((first, last)) if last.checked_add(1) == Some(a) && a - first < limit => Some((first, a)),
                Some((first, last)) => {
                    out.push((function, first, last - first + 1));
                    Some((a, a))
                }
                None => Some((a, a)),
            };
        }
        if let Some((first, last)) = run {
            out.push((function, first, last - first + 1));
        }
    }
    out.truncate(GENERIC_POLLS);
    out
}

/// Reads per device in a generic poll list.
const GENERIC_POLLS: usize = 8;

/// The poll list of a device with `profile`: (function, start, quantity) reads.
#[must_use]
pub fn poll_list(profile: &mbtap_device::profile::Profile) -> Vec<(u8, u16, u16)> {
    let listed = builtin(&profile.meta.name);
    if listed.is_empty() { runs_of(profile) } else { listed.to_vec() }
}
