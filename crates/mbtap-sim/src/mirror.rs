//! A device whose values come from another one (`mbtap simulate --mirror`): what to read from
//! the source, and how its values become the served device's registers. Served under the
//! source's own profile, every value is copied register for register; served under another
//! profile (`--as sdm630 --map 'V1=voltage,P=power*1000'`) each named value is read as a number
//! by the source's profile, scaled, and written as the served profile's register holds it — the
//! "fake meter" an inverter that insists on one brand needs. Pure: values in, registers out;
//! the shell reads the source on its freshness period.

use std::collections::BTreeMap;

use mbtap_device::profile::{Profile, Table};
use mbtap_device::query::encode::encode_number;
use mbtap_device::query::items::parse_item;
use mbtap_device::query::resolve::resolve;
use mbtap_device::query::rows::rows;

/// Registers `first..=last` of a table.
pub type Span = (Table, u16, u16);

/// A value to set: a table's address and its raw word.
pub type Set = ((Table, u16), u16);

/// How one served value is made.
#[derive(Debug, Clone, PartialEq)]
enum How {
    /// The source's registers, as they are.
    Copy,
    /// The source's value as a number, times this.
    Scaled(f64),
}

#[derive(Debug, Clone, PartialEq)]
struct Entry {
    served: Span,
    source: Span,
    how: How,
    /// `V1=voltage*1000` as given, for messages.
    spec: String,
}

/// A bad `--map`, saying which part and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("--map {part:?}: {problem}")]
pub struct MapError {
    pub part: String,
    pub problem: String,
}

/// The served device's values from the source's.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MirrorMap {
    entries: Vec<Entry>,
}

impl MirrorMap {
    /// Every value `profile` maps, copied register for register (a device served as itself).
    #[must_use]
    pub fn identity(profile: &Profile) -> Self {
        let mut entries = Vec::new();
        for (&table, slots) in &profile.tables {
            for (&a, slot) in slots {
                let Some(def) = profile.defs.get(slot.def) else { continue };
                if slot.part != 0 {
                    continue;
                }
                let last = a.saturating_add(def.width.max(1) - 1);
                let span = (table, a, last);
                entries.push(Entry { served: span, source: span, how: How::Copy, spec: def.name.clone() });
            }
        }
        Self { entries }
    }

