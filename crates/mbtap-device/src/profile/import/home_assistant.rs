//! Home Assistant's `modbus:` YAML — what a site already runs: `sensors` (with `address`,
//! `input_type`, `data_type`, `scale`, `precision`, `unit_of_measurement`, `swap`, `count`),
//! `binary_sensors` and `switches`, from a whole `configuration.yaml`, the list of hubs an
//! `!include` names, or one hub. One device (`slave`/`device_address`) per profile.

use serde_norway::Value;

use super::{Imported, Point, Problem};
use crate::profile::Table;
use crate::profile::format::{Access, ValueType, WordOrder};

/// Errors that stop the import as a whole (an entry that cannot be read is a [`Problem`]).
#[derive(Debug, thiserror::Error)]
pub enum HaError {
    #[error("not YAML: {0}")]
    Yaml(String),
    #[error("no `modbus:` hubs with sensors, binary_sensors or switches found")]
    NoHubs,
    #[error("entries for several devices ({0}): choose one with --unit")]
    SeveralUnits(String),
    #[error(
        "line {line}: nested deeper than {MAX_DEPTH} levels, the import's recursion limit — not a Home Assistant `modbus:` configuration (one nests about 6); nothing imported"
    )]
    TooDeep { line: usize },
}

/// Nesting a Home Assistant file may have (it has about 6: `modbus:`, a hub, `sensors:`, an
/// entry, a key): deeper is refused before the YAML reader sees it (issue 39: 100 000 nested `[`
/// took 30–40 s, 20 000 nested mappings 210 MB).
pub const MAX_DEPTH: usize = 64;

/// Refuses `yaml` nested deeper than [`MAX_DEPTH`] in flow collections (`[`, `{` where a value
/// begins, outside quotes and comments) or in block indentation (each deeper indentation, and
/// each `- ` opening a sequence on a line, one level). One pass, bounded work per byte.
fn check_depth(yaml: &str) -> Result<(), HaError> {
    let mut indents: Vec<usize> = Vec::new();
    let mut flow = 0usize;
    for (n, line) in yaml.lines().enumerate() {
        let too_deep = || HaError::TooDeep { line: n + 1 };
        let body = line.trim_start_matches(' ');
        if flow == 0 && !body.is_empty() && !body.starts_with('#') {
            let indent = line.len() - body.len();
            while indents.last().is_some_and(|&top| top > indent) {
                indents.pop();
            }
            if indents.last().is_none_or(|&top| top < indent) {
                indents.push(indent);
            }
            // `- - - x`: each dash opens a sequence one level deeper.
            let dashes = body.split_inclusive(' ').take_while(|w| *w == "- ").count();
            if indents.len() + dashes > MAX_DEPTH {
                return Err(too_deep());
            }
        }
        // Inside a quoted scalar (its quote), inside a plain one (brackets there are text).
        let (mut quote, mut plain, mut prev) = (None::<char>, false, ' ');
        for c in body.chars() {
            let opens = matches!(prev, ' ' | ':' | ',' | '[' | '{' | '-');
            match (quote, c) {
                (Some(q), c) if c == q && !(q == '"' && prev == '\\') => quote = None,
                (Some(_), _) => {}
                (None, '#') if prev == ' ' => break,
                (None, ':') => plain = false,
                (None, ',' | ']' | '}') if flow > 0 => {
                    plain = false;
                    if c != ',' {
                        flow -= 1;
                    }
                }
                _ if plain => {}
                (None, '"' | '\'') if opens => quote = Some(c),
                (None, '[' | '{') if opens => {
                    flow += 1;
                    if flow > MAX_DEPTH {
                        return Err(too_deep());
                    }
                }
                (None, ' ' | '-' | '?' | '|' | '>') => {}
                (None, _) => plain = true,
            }
            // An escaped backslash escapes nothing after it.
            prev = if quote.is_some() && c == '\\' && prev == '\\' { ' ' } else { c };
        }
    }
    Ok(())
}

/// The hubs in a document: under `modbus:`, a list of hubs, or one hub.
fn hubs(doc: &Value) -> Vec<&Value> {
    let is_hub = |v: &Value| {
        v.as_mapping().is_some_and(|m| ["sensors", "binary_sensors", "switches"].iter().any(|k| m.contains_key(*k)))
    };
    let v = doc.get("modbus").unwrap_or(doc);
    match v {
        Value::Sequence(s) => s.iter().filter(|h| is_hub(h)).collect(),
        v if is_hub(v) => vec![v],
        _ => Vec::new(),
    }
}

/// The device an entry belongs to (`slave`, or `device_address` in newer releases; 0 when
/// neither is given, as Home Assistant defaults).
fn unit_of(entry: &Value, hub: &Value) -> u64 {
    ["device_address", "slave"]
        .iter()
        .find_map(|k| entry.get(*k).and_then(Value::as_u64))
        .or_else(|| ["device_address", "slave"].iter().find_map(|k| hub.get(*k).and_then(Value::as_u64)))
        .unwrap_or(0)
}

