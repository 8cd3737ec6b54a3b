//! The bridge's option values as written on the command line and in its file: routes, unit
//! lists, function codes, unit maps. A leaf: the modules that read options (cache, timing,
//! roles, priorities) take their parsers from here, not from the orchestrator that imports them
//! all (that made the files of `src/bridge/` one import circle). Each error names the
//! option's value and what is expected.

use std::collections::BTreeMap;
use std::ops::RangeInclusive;

use crate::BadValue;

/// Parses `FIRST-LAST=PORT` or `UNIT=PORT` (`--route 1-10=/dev/ttyUSB0`).
///
/// # Errors
/// When the form or the unit range (1–247) is wrong, saying which.
pub fn parse_route(spec: &str) -> Result<(RangeInclusive<u8>, String), BadValue> {
    let (units, port) = spec
        .split_once('=')
        .ok_or_else(|| BadValue(format!("route {spec:?}: expected UNITS=PORT, e.g. 1-10=/dev/ttyUSB0")))?;
    let (a, b) = units.split_once('-').unwrap_or((units, units));
    let unit = |s: &str| {
        s.trim()
            .parse::<u8>()
            .ok()
            .filter(|u| (1..=247).contains(u))
            .ok_or_else(|| BadValue(format!("route {spec:?}: units must be 1–247 (Serial Line v1.02 §2.2)")))
    };
    let (a, b) = (unit(a)?, unit(b)?);
    if a > b {
        return Err(BadValue(format!("route {spec:?}: the range runs backwards")));
    }
    if port.trim().is_empty() {
        return Err(BadValue(format!("route {spec:?}: no port after '='")));
    }
    Ok((a..=b, port.trim().to_owned()))
}

/// Parses a unit list `1,5,10-20` (empty: none, meaning all).
///
/// # Errors
/// When an item is not a unit 1–247 or a range of them.
pub fn parse_units(spec: &str) -> Result<std::collections::BTreeSet<u8>, BadValue> {
    let mut out = std::collections::BTreeSet::new();
    for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (a, b) = item.split_once('-').unwrap_or((item, item));
        let unit =
            |s: &str| {
                s.trim().parse::<u8>().ok().filter(|u| (1..=247).contains(u)).ok_or_else(|| {
                    BadValue(format!("units {spec:?}: {item:?} is not a unit 1–247 or a range like 10-20"))
                })
            };
        let (a, b) = (unit(a)?, unit(b)?);
        if a > b {
            return Err(BadValue(format!("units {spec:?}: {item:?} runs backwards")));
        }
        out.extend(a..=b);
    }
    Ok(out)
}

/// A function code as written: decimal (`3`) or hex (`0x03`).
#[must_use]
pub fn parse_function_code(s: &str) -> Option<u8> {
    let s = s.trim();
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u8::from_str_radix(hex, 16).ok(),
        None => s.parse().ok(),
    }
}

/// A comma-separated list of function codes (`3,4,0x10`).
#[must_use]
pub fn parse_function_codes(list: &str) -> Option<std::collections::BTreeSet<u8>> {
    list.split(',').map(parse_function_code).collect()
}

/// Parses `TCP=SERIAL` unit mappings (`--map-unit 10=1`).
///
/// # Errors
/// When a side is not a unit id.
pub fn parse_unit_map(specs: &[String]) -> Result<BTreeMap<u8, u8>, BadValue> {
    specs
        .iter()
        .map(|s| {
            let (a, b) =
                s.split_once('=').ok_or_else(|| BadValue(format!("unit map {s:?}: expected TCP_UNIT=SERIAL_UNIT")))?;
            let unit = |v: &str| {
                v.trim().parse::<u8>().map_err(|_| BadValue(format!("unit map {s:?}: {v:?} is not a unit id 0–255")))
            };
            let (a, b) = (unit(a)?, unit(b)?);
            Ok((a, b))
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn routes_and_unit_maps_parse_or_say_what_is_wrong() {
        assert_eq!(parse_route("1-10=/dev/ttyUSB0").unwrap(), (1..=10, "/dev/ttyUSB0".to_owned()));
        assert_eq!(parse_route("17=/dev/ttyS1").unwrap(), (17..=17, "/dev/ttyS1".to_owned()));
        for bad in ["1-10", "0-5=/dev/x", "10-1=/dev/x", "1-300=/dev/x", "5="] {
            let e = parse_route(bad).unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
        assert_eq!(parse_unit_map(&["10=1".into(), "11=2".into()]).unwrap(), BTreeMap::from([(10, 1), (11, 2)]));
        assert_eq!(parse_units("1,5, 10-12").unwrap().into_iter().collect::<Vec<_>>(), [1, 5, 10, 11, 12]);
        assert!(parse_units("").unwrap().is_empty());
        for bad in ["0", "1-300", "x", "9-3"] {
            assert!(parse_units(bad).is_err(), "{bad}");
        }
        assert!(parse_unit_map(&["x=1".into()]).unwrap_err().to_string().contains("x=1"));
    }
}