    /// `SERVED=SOURCE[*K|/K],…`: each SERVED a name or address of `served`, each SOURCE one of
    /// `source`, K a number.
    ///
    /// # Errors
    /// A part without `=`, a name neither profile has (with the closest names), a bad factor.
    pub fn parse(spec: &str, served: &Profile, source: &Profile) -> Result<Self, MapError> {
        let mut entries = Vec::new();
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let bad = |problem: String| MapError { part: part.to_owned(), problem };
            let (to, from) =
                part.split_once('=').ok_or_else(|| bad("expected SERVED=SOURCE, e.g. V1=voltage*1000".to_owned()))?;
            let (from, factor) = match from.rsplit_once('*') {
                Some((f, k)) => (f, k.trim().parse::<f64>().ok().filter(|k| k.is_finite())),
                None => match from.rsplit_once('/') {
                    Some((f, k)) => {
                        (f, k.trim().parse::<f64>().ok().filter(|k| k.is_finite() && *k != 0.0).map(|k| 1.0 / k))
                    }
                    None => (from, Some(1.0)),
                },
            };
            let factor =
                factor.ok_or_else(|| bad("the factor after * or / must be a number (not 0 after /)".to_owned()))?;
            let span = |text: &str, p: &Profile, which: &str| -> Result<Span, MapError> {
                let item = parse_item(text.trim(), None).map_err(|e| bad(format!("{which}: {e}")))?;
                let t = resolve(&item, Some(p)).map_err(|e| bad(format!("{which} profile {}: {e}", p.meta.name)))?;
                p.slot(t.table, t.first).ok_or_else(|| {
                    bad(format!("{which} profile {} maps no value at {} {}", p.meta.name, t.table.name(), t.first))
                })?;
                Ok((t.table, t.first, t.last))
            };
            let served_span = span(to, served, "the served")?;
            // One source per served register: a name mapped twice would have the last win, silently.
            if let Some(first) = entries.iter().find(|e: &&Entry| {
                let (t, a, b) = e.served;
                t == served_span.0 && a <= served_span.2 && served_span.1 <= b
            }) {
                return Err(bad(format!("the served registers are already mapped by {:?}: map each once", first.spec)));
            }
            entries.push(Entry {
                served: served_span,
                source: span(from, source, "the source")?,
                how: How::Scaled(factor),
                spec: part.to_owned(),
            });
        }
        if entries.is_empty() {
            return Err(MapError { part: spec.to_owned(), problem: "no SERVED=SOURCE pairs".to_owned() });
        }
        Ok(Self { entries })
    }

    /// What to read from the source: each span once, adjacent ones of a table joined up to the
    /// spec's limits (125 registers, 2000 bits: MAP v1.1b3 §6.1–§6.4).
    #[must_use]
    pub fn reads(&self) -> Vec<Span> {
        let mut spans: Vec<Span> = self.entries.iter().map(|e| e.source).collect();
        spans.sort_unstable_by_key(|&(t, a, _)| (t, a));
        let mut out: Vec<Span> = Vec::new();
        for (t, a, b) in spans {
            let limit = if matches!(t, Table::Coils | Table::DiscreteInputs) { 2000 } else { 125 };
            match out.last_mut() {
                Some((lt, la, lb))
                    if *lt == t
                        && u32::from(a) <= u32::from(*lb) + 1
                        && u32::from(b.max(*lb)) - u32::from(*la) < limit =>
                {
                    *lb = b.max(*lb);
                }
                _ => out.push((t, a, b)),
            }
        }
        out
    }

    /// The served registers from the source's values (`values`: what the reads returned);
    /// values missing from `values`, or not numbers where a number is needed, are left out and
    /// named in the second list.
    #[must_use]
    pub fn apply(
        &self,
        values: &BTreeMap<(Table, u16), u16>,
        served: &Profile,
        source: &Profile,
    ) -> (Vec<Set>, Vec<String>) {
        let mut out = Vec::new();
        let mut missing = Vec::new();
        for e in &self.entries {
            let (st, sa, sb) = e.source;
            let words: Option<Vec<u16>> = (sa..=sb).map(|a| values.get(&(st, a)).copied()).collect();
            let Some(words) = words else {
                missing.push(format!("{}: not read from the source", e.spec));
                continue;
            };
            let (tt, ta, _) = e.served;
            let encoded = match e.how {
                How::Copy => Ok(words),
                How::Scaled(k) => rows(0, st, sa, &words, Some(source))
                    .first()
                    .and_then(|r| r.value.as_f64())
                    .zip(served.slot(tt, ta).map(|(_, d)| d))
                    .ok_or_else(|| "the source's value is not a number".to_owned())
                    .and_then(|(v, def)| encode_number(v * k, def)),
            };
            match encoded {
                Ok(w) => out.extend((ta..).zip(w).map(|(a, v)| ((tt, a), v))),
                // Never clamped: a value the served register cannot hold is not served.
                Err(why) => missing.push(format!("{}: {why}", e.spec)),
            }
        }
        (out, missing)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(name: &str) -> Profile {
        mbtap_device::profile::builtin::get(name).unwrap().unwrap()
    }

    /// A served profile with an f32 at input 0 (volts) and a u16 at 10 (deciwatts at 0.1 scale).
    const SERVED: &str = "[profile]\nname = \"fake-meter\"\ndevice = \"Fake meter\"\n\n\
        [[input_registers]]\naddress = 0\nname = \"V1\"\ntype = \"f32\"\nunit = \"V\"\n\n\
        [[input_registers]]\naddress = 10\nname = \"P\"\ntype = \"u16\"\nscale = 0.1\nunit = \"W\"\n";

    #[test]
    fn a_served_register_mapped_twice_is_refused_naming_the_first_mapping() {
        let served = mbtap_device::profile::loader::load("fake-meter.toml", SERVED).unwrap();
        let e = MirrorMap::parse("V1=input 430, V1=input 431", &served, &profile("mk4")).unwrap_err();
        assert!(e.to_string().contains("already mapped by \"V1=input 430\""), "{e}");
    }

    #[test]
    fn a_value_the_served_register_cannot_hold_is_not_served_and_said() {
        let served = mbtap_device::profile::loader::load("fake-meter.toml", SERVED).unwrap();
        let mk4 = profile("mk4");
        // P is a u16 at 0.1 W: 230.5 V × 1e9 is far beyond 6553.5 W.
        let map = MirrorMap::parse("P=input 430*1000000000", &served, &mk4).unwrap();
        let values = BTreeMap::from([((Table::InputRegisters, 430), 2305)]);
        let (set, missing) = map.apply(&values, &served, &mk4);
        assert!(set.is_empty(), "never clamped to 65535: {set:?}");
        assert!(missing[0].contains("0 to 6553.5"), "{missing:?}");
    }

    #[test]
    fn a_value_is_read_by_one_profile_and_written_by_another() {
        let served = mbtap_device::profile::loader::load("fake-meter.toml", SERVED).unwrap();
        let mk4 = profile("mk4");
        let map = MirrorMap::parse("V1=Phase A (L1) voltage, P=input 430*2", &served, &mk4).unwrap();
        assert_eq!(map.reads(), [(Table::InputRegisters, 430, 430)], "one read for both");
        // MK4 input 430 holds 0.1 V: raw 2305 is 230.5 V.
        let values = BTreeMap::from([((Table::InputRegisters, 430), 2305)]);
        let (set, missing) = map.apply(&values, &served, &mk4);
        assert!(missing.is_empty(), "{missing:?}");
        let [hi, lo] = [(230.5f32.to_bits() >> 16) as u16, (230.5f32.to_bits() & 0xFFFF) as u16];
        // 230.5 × 2 = 461 W at 0.1 W: raw 4610.
        assert_eq!(
            set,
            [((Table::InputRegisters, 0), hi), ((Table::InputRegisters, 1), lo), ((Table::InputRegisters, 10), 4610)]
        );
    }

    #[test]
    fn a_name_neither_profile_has_is_refused_naming_it() {
        let served = mbtap_device::profile::loader::load("fake-meter.toml", SERVED).unwrap();
        let e = MirrorMap::parse("V1=Phase Q voltage", &served, &profile("mk4")).unwrap_err();
        assert!(e.to_string().contains("the source profile mk4"), "{e}");
        let e = MirrorMap::parse("V9=input 430", &served, &profile("mk4")).unwrap_err();
        assert!(e.to_string().contains("the served profile fake-meter"), "{e}");
        assert!(MirrorMap::parse("V1", &served, &profile("mk4")).is_err());
        assert!(MirrorMap::parse("V1=input 430/0", &served, &profile("mk4")).is_err());
    }

    #[test]
    fn served_as_itself_every_register_is_copied() {
        let mk4 = profile("mk4");
        let map = MirrorMap::identity(&mk4);
        assert!(map.reads().iter().all(|&(t, a, b)| {
            let limit = if matches!(t, Table::Coils | Table::DiscreteInputs) { 2000 } else { 125 };
            b >= a && b - a < limit
        }));
        let values = BTreeMap::from([((Table::InputRegisters, 430), 2305)]);
        let (set, missing) = map.apply(&values, &mk4, &mk4);
        assert_eq!(set, [((Table::InputRegisters, 430), 2305)]);
        assert!(!missing.is_empty(), "what was not read is named");
    }
}
