//! A value's unit as Home Assistant spells it, with the device class and state class that go
//! with it (without them Home Assistant keeps no long-term statistics and the Energy dashboard
//! offers nothing; a sheet's `Volts` or `kWH` is unknown to it, its `V` and `kWh` known).
//!
//! The classes are Home Assistant's `SensorDeviceClass` and `SensorStateClass` values; each unit
//! here is one that class accepts. An energy unit is `total_increasing` (a meter's register
//! only grows, and the Energy dashboard takes exactly those); every other known unit is a
//! `measurement`. A unit not known keeps its text and gets no class: nothing is guessed. (Flow
//! rates get no device class: `volume_flow_rate` is missing from Home Assistant releases its
//! schema check here refused it with.)

/// What Home Assistant is told of a value with a known unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HaClass {
    /// The unit as Home Assistant spells it.
    pub unit: &'static str,
    pub device_class: Option<&'static str>,
    pub state_class: &'static str,
}

const fn m(unit: &'static str, device_class: Option<&'static str>) -> HaClass {
    HaClass { unit, device_class, state_class: "measurement" }
}

const fn total(unit: &'static str, device_class: Option<&'static str>) -> HaClass {
    HaClass { unit, device_class, state_class: "total_increasing" }
}

/// The unit spellings known (lower case, no spaces) and what they are.
const KNOWN: &[(&[&str], HaClass)] = &[
    (&["v", "volt", "volts", "vac", "vdc"], m("V", Some("voltage"))),
    (&["mv", "millivolt", "millivolts"], m("mV", Some("voltage"))),
    (&["a", "amp", "amps", "ampere", "amperes"], m("A", Some("current"))),
    (&["ma", "milliamp", "milliamps"], m("mA", Some("current"))),
    (&["w", "watt", "watts"], m("W", Some("power"))),
    (&["kw", "kilowatt", "kilowatts"], m("kW", Some("power"))),
    (&["va"], m("VA", Some("apparent_power"))),
    (&["kva"], m("kVA", Some("apparent_power"))),
    (&["var"], m("var", Some("reactive_power"))),
    (&["kvar"], m("kvar", Some("reactive_power"))),
    (&["wh"], total("Wh", Some("energy"))),
    (&["kwh"], total("kWh", Some("energy"))),
    (&["mwh"], total("MWh", Some("energy"))),
    (&["varh"], total("varh", None)),
    (&["kvarh"], total("kvarh", None)),
    (&["vah"], total("VAh", None)),
    (&["kvah"], total("kVAh", None)),
    (&["hz", "hertz"], m("Hz", Some("frequency"))),
    (&["°c", "℃", "degc", "degreesc", "celsius", "°celsius"], m("°C", Some("temperature"))),
    (&["°f", "℉", "degf", "degreesf", "fahrenheit"], m("°F", Some("temperature"))),
    (&["%", "percent"], m("%", None)),
    (&["bar"], m("bar", Some("pressure"))),
    (&["mbar"], m("mbar", Some("pressure"))),
    (&["pa"], m("Pa", Some("pressure"))),
    (&["kpa"], m("kPa", Some("pressure"))),
    (&["hpa"], m("hPa", Some("pressure"))),
    (&["psi"], m("psi", Some("pressure"))),
    (&["m³/h", "m3/h", "m^3/h"], m("m³/h", None)),
    (&["l/min", "lpm"], m("L/min", None)),
    (&["rpm", "r/min", "1/min"], m("rpm", None)),
];

/// Units of time, matched in their exact case: `S` is siemens and `H` henry, not seconds and
/// hours (a fuzzed sheet's `H` came back as `h`).
const TIME: &[(&[&str], HaClass)] = &[
    (&["s", "sec", "second", "seconds"], m("s", Some("duration"))),
    (&["ms"], m("ms", Some("duration"))),
    (&["min", "minutes"], m("min", Some("duration"))),
    (&["h", "hr", "hours"], m("h", Some("duration"))),
];

/// Home Assistant's unit and classes for `unit` as a profile or sheet writes it, when known.
#[must_use]
pub fn ha_class(unit: &str) -> Option<HaClass> {
    let exact: String = unit.trim().chars().filter(|c| !c.is_whitespace()).collect();
    if let Some(&(_, c)) = TIME.iter().find(|(names, _)| names.contains(&exact.as_str())) {
        return Some(c);
    }
    let key = exact.to_lowercase();
    KNOWN.iter().find(|(names, _)| names.contains(&key.as_str())).map(|&(_, c)| c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sheet spellings become Home Assistant's units, with the classes the Energy
    /// dashboard and long-term statistics need; an unknown unit is kept and gets no class.
    #[test]
    fn units_are_spelled_as_home_assistant_does_with_their_classes() {
        assert_eq!(ha_class("Volts"), Some(m("V", Some("voltage"))));
        assert_eq!(ha_class("kWH"), Some(total("kWh", Some("energy"))));
        assert_eq!(ha_class(" kw "), Some(m("kW", Some("power"))));
        assert_eq!(ha_class("°C").map(|c| c.device_class), Some(Some("temperature")));
        assert_eq!(ha_class("m3/h").map(|c| c.unit), Some("m³/h"));
        assert_eq!(ha_class("l"), None);
        // Time in its exact case only: `S` is siemens, `H` henry.
        assert_eq!(ha_class("h").map(|c| c.unit), Some("h"));
        assert_eq!(ha_class("H"), None);
        assert_eq!(ha_class("S"), None);
        assert_eq!(ha_class("furlongs"), None);
    }
}
