//! Home Assistant's `modbus:` YAML — what a site already runs: `sensors` (with `address`,
//! `input_type`, `data_type`, `scale`, `precision`, `unit_of_measurement`, `swap`, `count`),
//! `binary_sensors` and `switches`, from a whole `configuration.yaml`, the list of hubs an
//! `!include` names, or one hub. One device (`slave`/`device_address`) per profile.

use super::ha_yaml::{Level, OTHER_PLATFORMS, hubs};

use super::ha_entry::Read;
use super::{Imported, Sink};

/// Errors that stop the import as a whole (an entry that cannot be read is a [`super::Problem`]).
#[derive(Debug, thiserror::Error)]
pub enum HaError {
    #[error("not YAML: {0}")]
    Yaml(String),
    #[error("line {line}: {why}")]
    Read { line: usize, why: String },
    #[error("no `modbus:` hubs with sensors, binary_sensors or switches found")]
    NoHubs,
    #[error("entries for several devices ({0}): choose one with --unit")]
    SeveralUnits(String),
    #[error(
        "line {line}: nested deeper than {MAX_DEPTH} levels, the import's recursion limit — not a Home Assistant `modbus:` configuration (one nests about 6); nothing imported"
    )]
    TooDeep { line: usize },
    #[error(
        "the file expands past the import's limits (an alias bomb, or far more than a Home Assistant configuration holds) — {why}; nothing imported"
    )]
    TooLarge { why: String },
}

/// Nesting a Home Assistant file may have (it has about 6: `modbus:`, a hub, `sensors:`, an
/// entry, a key): deeper is refused before the YAML reader sees it (100 000 nested `[`
/// took 30–40 s, 20 000 nested mappings 210 MB).
pub const MAX_DEPTH: usize = 64;

