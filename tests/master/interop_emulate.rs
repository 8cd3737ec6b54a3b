//! Emulated devices read by third-party masters: pymodbus and mbpoll (libmodbus)
//! over Modbus TCP read a device emulated from an imported profile, from a real recording in
//! `captures/` and from a probe dump, and get exactly what the source holds. Needs python3 with
//! pymodbus and mbpoll: `#[ignore]`d in a plain `cargo test`, run by `.ci/run` with `--ignored`.

use std::path::Path;
use std::process::Command;

use super::emulate::emulate;
use crate::common::BIN;

/// pymodbus reading one range (`tests/interop/pymodbus_tcp_read.py`): its JSON answer.
fn pymodbus_read(addr: &str, unit: u8, table: &str, address: u16, count: u16) -> serde_json::Value {
    let (host, port) = addr.rsplit_once(':').unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_tcp_read.py");
    let out = Command::new("python3")
        .arg(script)
        .args([host, port, &unit.to_string(), table, &address.to_string(), &count.to_string()])
        .output()
        .expect("python3 must be installed");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The registers of an FC 03/04 answer line of a capture's `.txt` (unit, fc, count, data, CRC).
fn registers_of(answer_hex: &str) -> Vec<u64> {
    let bytes: Vec<u8> = answer_hex.split_whitespace().map(|h| u8::from_str_radix(h, 16).unwrap()).collect();
    bytes[3..bytes.len() - 2].chunks(2).map(|w| u64::from(u16::from_be_bytes([w[0], w[1]]))).collect()
}

fn txt_line(name: &str, starts: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures").join(name);
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .find(|l| l.to_ascii_lowercase().starts_with(starts))
        .unwrap()
        .to_owned()
}

#[test]
#[ignore = "needs python3 with pymodbus; .ci/run installs it and runs this with --ignored"]
fn pymodbus_reads_a_recorded_power_meter_as_it_was_recorded() {
    let meter = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/rtu-real-power-meter.pcapng");
    let (_sim, addr, _) = emulate(&["--from", meter.to_str().unwrap()]);
    // The recording's answers to FC 04 0–41 and FC 03 0–45.
    let input = registers_of(&txt_line("rtu-real-power-meter.txt", "01 04 54"));
    let holding = registers_of(&txt_line("rtu-real-power-meter.txt", "01 03 5c"));
    assert_eq!((input.len(), holding.len()), (42, 46));
    assert_eq!(pymodbus_read(&addr, 1, "input", 0, 42)["registers"], serde_json::json!(input));
    assert_eq!(pymodbus_read(&addr, 1, "holding", 0, 46)["registers"], serde_json::json!(holding));
    // A smaller read inside what was recorded, and one past it.
    assert_eq!(pymodbus_read(&addr, 1, "holding", 10, 3)["registers"], serde_json::json!(holding[10..13]));
    assert_eq!(pymodbus_read(&addr, 1, "holding", 45, 2)["exception"], 2);
    // Coils 0–30: answer 04 10 00 00 10 → coil 4 and coil 28 on.
    let bits = pymodbus_read(&addr, 1, "coils", 0, 31)["bits"].clone();
    let on: Vec<usize> =
        bits.as_array().unwrap().iter().enumerate().filter(|(_, b)| b.as_bool().unwrap()).map(|(i, _)| i).collect();
    assert_eq!(on, [4, 28]);
}

#[test]
#[ignore = "needs python3 with pymodbus; .ci/run installs it and runs this with --ignored"]
fn pymodbus_reads_an_imported_profile_and_a_probe_dump_as_they_hold() {
    let dir = std::env::temp_dir().join(format!("mbtap-emulate-interop-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // An imported vendor sheet: input registers 0–1 (volts, a float), 6–7, 12–13, 70–71, 342–343.
    let profile = crate::common::imported_meter(&dir);
    let (_sim, addr, _) = emulate(&["--device", &format!("{}@3", profile.display())]);
    // Mapped and at rest (0.0 V is in range: the sheet gives no range): read; unmapped: 02.
    assert_eq!(pymodbus_read(&addr, 3, "input", 0, 2)["registers"], serde_json::json!([0, 0]));
    assert_eq!(pymodbus_read(&addr, 3, "input", 342, 2)["registers"], serde_json::json!([0, 0]));
    assert_eq!(pymodbus_read(&addr, 3, "input", 2, 2)["exception"], 2);

    // A probe dump of the built-in MK4's holding registers 100–140, then a device from it.
    let (_mk4, mk4, _) = emulate(&["--device", "mk4@1"]);
    let out = Command::new(BIN)
        .args(["probe", &mk4, "--unit", "1", "--tables", "holding", "--range", "100-140", "--rate", "1000"])
        .args(["--format", "json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let dump = dir.join("mk4-dump.json");
    std::fs::write(&dump, &out.stdout).unwrap();
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = doc["image"].as_array().unwrap();
    assert!(rows.len() > 20, "the probe found {} holding registers", rows.len());
    let (_copy, copy, said) = emulate(&["--from", dump.to_str().unwrap()]);
    assert!(said.contains("emulating unit 1"), "{said}");
    for row in rows {
        let a = u16::try_from(row["address"].as_u64().unwrap()).unwrap();
        assert_eq!(
            pymodbus_read(&copy, 1, "holding", a, 1)["registers"],
            serde_json::json!([row["raw"]]),
            "holding {a}"
        );
    }
}

#[test]
#[ignore = "needs mbpoll; .ci/run installs it and runs this with --ignored"]
fn mbpoll_reads_a_recorded_device_over_tcp() {
    let meter = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/rtu-real-power-meter.pcapng");
    let (_sim, addr, _) = emulate(&["--from", meter.to_str().unwrap()]);
    let (host, port) = addr.rsplit_once(':').unwrap();
    // mbpoll: -t 4 holding registers, -0 zero-based addresses, -1 one poll.
    let out = Command::new("mbpoll")
        .args(["-m", "tcp", "-p", port, "-a", "1", "-t", "4", "-0", "-r", "0", "-c", "46", "-1", host])
        .output()
        .expect("mbpoll must be installed for this test");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    let got: Vec<u64> = text
        .lines()
        .filter_map(|l| {
            let (_, v) = l.trim().strip_prefix('[')?.split_once("]:")?;
            let v = v.split_whitespace().next()?;
            v.parse().ok()
        })
        .collect();
    assert_eq!(got, registers_of(&txt_line("rtu-real-power-meter.txt", "01 03 5c")), "{text}");
}

/// A register pair as pymodbus read it, as the IEEE 754 float Eastron's maps say (high word first).
fn float_of(answer: &serde_json::Value) -> f32 {
    let r = answer["registers"].as_array().unwrap_or_else(|| panic!("{answer}"));
    let words: Vec<u32> = r.iter().map(|w| u32::try_from(w.as_u64().unwrap()).unwrap()).collect();
    f32::from_bits(words[0] << 16 | words[1])
}

/// The built-in Eastron meters, emulated and read by pymodbus at their maps' addresses and types:
/// input 0 the (first) phase's volts, 70 hertz, 342 the total kWh — a float near 230, 50 and
/// above the counter's start, the energy never going back between two reads; an address the map
/// leaves out refused with 02.
#[test]
#[ignore = "needs python3 with pymodbus; .ci/run installs it and runs this with --ignored"]
fn pymodbus_reads_the_built_in_meters_at_their_maps_addresses_and_types() {
    for (name, unit) in [("sdm630", 1u8), ("sdm120", 2), ("sdm230", 3)] {
        let (_sim, addr, said) = emulate(&["--device", &format!("{name}@{unit}")]);
        assert!(said.contains(name), "{said}");
        let volts = float_of(&pymodbus_read(&addr, unit, "input", 0, 2));
        assert!((225.0..235.0).contains(&volts), "{name}: input 0 = {volts} V");
        let hertz = float_of(&pymodbus_read(&addr, unit, "input", 70, 2));
        assert!((49.9..50.1).contains(&hertz), "{name}: input 70 = {hertz} Hz");
        let first = float_of(&pymodbus_read(&addr, unit, "input", 342, 2));
        std::thread::sleep(std::time::Duration::from_millis(1200));
        let second = float_of(&pymodbus_read(&addr, unit, "input", 342, 2));
        assert!(first > 1234.0 && second >= first, "{name}: total kWh {first} then {second}");
        assert_eq!(pymodbus_read(&addr, unit, "input", 1000, 2)["exception"], 2, "{name}: outside the map");
    }
    // Carlo Gavazzi EM24 and EM340 (holding 0: V L1-N, INT32 low word first, ×0.1 V; 51: Hz,
    // u16 ×0.1; 52: kWh (+) TOT, INT32 low word first, ×0.1 kWh), Chint DTSU666 (holding 2006h:
    // Ua, a float in 0.1 V; 401Eh: ImpEp, a float in kWh) and DDSU666 (input 2000h: U, a float in
    // V; 4000h: Ep, kWh).
    let low_first = |answer: &serde_json::Value| {
        let r = answer["registers"].as_array().unwrap_or_else(|| panic!("{answer}"));
        let w: Vec<u32> = r.iter().map(|w| u32::try_from(w.as_u64().unwrap()).unwrap()).collect();
        f64::from((w[1] << 16 | w[0]).cast_signed())
    };
    for (name, unit) in [("em24", 4u8), ("em340", 5)] {
        let (_sim, addr, said) = emulate(&["--device", &format!("{name}@{unit}")]);
        assert!(said.contains(name), "{said}");
        let volts = low_first(&pymodbus_read(&addr, unit, "holding", 0, 2)) * 0.1;
        assert!((225.0..235.0).contains(&volts), "{name}: holding 0 = {volts} V");
        let hertz = &pymodbus_read(&addr, unit, "holding", 51, 1)["registers"][0];
        assert!((499..=501).contains(&hertz.as_u64().unwrap()), "{name}: holding 51 = {hertz} (0.1 Hz)");
        let first = low_first(&pymodbus_read(&addr, unit, "holding", 52, 2)) * 0.1;
        std::thread::sleep(std::time::Duration::from_millis(1200));
        let second = low_first(&pymodbus_read(&addr, unit, "holding", 52, 2)) * 0.1;
        assert!(first > 1234.0 && second >= first, "{name}: kWh {first} then {second}");
        assert_eq!(pymodbus_read(&addr, unit, "holding", 200, 2)["exception"], 2, "{name}: outside the map");
    }
    let (_sim, addr, _) = emulate(&["--device", "dtsu666@6"]);
    let tenths = f64::from(float_of(&pymodbus_read(&addr, 6, "holding", 0x2006, 2)));
    assert!((2250.0..2350.0).contains(&tenths), "dtsu666: holding 2006h = {tenths} (0.1 V)");
    let kwh = float_of(&pymodbus_read(&addr, 6, "holding", 0x401E, 2));
    assert!(kwh > 1234.0, "dtsu666: ImpEp {kwh}");
    let (_sim, addr, _) = emulate(&["--device", "ddsu666@7"]);
    let volts = float_of(&pymodbus_read(&addr, 7, "input", 0x2000, 2));
    assert!((225.0..235.0).contains(&volts), "ddsu666: input 2000h = {volts} V");
    assert!(float_of(&pymodbus_read(&addr, 7, "input", 0x4000, 2)) > 1234.0, "ddsu666: Ep");

    // ABB B21, B23, B24 (holding 5B00h: Voltage L1-N, u32 high word first, 0.1 V; 5000h: Active
    // import energy, u64 high word first, 0.01 kWh).
    for (name, unit) in [("b21", 8u8), ("b23", 9), ("b24", 10)] {
        let (_sim, addr, _) = emulate(&["--device", &format!("{name}@{unit}")]);
        let words = |a: &serde_json::Value| -> Vec<u64> {
            a["registers"].as_array().unwrap_or_else(|| panic!("{a}")).iter().map(|w| w.as_u64().unwrap()).collect()
        };
        let v = words(&pymodbus_read(&addr, unit, "holding", 0x5B00, 2));
        let decivolts = v[0] << 16 | v[1];
        assert!((2250..2350).contains(&decivolts), "{name}: 5B00h = {decivolts} (0.1 V)");
        let e = words(&pymodbus_read(&addr, unit, "holding", 0x5000, 4));
        let centi_kwh = e.iter().fold(0, |acc, w| acc << 16 | w);
        assert!(centi_kwh > 123_400, "{name}: 5000h = {centi_kwh} (0.01 kWh)");
    }

    let out = Command::new(BIN).args(["profiles", "list"]).output().unwrap();
    let listed = String::from_utf8_lossy(&out.stdout);
    for name in ["sdm120", "sdm230", "sdm630", "em24", "em340", "dtsu666", "ddsu666", "b21", "b23", "b24"] {
        assert!(listed.contains(name), "profiles list: {listed}");
    }
    let out = Command::new(BIN).args(["profiles", "show", "sdm630"]).output().unwrap();
    let shown = String::from_utf8_lossy(&out.stdout);
    assert!(shown.contains("Phase 1 line to neutral volts") && shown.contains("Total kWh"), "{shown}");
    let out = Command::new(BIN).args(["profiles", "show", "em24"]).output().unwrap();
    let shown = String::from_utf8_lossy(&out.stdout);
    assert!(shown.contains("V L1-N") && shown.contains("kWh (+) TOT"), "{shown}");
}
