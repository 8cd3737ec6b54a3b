//! A profile out to the tools the rest of a site runs: Home Assistant's `modbus:`
//! YAML, an ESPHome `modbus_controller` configuration, Telegraf's `inputs.modbus` — the same
//! registers with their names, types, word order, scale and units. A date/time group goes out as
//! one register per part; what a tool cannot hold is left out and said (a string for Telegraf's
//! register style).
//!
//! The YAML is built as data and serialised (names with `:` or `#` stay names); the site's
//! connection (host, serial port) is a placeholder the user edits, said in the file's head.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use serde_json::{Value, json};

use super::Table;
use super::escape::{comment, toml_str, yaml_doc};
use super::format::{ValueType, WordOrder};
use super::model::Profile;

/// The tools a profile exports to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    HomeAssistant,
    Esphome,
    Telegraf,
}

/// What an export wrote and what it left out.
#[derive(Debug, Clone, Default)]
pub struct Exported {
    pub text: String,
    /// Registers left out, each with why.
    pub skipped: Vec<String>,
    pub written: usize,
}

/// One thing a profile defines, at its first address (a date/time group as one entry per part:
/// the tools have no type for it, but each part is a plain register).
struct Item {
    table: Table,
    address: u16,
    name: String,
    value_type: ValueType,
    width: u16,
    word_order: WordOrder,
    scale: Option<f64>,
    unit: Option<String>,
}

/// Every definition once, in table and address order, names made unique (the tools refuse two
/// entities of one name).
fn items(p: &Profile) -> Vec<Item> {
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    let mut unique = |name: String, table: Table, address: u16| {
        if seen.insert(name.clone()) {
            return name;
        }
        let name = format!("{name} ({} {address})", table.name());
        seen.insert(name.clone());
        name
    };
    for (&table, slots) in &p.tables {
        for (&address, slot) in slots {
            if slot.part != 0 {
                continue;
            }
            let Some(def) = p.defs.get(slot.def) else { continue };
            if def.value_type == ValueType::Datetime {
                for (i, part) in def.parts.iter().enumerate() {
                    let Some(a) = u16::try_from(i).ok().and_then(|i| address.checked_add(i)) else { continue };
                    let name = unique(format!("{} {}", slot.name, format!("{part:?}").to_lowercase()), table, a);
                    out.push(Item {
                        table,
                        address: a,
                        name,
                        value_type: ValueType::U16,
                        width: 1,
                        word_order: WordOrder::HighFirst,
                        scale: None,
                        unit: None,
                    });
                }
                continue;
            }
            out.push(Item {
                table,
                address,
                name: unique(slot.name.clone(), table, address),
                value_type: def.value_type,
                width: def.width,
                word_order: def.word_order,
                scale: def.scale,
                unit: def.unit.clone(),
            });
        }
    }
    out
}

/// Decimals worth showing for a scale (0.1 → 1, 0.025 → 3), floats 2.
fn decimals(def: &Item) -> u32 {
    if def.value_type == ValueType::F32 {
        return 2;
    }
    match def.scale {
        Some(k) if k < 1.0 => {
            let mut d = 0;
            let mut x = k;
            while d < 6 && (x - x.round()).abs() > 1e-9 {
                x *= 10.0;
                d += 1;
            }
            d
        }
        _ => 0,
    }
}

const fn is_register(t: Table) -> bool {
    matches!(t, Table::HoldingRegisters | Table::InputRegisters)
}

/// Exports `p` (for unit `unit`) to `target`. Every string from the profile goes through the
/// target's own quoting ([`super::escape`]): it stays a value whatever it holds.
#[must_use]
pub fn export(p: &Profile, unit: u8, target: Target) -> Exported {
    match target {
        Target::HomeAssistant => home_assistant(p, unit),
        Target::Esphome => esphome(p, unit),
        Target::Telegraf => telegraf(p, unit),
    }
}

/// The file's first line: the device and profile names as comment text (no line break a YAML
/// 1.1 or TOML reader knows can be in it).
fn header(p: &Profile, what: &str) -> String {
    format!(
        "# {what} for {} - exported by `mbtap profiles export` from profile \"{}\".\n",
        comment(&p.meta.device),
        comment(&p.meta.name)
    )
}