/// Refuses `yaml` nested deeper than [`MAX_DEPTH`] in flow collections (`[`, `{` where a value
/// begins, outside quotes and comments) or in block indentation (each deeper indentation, and
/// each `- ` opening a sequence on a line, one level). One pass, bounded work per byte.
fn check_depth(yaml: impl std::io::BufRead) -> Result<(), HaError> {
    let mut indents: Vec<usize> = Vec::new();
    let mut flow = 0usize;
    for (n, line) in yaml.lines().enumerate() {
        let line = line.map_err(|e| HaError::Read {
            line: n + 1,
            why: if e.kind() == std::io::ErrorKind::InvalidData {
                "not UTF-8 text: save the file as UTF-8".into()
            } else {
                e.to_string()
            },
        })?;
        let line = line.strip_suffix('\r').unwrap_or(&line);
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

/// Nodes (mappings, sequences, scalars, aliases' expansions counted) a file may have: 200 000
/// sensors of five keys are 2.2 M; an alias bomb past it is refused before it is read.
pub const MAX_NODES: usize = 8 << 20;

/// Events the reader may keep for anchors to be replayed where an alias names them: a
/// configuration's templates (`&defaults {slave: 1, input_type: holding}`) are tens; the
/// reader's default (a million) let an alias bomb hold 109 MB before it was refused.
pub const MAX_ANCHOR_EVENTS: usize = 1 << 16;

/// Bytes the anchors may hold, recorded (an anchor holding aliases records their expansion): a
/// configuration's templates are a few hundred bytes; a nested bomb's anchors pass it at once.
pub const MAX_ANCHOR_BYTES: usize = 1 << 20;

/// Scalar bytes the reader may produce, replayed aliases included: what an expansion makes is
/// bounded here, whatever the ratio of aliases to anchors (an honest file merges one
/// `&defaults` into hundreds of sensors: 119 aliases of 1 anchor were refused as a bomb).
pub const MAX_SCALAR_BYTES: usize = 64 << 20;

/// The YAML reader streams (no list of the document's events: serde_norway held 201 MB of them
/// for 200 000 sensors); its budgets bound what an alias may expand to — nodes, events, anchor
/// bytes and scalar bytes produced — not the ratio of aliases to anchors.
fn reader_options() -> serde_saphyr::Options {
    serde_saphyr::options! {
        budget: serde_saphyr::budget! {
            max_nodes: MAX_NODES,
            max_events: 2 * MAX_NODES,
            max_depth: MAX_DEPTH,
            max_recorded_anchor_events: MAX_ANCHOR_EVENTS,
            max_recorded_anchor_bytes: MAX_ANCHOR_BYTES,
            max_total_scalar_bytes: MAX_SCALAR_BYTES,
            enforce_alias_anchor_ratio: false,
        },
        // One line: the error names its line and column; the import says the file.
        with_snippet: false,
    }
}

/// The reader's error, a budget's breach said as the import's limit.
fn yaml_error(e: &serde_saphyr::Error) -> HaError {
    // A breach met while expanding an alias comes wrapped with the alias's place.
    let mut inner = e;
    while let serde_saphyr::Error::AliasError { error, .. } | serde_saphyr::Error::WithSnippet { error, .. } = inner {
        inner = error;
    }
    match inner {
        serde_saphyr::Error::Budget { .. }
        | serde_saphyr::Error::AliasReplayLimitExceeded { .. }
        | serde_saphyr::Error::AliasExpansionLimitExceeded { .. }
        | serde_saphyr::Error::AliasReplayStackDepthExceeded { .. } => HaError::TooLarge { why: e.to_string() },
        _ => HaError::Yaml(e.to_string()),
    }
}

/// Reads `yaml`; with several devices, `unit` chooses one.
///
/// # Errors
/// Not YAML, no hubs, or several devices and no `unit`.
pub fn parse_home_assistant(yaml: &str, unit: Option<u8>) -> Result<(Imported, u8), HaError> {
    let mut out = Imported::default();
    let unit = read_home_assistant(yaml, unit, &mut out)?;
    Ok((out, unit))
}

/// Reads `yaml` into `out` and returns the device read; with several devices, `unit` chooses one.
///
/// # Errors
/// Not YAML, no hubs, or several devices and no `unit`.
pub fn read_home_assistant(yaml: &str, unit: Option<u8>, out: &mut impl Sink) -> Result<u8, HaError> {
    read_home_assistant_from(yaml.as_bytes(), yaml.as_bytes(), unit, out)
}

/// [`read_home_assistant`] of a file read twice, streamed: `depth` for its nesting, then `yaml`
/// by the reader (the file held whole was a quarter of the import's memory).
///
/// # Errors
/// Not YAML, no hubs, several devices and no `unit`, or the file cannot be read.
pub fn read_home_assistant_from(
    depth: impl std::io::BufRead,
    yaml: impl std::io::Read,
    unit: Option<u8>,
    out: &mut impl Sink,
) -> Result<u8, HaError> {
    check_depth(depth)?;
    let doc: Level = serde_saphyr::from_reader_with_options(yaml, reader_options()).map_err(|e| yaml_error(&e))?;
    let hubs = hubs(doc);
    if hubs.is_empty() {
        return Err(HaError::NoHubs);
    }
    // An entry names its device, else its hub does, else it is HA's default 0 — unless it could
    // not be read and names none (a tagged node, a scalar, a mapping without its address): then
    // it counts as no device, and is said with whichever device is chosen.
    let unit_of = |r: &Read| r.unit.or_else(|| r.point.is_ok().then_some(0));
    let units: std::collections::BTreeSet<u64> = hubs.iter().flat_map(Level::reads).filter_map(unit_of).collect();
    let chosen = match (unit, units.len()) {
        (Some(u), _) => u64::from(u),
        (None, 0 | 1) => units.first().copied().unwrap_or(0),
        (None, _) => {
            let all: Vec<String> = units.iter().map(u64::to_string).collect();
            return Err(HaError::SeveralUnits(all.join(", ")));
        }
    };
    let other: Vec<&str> = OTHER_PLATFORMS
        .into_iter()
        .enumerate()
        .filter(|(i, _)| hubs.iter().any(|h| h.other[*i]))
        .map(|(_, k)| k)
        .collect();
    for r in hubs.into_iter().flat_map(Level::into_reads).filter(|r| unit_of(r).is_none_or(|u| u == chosen)) {
        match r.point {
            Ok(p) => out.point(p),
            Err(problem) => out.problem(problem),
        }
    }
    if !other.is_empty() {
        out.note(format!("not imported (no profile equivalent): {}", other.join(", ")));
    }
    Ok(u8::try_from(chosen).unwrap_or(0))
}

/// One entry as a point, or the key to blame and why.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::format::{Access, ValueType, WordOrder};

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
        data_type: float64
      - name: Counter
        slave: 3
        address: 20
        data_type: uint64
        swap: word
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
        assert_eq!(r.points.len(), 5, "{:?}", r.problems);
        let energy = &r.points[1];
        assert_eq!(
            (energy.value_type, energy.word_order, energy.scale),
            (ValueType::U32, WordOrder::LowFirst, Some(0.01))
        );
        let counter = &r.points[2];
        assert_eq!((counter.value_type, counter.word_order, counter.width()), (ValueType::U64, WordOrder::LowFirst, 4));
        assert_eq!(r.points[4].access, Access::ReadWrite);
        assert_eq!(r.problems.len(), 1);
        assert_eq!(
            r.problems[0].to_string(),
            "sensors[2] \"Odd\", data_type: \"float64\": not in the profile format (int16, uint16, int32, uint32, int64, uint64, float32, string)"
        );
    }

    /// The usual pattern: one `&defaults` sensor, every other `<<: *defaults` with its own name
    /// and address. Hundreds of aliases of one anchor are honest: they import.
    #[test]
    fn one_template_merged_into_hundreds_of_sensors_imports() {
        use std::fmt::Write as _;
        let mut yaml = String::from(
            "- name: hub\n  type: tcp\n  host: 127.0.0.1\n  port: 502\n  sensors:\n    - &defaults\n      name: S0\n      slave: 1\n      address: 0\n      input_type: holding\n      data_type: int16\n",
        );
        for i in 1..300 {
            let _ = write!(yaml, "    - <<: *defaults\n      name: S{i}\n      address: {i}\n");
        }
        let (r, unit) = parse_home_assistant(&yaml, None).unwrap();
        assert_eq!((unit, r.points.len()), (1, 300), "{:?}", r.problems);
    }

    /// A bomb is refused by what its expansion produces: one 1 MB anchor named by 100 aliases is
    /// 100 MB of text.
    #[test]
    fn an_alias_bomb_is_refused_by_the_bytes_its_expansion_produces() {
        use std::fmt::Write as _;
        let mut yaml = format!(
            "- name: hub\n  type: tcp\n  sensors:\n    - name: &big {}\n      slave: 1\n      address: 0\n",
            "x".repeat(1 << 20)
        );
        for i in 1..100 {
            let _ = write!(yaml, "    - name: *big\n      slave: 1\n      address: {i}\n");
        }
        let e = parse_home_assistant(&yaml, None).unwrap_err();
        assert!(matches!(e, HaError::TooLarge { .. }), "{e}");
        assert!(e.to_string().contains("ScalarBytes"), "{e}");
    }

    #[test]
    fn several_devices_need_a_choice_and_garbage_is_named() {
        let two = "- name: hub\n  type: serial\n  sensors:\n    - {name: a, slave: 1, address: 0}\n    - {name: b, slave: 2, address: 0}\n";
        assert!(matches!(parse_home_assistant(two, None), Err(HaError::SeveralUnits(u)) if u == "1, 2"));
        assert_eq!(parse_home_assistant(two, Some(2)).unwrap().0.points.len(), 1);
        assert!(matches!(parse_home_assistant("a: [", None), Err(HaError::Yaml(_))));
        assert!(matches!(parse_home_assistant("sensor: []", None), Err(HaError::NoHubs)));
    }

    /// Nesting deeper than any Home Assistant file (100 000 nested `[`: 30 s to read; 20 000 nested
    /// mappings: 210 MB) is refused before the YAML reader, naming the line.
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
        check_depth(fine.as_bytes()).unwrap();
        check_depth(CONFIG.as_bytes()).unwrap();
    }

    /// The YAML is read into entries as it goes, no tree of the document (200 000 sensors take 540
    /// MB as a tree). What a tree would give holds: a hub's unit given after its lists still names
    /// their entries; an entry that is not a mapping is a problem, not the end of the import. An
    /// alias bomb (9^9 nodes if expanded) is refused by the reader's budget, naming where, wherever
    /// it sits — even under an unread key, without holding every event of the file (201 MB for 200
    /// 000 sensors).
    #[test]
    fn the_yaml_is_read_without_a_tree_as_the_tree_read_it() {
        let late_unit =
            "modbus:\n  - name: hub\n    sensors:\n      - name: A\n        address: 1\n      - 42\n    slave: 7\n";
        let (r, unit) = parse_home_assistant(late_unit, None).unwrap();
        assert_eq!(unit, 7);
        assert_eq!(r.points.len(), 1);
        assert_eq!(r.problems.len(), 1, "{:?}", r.problems);
        assert!(r.problems[0].why.contains("not a mapping of keys"), "{:?}", r.problems);
        let mut bomb =
            String::from("modbus:\n  - name: hub\n    x0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n");
        for i in 1..10 {
            let refs = vec![format!("*a{}", i - 1); 9].join(", ");
            bomb += &["    x", &i.to_string(), ": &a", &i.to_string(), " [", &refs, "]\n"].concat();
        }
        bomb.push_str("    sensors:\n      - name: *a9\n        slave: 1\n        address: 100\n");
        let e = parse_home_assistant(&bomb, None).unwrap_err();
        assert!(matches!(e, HaError::TooLarge { .. }), "{e}");
        assert!(e.to_string().contains("limits") && e.to_string().contains("line 3"), "{e}");
    }

    /// Tags as the round-4 probe writes them: a hub named by a Python object, a `!secret` host,
    /// a `!lambda` sensor name, an `!include`d entry.
    const TAGGED: &str = r"
modbus:
  - name: !!python/object/apply:os.system ['id']
    type: tcp
    host: !secret host
    port: 502
    sensors:
      - name: !lambda 'return 1;'
        slave: 1
        address: 100
        input_type: holding
      - !include other.yaml
";

    /// A tagged node (`!include`, `!secret`) is read past as plain data, nothing resolved or run,
    /// never refusing the whole file ("invalid type: enum, expected a scalar"); the `!include`d
    /// entry names no device, so it neither counts as one nor is lost.
    #[test]
    fn tagged_nodes_are_read_past_as_no_value() {
        let (r, unit) = parse_home_assistant(TAGGED, None).unwrap();
        assert_eq!((unit, r.points.len(), r.problems.len()), (1, 1, 1), "{r:?}");
        assert_eq!((r.points[0].address, r.points[0].name.as_str()), (100, "reg_100"));
        assert!(r.problems[0].at.starts_with("sensors[1]"), "{:?}", r.problems);
        assert!(r.problems[0].why.contains("tagged node such as !include"), "{:?}", r.problems);
    }
}