fn text(v: Option<&Value>) -> Option<String> {
    match v? {
        Value::String(s) => Some(s.clone()),
        Value::Number(n) => Some(n.to_string()),
        Value::Bool(b) => Some(b.to_string()),
        _ => None,
    }
}

/// Reads `yaml`; with several devices, `unit` chooses one.
///
/// # Errors
/// Not YAML, no hubs, or several devices and no `unit`.
pub fn parse_home_assistant(yaml: &str, unit: Option<u8>) -> Result<(Imported, u8), HaError> {
    check_depth(yaml)?;
    let doc: Value = serde_norway::from_str(yaml).map_err(|e| HaError::Yaml(e.to_string()))?;
    let hubs = hubs(&doc);
    if hubs.is_empty() {
        return Err(HaError::NoHubs);
    }
    let mut units = std::collections::BTreeSet::new();
    for hub in &hubs {
        for kind in ["sensors", "binary_sensors", "switches"] {
            for e in hub.get(kind).and_then(Value::as_sequence).into_iter().flatten() {
                units.insert(unit_of(e, hub));
            }
        }
    }
    let chosen = match (unit, units.len()) {
        (Some(u), _) => u64::from(u),
        (None, 1) => units.first().copied().unwrap_or(0),
        (None, _) => {
            let all: Vec<String> = units.iter().map(u64::to_string).collect();
            return Err(HaError::SeveralUnits(all.join(", ")));
        }
    };
    let mut out = Imported::default();
    for hub in &hubs {
        for kind in ["sensors", "binary_sensors", "switches"] {
            for (i, e) in hub.get(kind).and_then(Value::as_sequence).into_iter().flatten().enumerate() {
                if unit_of(e, hub) != chosen {
                    continue;
                }
                let name = text(e.get("name")).unwrap_or_default();
                let at = format!("{kind}[{i}] {name:?}");
                match entry(kind, e, &name) {
                    Ok(p) => out.add(Point { origin: at, ..p }),
                    Err((key, why)) => out.problems.push(Problem { at, column: Some(key.to_owned()), why }),
                }
            }
        }
    }
    let other: Vec<&str> = ["climates", "covers", "fans", "lights"]
        .into_iter()
        .filter(|k| hubs.iter().any(|h| h.get(*k).is_some()))
        .collect();
    if !other.is_empty() {
        out.notes.push(format!("not imported (no profile equivalent): {}", other.join(", ")));
    }
    Ok((out, u8::try_from(chosen).unwrap_or(0)))
}