/// A sensor's unit as Home Assistant and ESPHome spell it, with its device and state class
/// when the unit is known ([`super::ha_classes`]); an unknown unit as written.
fn insert_unit(e: &mut serde_json::Map<String, Value>, unit: Option<&str>) {
    let Some(u) = unit else { return };
    match super::ha_classes::ha_class(u) {
        Some(c) => {
            e.insert("unit_of_measurement".into(), json!(c.unit));
            if let Some(d) = c.device_class {
                e.insert("device_class".into(), json!(d));
            }
            e.insert("state_class".into(), json!(c.state_class));
        }
        None => {
            e.insert("unit_of_measurement".into(), json!(u));
        }
    }
}

fn home_assistant(p: &Profile, unit: u8) -> Exported {
    let mut out = Exported::default();
    let (mut sensors, mut binary) = (Vec::new(), Vec::new());
    for it in items(p) {
        let d = &it;
        let mut e = serde_json::Map::new();
        e.insert("name".into(), json!(it.name));
        e.insert("slave".into(), json!(unit));
        e.insert("address".into(), json!(it.address));
        let input_type = match it.table {
            Table::HoldingRegisters => "holding",
            Table::InputRegisters => "input",
            Table::Coils => "coil",
            Table::DiscreteInputs => "discrete_input",
        };
        e.insert("input_type".into(), json!(input_type));
        if !is_register(it.table) || d.value_type == ValueType::Bool {
            binary.push(Value::Object(e));
            out.written += 1;
            continue;
        }
        let data_type = match d.value_type {
            ValueType::I16 => "int16",
            ValueType::U32 => "uint32",
            ValueType::I32 => "int32",
            ValueType::U64 => "uint64",
            ValueType::I64 => "int64",
            ValueType::F32 => "float32",
            ValueType::String => "string",
            ValueType::Datetime => {
                out.skipped.push(format!(
                    "{} {}: a date/time group has no Home Assistant sensor",
                    it.table.name(),
                    it.address
                ));
                continue;
            }
            _ => "uint16",
        };
        e.insert("data_type".into(), json!(data_type));
        if d.value_type == ValueType::String {
            e.insert("count".into(), json!(d.width));
        } else {
            // Home Assistant's `word` swap reverses the registers of a 32- or 64-bit value.
            if d.width >= 2 && d.word_order == WordOrder::LowFirst {
                e.insert("swap".into(), json!("word"));
            }
            if let Some(k) = d.scale {
                e.insert("scale".into(), json!(k));
            }
            e.insert("precision".into(), json!(decimals(d)));
            insert_unit(&mut e, d.unit.as_deref());
        }
        sensors.push(Value::Object(e));
        out.written += 1;
    }
    let mut hub = serde_json::Map::new();
    hub.insert("name".into(), json!(p.meta.name));
    hub.insert("type".into(), json!("tcp"));
    hub.insert("host".into(), json!("192.0.2.10"));
    hub.insert("port".into(), json!(502));
    if !sensors.is_empty() {
        hub.insert("sensors".into(), Value::Array(sensors));
    }
    if !binary.is_empty() {
        hub.insert("binary_sensors".into(), Value::Array(binary));
    }
    out.text = header(p, "Home Assistant `modbus:` configuration")
        + "# Set type/host/port for your site (or type: serial with port, baudrate, bytesize, parity, stopbits, method: rtu).\n"
        + &yaml_doc(&json!({ "modbus": [Value::Object(hub)] }));
    out
}

/// An ESPHome node name: lower case letters, digits and hyphens.
fn node_name(s: &str) -> String {
    let n: String = s.to_lowercase().chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '-' }).collect();
    let n = n.trim_matches('-').to_owned();
    let n: String = n.chars().take(24).collect();
    format!("mbtap-{}", if n.is_empty() { "device" } else { &n })
}

