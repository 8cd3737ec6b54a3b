//! `mbtap read`, `write` and `watch` against `mbtap simulate` on a real pseudo-terminal, and
//! through `mbtap bridge` over Modbus TCP and RTU over TCP. The third-party peers (mbpoll,
//! pymodbus's TCP server, socat for "nothing on the line") are in `tests/master/interop_master.rs`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use crate::common;
use common::{BIN, Kill};

fn simulator(name: &str) -> (Kill, PathBuf) {
    let dir = std::env::temp_dir().join(format!("mbtap-master-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bus = dir.join("bus");
    let sim = common::simulate(&bus, &["--duration", "60"]);
    (sim, bus)
}

fn mbtap(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn json_lines(o: &Output) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(&o.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn read_by_name_gives_named_scaled_values_with_the_image_keys() {
    let (_sim, bus) = simulator("names");
    let o = mbtap(&[
        "read",
        bus.to_str().unwrap(),
        "--device",
        "mk4",
        "--format",
        "jsonl",
        "Phase A (L1) voltage",
        "430..433",
        "operating mode",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = json_lines(&o);
    assert_eq!(rows.len(), 6, "{rows:?}");
    for key in ["unit", "table", "address", "name", "raw", "value", "unit_of_measure"] {
        assert!(rows[0].get(key).is_some(), "missing {key}: {}", rows[0]);
    }
    assert_eq!(rows[0]["name"], "Phase A (L1) voltage");
    assert_eq!(rows[0]["table"], "input_registers", "the range's table comes from the profile");
    assert_eq!(rows[0]["unit_of_measure"], "V");
    let raw: Vec<i64> = rows[1..5].iter().map(|r| r["raw"].as_i64().unwrap()).collect();
    assert!(raw.iter().all(|v| (2000..=2600).contains(v)), "mains voltages in 0.1 V: {raw:?}");
    // The scaled value is the raw value at the profile's scale 0.1.
    let scaled = rows[1]["value"].as_f64().unwrap();
    assert!((scaled * 10.0 - f64::from(i32::try_from(raw[0]).unwrap())).abs() < 1e-6, "{}", rows[1]);
    assert_eq!(rows[5]["name"], "Operating mode");
    assert!(rows[5]["value"].is_string(), "an enum reads as its label: {}", rows[5]);
}

#[test]
fn all_three_builtin_devices_read_by_name() {
    let (_sim, bus) = simulator("three");
    let b = bus.to_str().unwrap();
    for (unit, device, item, name) in [
        ("1", "mk4", "Average phase voltage", "Average phase voltage"),
        ("17", "mkzp", "voltage", "Voltage"),
        ("5", "display", "Level sensor 1: temperature", "Level sensor 1: temperature"),
    ] {
        let o = mbtap(&["read", b, "--unit", unit, "--device", device, "--format", "jsonl", item]);
        assert!(o.status.success(), "{device}: {}", text(&o));
        let rows = json_lines(&o);
        assert_eq!(rows.len(), 1, "{device}: {rows:?}");
        assert_eq!(rows[0]["name"], name, "{device}");
        assert_eq!(rows[0]["unit"].as_u64(), unit.parse().ok(), "{device}");
    }
}

#[test]
fn a_write_is_echoed_and_a_clamped_one_fails_the_run() {
    let (_sim, bus) = simulator("write");
    let b = bus.to_str().unwrap();
    let o = mbtap(&["write", b, "--device", "mk4", "--format", "text", "Level 2 set point=1.50"]);
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    assert!(out.contains("wrote holding 105"), "{out}");
    assert!(out.contains("read back holding 105 Level 2 set point (pump 1 on) = 1.50 (raw 150)"), "{out}");
    // Out of range: refused before sending, with the reason.
    let o = mbtap(&["write", b, "--device", "mk4", "Level 2 set point=150"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("outside the documented range 0..=10000"), "{}", text(&o));
    // Forced: the MK4 clamps (document §3.3) and the echo shows it; the run fails.
    let o = mbtap(&["write", b, "--device", "mk4", "--force", "--format", "jsonl", "Level 2 set point=150"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let echo = &json_lines(&o)[0];
    assert_eq!(echo["event"], "write");
    assert_eq!(echo["kept_as_written"], false, "{echo}");
    assert_eq!(echo["read_back"][0]["raw"], 10000, "{echo}");
}

#[test]
fn exceptions_and_silence_are_reported_per_request_and_fail_the_run() {
    let (_sim, bus) = simulator("errors");
    let b = bus.to_str().unwrap();
    let o = mbtap(&["read", b, "--format", "jsonl", "holding", "9999", "holding", "101"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let lines = json_lines(&o);
    let err = lines.iter().find(|l| l.get("error").is_some()).unwrap();
    assert_eq!(err["item"], "holding 9999");
    assert!(err["error"].as_str().unwrap().contains("Illegal Data Address"), "{err}");
    assert!(
        lines.iter().any(|l| l["address"] == 101 && l.get("raw").is_some()),
        "the good read still shows: {lines:?}"
    );
    let o = mbtap(&["read", b, "--unit", "9", "--timeout-ms", "200", "--format", "jsonl", "holding", "1"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("no answer from unit 9 within 200 ms"), "{}", text(&o));
}

#[test]
fn a_name_typo_gets_a_suggestion_and_nothing_is_sent() {
    let o = mbtap(&["read", "/nonexistent/port", "--device", "mk4", "Operating mdoe"]);
    assert_eq!(o.status.code(), Some(2));
    let t = text(&o);
    assert!(t.contains("did you mean \"Operating mode\""), "{t}");
    assert!(!t.contains("/nonexistent/port"), "checked before the port was opened: {t}");
}

#[test]
fn dry_run_prints_the_frame_and_opens_nothing() {
    let o = mbtap(&["write", "/nonexistent/port", "--device", "mk4", "--dry-run", "Level 2 set point=2.50"]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    // Unit 1, function 06, address 105 (0x0069), value 250 (0x00FA), CRC.
    assert!(t.contains("01 06 00 69 00 FA D9 95"), "{t}");
    assert!(t.contains("dry run: nothing sent"), "{t}");
}

/// Starts `mbtap bridge` on `bus`; its Modbus TCP and RTU-over-TCP addresses.
fn bridge(bus: &Path) -> (Kill, String, String) {
    let mut child = Command::new(BIN)
        .args(["bridge", "--serial", bus.to_str().unwrap(), "--listen", "127.0.0.1:0", "--listen-rtu", "127.0.0.1:0"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let (mut tcp, mut rtu) = (None, None);
    while tcp.is_none() || rtu.is_none() {
        let line = lines.next().expect("the bridge ended before listening").unwrap();
        if let Some(rest) = line.strip_prefix("mbtap: bridge listening on ") {
            let addr = rest.split_whitespace().next().unwrap().to_owned();
            if rest.contains("(Modbus TCP)") { tcp = Some(addr) } else { rtu = Some(addr) }
        }
    }
    std::thread::spawn(move || for _ in lines {});
    (Kill(child), tcp.unwrap(), rtu.unwrap())
}

#[test]
fn read_and_watch_through_the_bridge_over_tcp_and_rtu_over_tcp() {
    let (_sim, bus) = simulator("bridge");
    let (_bridge, tcp, rtu) = bridge(&bus);
    for target in [tcp.clone(), format!("rtu+tcp://{rtu}")] {
        let o = mbtap(&["read", &target, "--device", "mk4", "--format", "jsonl", "430..433"]);
        assert!(o.status.success(), "{target}: {}", text(&o));
        assert_eq!(json_lines(&o).len(), 4, "{target}");
    }
    let o =
        mbtap(&["watch", &tcp, "--device", "mk4", "--interval", "50ms", "--count", "3", "--format", "jsonl", "430"]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = json_lines(&o);
    let rounds: Vec<u64> = rows.iter().map(|r| r["round"].as_u64().unwrap()).collect();
    assert_eq!(rounds, [1, 2, 3], "{rows:?}");
    assert!(rows.windows(2).all(|w| w[0]["t_ns"].as_u64() < w[1]["t_ns"].as_u64()), "{rows:?}");
}

/// Found while building `read`: `mbtap profiles show display | head` panicked on the closed
/// pipe (println!). A closed pipe is success, with nothing on stderr.
#[test]
fn profiles_show_into_a_closed_pipe_does_not_panic() {
    let mut child = Command::new(BIN)
        .args(["profiles", "show", "display"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && !err.contains("panicked"), "{err}");
}

/// A profile whose names and units carry terminal escape sequences (a hostile or mangled
/// import): MK4 input registers 430–431 under names that would retitle and clear a terminal.
const HOSTILE_PROFILE: &str = "[profile]\nname = \"evil\\u001b]0;pwned\\u0007\"\ndevice = \"Pump\\u001b[2J\"\n\
    functions = [3, 4]\n\n[[input_registers]]\naddress = 430\nname = \"Volts\\u001b[31m\"\nunit = \"V\\u009b1m\"\nscale = 0.1\n";

/// Control characters in profile names and units never reach the terminal in `profiles show` and
/// `read`'s text output.
#[test]
fn control_characters_in_profiles_never_reach_the_terminal() {
    let (_sim, bus) = simulator("escape");
    let file = bus.with_file_name("evil.toml");
    std::fs::write(&file, HOSTILE_PROFILE).unwrap();
    let f = file.to_str().unwrap();
    let shown = mbtap(&["profiles", "show", f]);
    let read = mbtap(&["read", bus.to_str().unwrap(), "--device", f, "--format", "text", "input", "430"]);
    for o in [&shown, &read] {
        let all = text(o);
        assert!(o.status.success(), "{all}");
        assert!(!all.chars().any(|c| c.is_control() && c != '\n'), "{all:?}");
        assert!(all.contains("\\u{1b}"), "shown escaped: {all}");
    }
    assert!(text(&read).contains("Volts"), "{}", text(&read));
}

/// `write --unit 0` broadcasts a profile write only with --force, and a command register takes its
/// documented commands only.
#[test]
fn a_broadcast_write_or_an_undocumented_command_needs_force() {
    let (_sim, bus) = simulator("broadcast");
    let b = bus.to_str().unwrap();
    let o = mbtap(&["write", b, "--device", "mk4", "--unit", "0", "Level 2 set point=1.23"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("broadcast") && text(&o).contains("--force"), "{}", text(&o));
    let o = mbtap(&["read", b, "--device", "mk4", "--format", "jsonl", "Level 2 set point"]);
    assert_ne!(json_lines(&o)[0]["raw"], 123, "nothing was sent: {}", text(&o));
    // MK4 holding 126 "Clear alarm log" documents one command, 30.
    let o = mbtap(&["write", b, "--device", "mk4", "Clear alarm log=31"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("not one of the documented commands"), "{}", text(&o));
    // On purpose: sent once, said as a broadcast, nothing read back, success.
    let o =
        mbtap(&["write", b, "--device", "mk4", "--unit", "0", "--force", "--format", "text", "Level 2 set point=1.23"]);
    assert!(o.status.success() && text(&o).contains("broadcast holding 105"), "{}", text(&o));
}

/// `read --device mkzp holding 50` asks unit 1 (the profile's default address, where the simulated
/// line has the MK4): the error says which unit was asked and why, rather than blaming the
/// register.
#[test]
fn a_failure_at_the_default_unit_says_which_unit_was_asked() {
    let (_sim, bus) = simulator("default-unit");
    let o = mbtap(&["read", bus.to_str().unwrap(), "--device", "mkzp", "--format", "text", "holding", "50"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("unit 1 was asked because it is the mkzp profile's default address"), "{}", text(&o));
    let o = mbtap(&[
        "read",
        bus.to_str().unwrap(),
        "--device",
        "mkzp",
        "--unit",
        "17",
        "--format",
        "text",
        "holding",
        "50",
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

/// `watch` of two ranges of the same shape (FC03, 2 registers) on a device of `delay_ms` with a
/// 300 ms timeout: (values right, values under the wrong register).
fn watch_late_device(delay_ms: u32) -> (usize, usize) {
    let dir = std::env::temp_dir().join(format!("mbtap-late-{}-{delay_ms}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("tty");
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/late_slave.py");
    let mut slave = std::process::Command::new("python3")
        .args([script.to_str().unwrap(), link.to_str().unwrap(), &delay_ms.to_string()])
        .spawn()
        .expect("python3");
    for _ in 0..100 {
        if link.exists() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["watch", link.to_str().unwrap(), "--unit", "1", "--timeout-ms", "300", "--retries", "0"])
        .args([
            "--interval",
            "100ms",
            "--count",
            "4",
            "--format",
            "jsonl",
            "holding",
            "100..101",
            "holding",
            "200..201",
        ])
        .output()
        .unwrap();
    let _ = slave.kill();
    let _ = slave.wait();
    let _ = std::fs::remove_dir_all(&dir);
    let (mut right, mut wrong) = (0, 0);
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else { continue };
        if let (Some(a), Some(raw)) = (v["address"].as_u64(), v["raw"].as_u64()) {
            if raw == 1000 + a { right += 1 } else { wrong += 1 }
        }
    }
    (right, wrong)
}

/// A device slower than the timeout answers the first range while the second is awaited:
/// after a timeout the line is listened to for the late answer before the next request, so
/// nothing is shown under the wrong register; a device within the timeout is read right.
#[test]
fn a_late_answer_is_never_shown_under_another_request_s_registers() {
    let (_, wrong) = watch_late_device(450);
    assert_eq!(wrong, 0, "values shown under the wrong register");
    let (right, wrong) = watch_late_device(50);
    assert_eq!((right, wrong), (16, 0));
}

/// `rfc2217://` is a serial server, not a port path: `read` connects to it (a line of the
/// bridge's, as `bridge --serial rfc2217://` does) and, with nobody listening, says it could not
/// connect — never "opening serial port" for a file named `rfc2217:`.
#[test]
fn an_rfc2217_target_is_connected_to_as_a_serial_server() {
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["read", &format!("rfc2217://{closed}"), "holding", "0", "--timeout-ms", "300"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stdout) + String::from_utf8_lossy(&o.stderr);
    assert_ne!(o.status.code(), Some(0), "{err}");
    assert!(err.contains(&closed.to_string()) && !err.contains("opening serial port"), "{err}");
}