/// One entry as a point, or the key to blame and why.
fn entry(kind: &str, e: &Value, name: &str) -> Result<Point, (&'static str, String)> {
    let address = e.get("address").and_then(Value::as_u64).ok_or(("address", "missing or not a number".to_owned()))?;
    let address = u16::try_from(address).map_err(|_| ("address", format!("{address} is past 65535")))?;
    let input_type = text(e.get("input_type")).or_else(|| text(e.get("write_type")));
    let default = if kind == "sensors" { "holding" } else { "coil" };
    let input_type = input_type.as_deref().unwrap_or(default);
    let table = match input_type {
        "holding" | "holdings" => Table::HoldingRegisters,
        "input" => Table::InputRegisters,
        "coil" | "coils" => Table::Coils,
        "discrete_input" => Table::DiscreteInputs,
        other => return Err(("input_type", format!("{other:?} is not holding, input, coil or discrete_input"))),
    };
    let access = if kind == "switches" { Access::ReadWrite } else { Access::Read };
    let mut p = Point {
        table,
        address,
        name: if name.is_empty() { format!("reg_{address}") } else { name.to_owned() },
        value_type: ValueType::U16,
        word_order: WordOrder::HighFirst,
        scale: None,
        unit: text(e.get("unit_of_measurement")),
        access,
        length: None,
        description: None,
        origin: String::new(),
    };
    if kind != "sensors" || matches!(table, Table::Coils | Table::DiscreteInputs) {
        p.value_type = ValueType::Bool;
        return Ok(p);
    }
    let count = e.get("count").and_then(Value::as_u64).and_then(|c| u16::try_from(c).ok());
    let data_type = text(e.get("data_type")).unwrap_or_else(|| "int16".to_owned());
    p.value_type = match data_type.as_str() {
        "int16" | "int" => ValueType::I16,
        "uint16" | "uint" => ValueType::U16,
        "int32" => ValueType::I32,
        "uint32" => ValueType::U32,
        "float32" | "float" => ValueType::F32,
        "string" => {
            p.length = Some(count.ok_or(("count", "a string needs its count of registers".to_owned()))?);
            ValueType::String
        }
        other => {
            return Err((
                "data_type",
                format!("{other:?}: not in the profile format (int16, uint16, int32, uint32, float32, string)"),
            ));
        }
    };
    match text(e.get("swap")).as_deref() {
        None | Some("none") => {}
        Some("word") if matches!(p.value_type, ValueType::I32 | ValueType::U32 | ValueType::F32) => {
            p.word_order = WordOrder::LowFirst;
        }
        Some(other) => return Err(("swap", format!("{other:?}: byte swaps are not in the profile format"))),
    }
    if let Some(s) = e.get("scale") {
        let k = s.as_f64().ok_or(("scale", "not a number".to_owned()))?;
        if k == 0.0 || !k.is_finite() {
            return Err(("scale", format!("{k} is not a usable scale")));
        }
        p.scale = ((k - 1.0).abs() > f64::EPSILON).then_some(k);
    }
    if e.get("offset").and_then(Value::as_f64).is_some_and(|o| o != 0.0) {
        return Err(("offset", "offsets are not in the profile format".to_owned()));
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CONFIG: &str = r"
homeassistant:
  name: Home
modbus:
  - name: meter
    type: tcp
    host: 192.0.2.5
    port: 502
    sensors:
      - name: Grid voltage
        slave: 3
        address: 0
        input_type: input
        data_type: float32
        unit_of_measurement: V
        precision: 1
      - name: Energy
        slave: 3
        address: 2
        input_type: input
        data_type: uint32
        swap: word
        scale: 0.01
      - name: Odd
        slave: 3
        address: 10
        data_type: int64
    binary_sensors:
      - name: Relay
        slave: 3
        address: 5
        input_type: coil
    switches:
      - name: Pump
        slave: 3
        address: 6
        write_type: coil
";

    #[test]
    fn sensors_binary_sensors_and_switches_become_points() {
        let (r, unit) = parse_home_assistant(CONFIG, None).unwrap();
        assert_eq!(unit, 3);
        assert_eq!(r.points.len(), 4, "{:?}", r.problems);
        let energy = &r.points[1];
        assert_eq!(
            (energy.value_type, energy.word_order, energy.scale),
            (ValueType::U32, WordOrder::LowFirst, Some(0.01))
        );
        assert_eq!(r.points[3].access, Access::ReadWrite);
        assert_eq!(r.problems.len(), 1);
        assert_eq!(
            r.problems[0].to_string(),
            "sensors[2] \"Odd\", data_type: \"int64\": not in the profile format (int16, uint16, int32, uint32, float32, string)"
        );
    }

    #[test]
    fn several_devices_need_a_choice_and_garbage_is_named() {
        let two = "- name: hub\n  type: serial\n  sensors:\n    - {name: a, slave: 1, address: 0}\n    - {name: b, slave: 2, address: 0}\n";
        assert!(matches!(parse_home_assistant(two, None), Err(HaError::SeveralUnits(u)) if u == "1, 2"));
        assert_eq!(parse_home_assistant(two, Some(2)).unwrap().0.points.len(), 1);
        assert!(matches!(parse_home_assistant("a: [", None), Err(HaError::Yaml(_))));
        assert!(matches!(parse_home_assistant("sensor: []", None), Err(HaError::NoHubs)));
    }

    /// Issue 39 (`gen_yaml.py` deep_seq, deep_map): 100 000 nested `[` took 30 s, 20 000 nested
    /// mappings 210 MB; both are refused before the YAML reader, naming the line.
    #[test]
    fn nesting_deeper_than_any_home_assistant_file_is_refused_at_once() {
        let deep_seq = format!("modbus: {}{}\n", "[".repeat(100_000), "]".repeat(100_000));
        assert!(matches!(parse_home_assistant(&deep_seq, None), Err(HaError::TooDeep { line: 1 })));
        let deep_map: String = std::iter::once("modbus:\n".to_owned())
            .chain((0..20_000).map(|i| format!("{}k{i}:\n", " ".repeat(i + 1))))
            .collect();
        let e = parse_home_assistant(&deep_map, None).unwrap_err();
        assert!(matches!(e, HaError::TooDeep { line } if line <= MAX_DEPTH + 1), "{e}");
        assert!(e.to_string().contains("nothing imported"), "{e}");
        let dashes = format!("modbus:\n{}x\n", "- ".repeat(100));
        assert!(matches!(parse_home_assistant(&dashes, None), Err(HaError::TooDeep { line: 2 })));
        // Brackets inside quotes, plain scalars and comments are no nesting.
        let fine = CONFIG.replace("Grid voltage", &format!("\"{}\"", "[".repeat(200)))
            + &format!("# {}\nx: a{}\n", "{".repeat(200), "[".repeat(200));
        check_depth(&fine).unwrap();
        check_depth(CONFIG).unwrap();
    }
}