fn esphome(p: &Profile, unit: u8) -> Exported {
    let mut out = Exported::default();
    let (mut sensors, mut binary, mut text) = (Vec::new(), Vec::new(), Vec::new());
    for it in items(p) {
        let d = &it;
        let mut e = serde_json::Map::new();
        e.insert("platform".into(), json!("modbus_controller"));
        e.insert("modbus_controller_id".into(), json!("device"));
        e.insert("name".into(), json!(it.name));
        let register_type = match it.table {
            Table::HoldingRegisters => "holding",
            Table::InputRegisters => "read",
            Table::Coils => "coil",
            Table::DiscreteInputs => "discrete_input",
        };
        e.insert("register_type".into(), json!(register_type));
        e.insert("address".into(), json!(it.address));
        if !is_register(it.table) || d.value_type == ValueType::Bool {
            if is_register(it.table) {
                e.insert("bitmask".into(), json!(1));
            }
            binary.push(Value::Object(e));
            out.written += 1;
            continue;
        }
        if d.value_type == ValueType::String {
            e.insert("register_count".into(), json!(d.width));
            e.insert("response_size".into(), json!(u32::from(d.width) * 2));
            e.insert("raw_encode".into(), json!("NONE"));
            text.push(Value::Object(e));
            out.written += 1;
            continue;
        }
        let low = d.word_order == WordOrder::LowFirst;
        let value_type = match (d.value_type, low) {
            (ValueType::I16, _) => "S_WORD",
            (ValueType::U32, false) => "U_DWORD",
            (ValueType::U32, true) => "U_DWORD_R",
            (ValueType::I32, false) => "S_DWORD",
            (ValueType::I32, true) => "S_DWORD_R",
            (ValueType::U64, false) => "U_QWORD",
            (ValueType::U64, true) => "U_QWORD_R",
            (ValueType::I64, false) => "S_QWORD",
            (ValueType::I64, true) => "S_QWORD_R",
            (ValueType::F32, false) => "FP32",
            (ValueType::F32, true) => "FP32_R",
            (ValueType::Datetime, _) => {
                out.skipped.push(format!(
                    "{} {}: a date/time group has no ESPHome sensor",
                    it.table.name(),
                    it.address
                ));
                continue;
            }
            _ => "U_WORD",
        };
        e.insert("value_type".into(), json!(value_type));
        insert_unit(&mut e, d.unit.as_deref());
        e.insert("accuracy_decimals".into(), json!(decimals(d)));
        if let Some(k) = d.scale {
            e.insert("filters".into(), json!([{ "multiply": k }]));
        }
        sensors.push(Value::Object(e));
        out.written += 1;
    }
    let (baud, parity, stop_bits) = p.line.as_ref().map_or((9600, "NONE", 1), |l| {
        let parity = match l.framing.as_deref().and_then(|f| f.chars().nth(1)) {
            Some('E' | 'e') => "EVEN",
            Some('O' | 'o') => "ODD",
            _ => "NONE",
        };
        let stop = l.framing.as_deref().and_then(|f| f.chars().nth(2)).and_then(|c| c.to_digit(10)).unwrap_or(1);
        (l.baud.unwrap_or(9600), parity, stop)
    });
    let mut doc = serde_json::Map::new();
    doc.insert("esphome".into(), json!({ "name": node_name(&p.meta.name) }));
    doc.insert("esp32".into(), json!({ "board": "esp32dev" }));
    doc.insert(
        "uart".into(),
        json!({ "tx_pin": "GPIO17", "rx_pin": "GPIO16", "baud_rate": baud, "parity": parity, "stop_bits": stop_bits }),
    );
    doc.insert("modbus".into(), json!({}));
    doc.insert("modbus_controller".into(), json!([{ "id": "device", "address": unit, "update_interval": "10s" }]));
    if !sensors.is_empty() {
        doc.insert("sensor".into(), Value::Array(sensors));
    }
    if !binary.is_empty() {
        doc.insert("binary_sensor".into(), Value::Array(binary));
    }
    if !text.is_empty() {
        doc.insert("text_sensor".into(), Value::Array(text));
    }
    out.text = header(p, "ESPHome configuration")
        + "# Set the board and the UART pins for your hardware (and flow_control_pin under modbus: for an RS-485 driver).\n"
        + &yaml_doc(&Value::Object(doc));
    out
}

fn telegraf(p: &Profile, unit: u8) -> Exported {
    let mut out = Exported::default();
    let mut s = header(p, "Telegraf inputs.modbus");
    s.push_str("# Set controller for your site: \"tcp://HOST:502\", or \"file:///dev/ttyUSB0\" with baud_rate, data_bits, parity, stop_bits and transmission_mode = \"RTU\".\n");
    let _ =
        writeln!(s, "[[inputs.modbus]]\n  name = {}\n  slave_id = {unit}\n  timeout = \"1s\"", toml_str(&p.meta.name));
    s.push_str("  controller = \"tcp://192.0.2.10:502\"\n  configuration_type = \"register\"\n");
    let all = items(p);
    for table in [Table::Coils, Table::DiscreteInputs, Table::HoldingRegisters, Table::InputRegisters] {
        let mut lines = Vec::new();
        for it in all.iter().filter(|i| i.table == table) {
            let d = it;
            if !is_register(table) {
                lines.push(format!("{{ name = {}, address = [{}] }}", toml_str(&it.name), it.address));
                out.written += 1;
                continue;
            }
            let low = d.word_order == WordOrder::LowFirst;
            let (data_type, order) = match (d.value_type, low) {
                (ValueType::I16, _) => ("INT16", "AB"),
                (ValueType::U32, l) => ("UINT32", if l { "CDAB" } else { "ABCD" }),
                (ValueType::I32, l) => ("INT32", if l { "CDAB" } else { "ABCD" }),
                (ValueType::U64, l) => ("UINT64", if l { "GHEFCDAB" } else { "ABCDEFGH" }),
                (ValueType::I64, l) => ("INT64", if l { "GHEFCDAB" } else { "ABCDEFGH" }),
                (ValueType::F32, l) => ("FLOAT32-IEEE", if l { "CDAB" } else { "ABCD" }),
                (ValueType::String, _) => {
                    out.skipped.push(format!(
                        "{} {}: Telegraf's register configuration has no {}",
                        table.name(),
                        it.address,
                        super::import::type_name(d.value_type)
                    ));
                    continue;
                }
                _ => ("UINT16", "AB"),
            };
            let addresses: Vec<String> =
                (0..d.width).map(|i| (u32::from(it.address) + u32::from(i)).to_string()).collect();
            lines.push(format!(
                "{{ name = {}, byte_order = \"{order}\", data_type = \"{data_type}\", scale = {:?}, address = [{}] }}",
                toml_str(&it.name),
                d.scale.unwrap_or(1.0),
                addresses.join(", ")
            ));
            out.written += 1;
        }
        if !lines.is_empty() {
            let _ = writeln!(s, "  {} = [", table.name());
            for l in lines {
                let _ = writeln!(s, "    {l},");
            }
            s.push_str("  ]\n");
        }
    }
    out.text = s;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mk4() -> Profile {
        super::super::builtin::get("mk4").expect("built in").expect("loads")
    }

    #[test]
    fn every_target_writes_every_register_it_can_and_says_what_it_cannot() {
        let p = mk4();
        for target in [Target::HomeAssistant, Target::Esphome, Target::Telegraf] {
            let e = export(&p, 1, target);
            assert!(e.written > 20, "{target:?}: {}", e.written);
            assert!(!e.text.is_empty());
        }
        // The YAML reads back as the data it was made from.
        let ha = export(&p, 1, Target::HomeAssistant);
        let v: serde_norway::Value = serde_norway::from_str(&ha.text).expect("YAML");
        assert_eq!(v["modbus"][0]["sensors"][0]["slave"].as_u64(), Some(1));
        let t = export(&p, 7, Target::Telegraf);
        let v: toml::Value = toml::from_str(&t.text).expect("TOML");
        assert_eq!(v["inputs"]["modbus"][0]["slave_id"].as_integer(), Some(7));
    }
}
