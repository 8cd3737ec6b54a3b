//! The real `mbtap decode` binary: the three examples, transactions, stdin, JSON lines,
//! unreadable input and `--help`, snapshot-tested with insta.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::io::Write;
use std::process::{Command, Output, Stdio};

fn mbtap(args: &[&str], stdin: Option<&str>) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        // The user's own configuration must not change what the tests see.
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    if let Some(s) = stdin {
        child.stdin.take().unwrap().write_all(s.as_bytes()).unwrap();
    }
    drop(child.stdin.take());
    child.wait_with_output().unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8(o.stdout.clone()).unwrap()
}

#[test]
fn read_holding_registers_response() {
    let o = mbtap(&["decode", "01 03 06 00 00 00 00 01 90 20 89"], None);
    assert_eq!(o.status.code(), Some(0));
    let s = stdout(&o);
    assert!(s.contains("unit 1"), "{s}");
    assert!(s.contains("Read Holding Registers"), "{s}");
    assert!(s.contains("3 register(s)"), "{s}");
    assert!(s.contains("CRC ok"), "{s}");
    insta::assert_snapshot!(s);
}

#[test]
fn ascii_read_request() {
    let o = mbtap(&["decode", ":01030065000394"], None);
    assert_eq!(o.status.code(), Some(0));
    let s = stdout(&o);
    assert!(s.contains("address: 101") && s.contains("quantity: 3") && s.contains("LRC ok"), "{s}");
    insta::assert_snapshot!(s);
}

#[test]
fn exception_response() {
    let o = mbtap(&["decode", "0183030131"], None);
    assert_eq!(o.status.code(), Some(0));
    let s = stdout(&o);
    assert!(s.contains("Illegal Data Value") && s.contains("Exception to Read Holding Registers"), "{s}");
    insta::assert_snapshot!(s);
}

#[test]
fn request_then_response_is_one_transaction_with_addresses() {
    let o = mbtap(&["decode", "01 03 00 65 00 03 15 D4", "0103060000000001902089"], None);
    let s = stdout(&o);
    assert!(s.starts_with("transaction: unit 1"), "{s}");
    assert!(s.contains("103 = 400"), "{s}");
    insta::assert_snapshot!(s);
}

#[test]
fn jsonl_carries_the_contract_keys() {
    let o = mbtap(&["decode", "--format", "jsonl"], Some("0183030131\n# a comment\n\n:01030065000394\n"));
    assert_eq!(o.status.code(), Some(0));
    let lines: Vec<serde_json::Value> = stdout(&o).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["event"], "frame");
    assert_eq!(lines[0]["hex"], "0183030131");
    assert_eq!(lines[0]["check_ok"], true);
    assert_eq!(lines[0]["unit"], 1);
    assert_eq!(lines[0]["function"], 131);
    assert_eq!(lines[0]["fields"]["exception_code"], 3);
    assert_eq!(lines[1]["fields"]["address"], 101);
    assert_eq!(lines[1]["hex"], ":01030065000394\r\n");
}

#[test]
fn jsonl_transaction_has_both_frames() {
    let o = mbtap(&["decode", "--format", "jsonl", "01 03 00 65 00 03 15 D4", "0103060000000001902089"], None);
    let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(j["event"], "transaction");
    assert_eq!(j["response"]["fields"]["registers"], serde_json::json!([0, 0, 400]));
    assert_eq!(j["response"]["fields"]["registers_start_address"], 101);
}

#[test]
fn unreadable_input_gets_one_line_and_exit_2() {
    let o = mbtap(&["decode", "01 0G 00"], None);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8(o.stderr).unwrap();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("'G' at column 5"), "{err}");
}

#[test]
fn bad_crc_exits_1_and_says_so() {
    let o = mbtap(&["decode", "01 03 06 00 00 00 00 01 90 20 88"], None);
    assert_eq!(o.status.code(), Some(1));
    assert!(stdout(&o).contains("CRC FAILED: received 0x8820, computed 0x8920"));
}

#[test]
fn mode_can_be_forced() {
    let o = mbtap(&["decode", "--mode", "tcp", "00 01 00 00 00 06 11 03 00 6B 00 03"], None);
    assert_eq!(o.status.code(), Some(0));
    assert!(stdout(&o).starts_with("TCP tid 1 unit 17"));
}

#[test]
fn help_is_stable() {
    let o = mbtap(&["decode", "--help"], None);
    insta::assert_snapshot!(stdout(&o));
}

/// The example with a profile: the phase voltages L1, L2, L3 and their average.
#[test]
fn decode_with_a_profile_shows_scaled_values() {
    let profile = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/example-profile.toml");
    let o =
        mbtap(&["decode", "--device", &format!("1={profile}"), "010401AE000491D4", "010408090108FA09060900C836"], None);
    assert_eq!(o.status.code(), Some(0));
    let s = stdout(&o);
    for want in ["230.5 V", "229.8 V", "231.0 V", "230.4 V", "Phase A (L1) voltage"] {
        assert!(s.contains(want), "{want} missing from\n{s}");
    }
    let o = mbtap(
        &[
            "decode",
            "--format",
            "jsonl",
            "--device",
            &format!("1={profile}"),
            "010401AE000491D4",
            "010408090108FA09060900C836",
        ],
        None,
    );
    let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(j["annotations"][0]["value"], 230.5);
    assert_eq!(j["annotations"][0]["unit"], "V");
}

#[test]
fn a_bad_profile_is_reported_with_its_position() {
    let dir = std::env::temp_dir().join(format!("mbtap-profile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[profile]\nname = \"x\"\ndevice = \"y\"\n\n[[input_registers]]\naddress = 430\nname = \"v\"\nscael = 0.1\n",
    )
    .unwrap();
    let o = mbtap(&["profiles", "check", bad.to_str().unwrap()], None);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(err.contains("bad.toml:8:1: unknown field `scael`"), "{err}");
}

/// `replay --image`: the latest value of every register seen, with the transaction it came
/// from, named and scaled by the unit's profile (MK4 document examples: 101–105 written last
/// by the 0x10 example, transaction 9).
#[test]
fn replay_writes_the_register_image() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/mk4-doc-examples-rtu.pcapng");
    let out = std::env::temp_dir().join(format!("mbtap-image-{}.json", std::process::id()));
    let o =
        mbtap(&["replay", capture, "--device", "1=mk4", "--format", "summary", "--image", out.to_str().unwrap()], None);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let image: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let row =
        image.as_array().unwrap().iter().find(|r| r["table"] == "holding_registers" && r["address"] == 104).unwrap();
    assert_eq!(
        (row["raw"].as_u64(), row["value"].as_str(), row["transaction"].as_u64()),
        (Some(300), Some("3.00"), Some(9))
    );
    assert_eq!(row["name"], "Level 1 set point (all pumps off)");
    let coil = image.as_array().unwrap().iter().find(|r| r["table"] == "coils" && r["address"] == 3).unwrap();
    assert_eq!(coil["value"], "on", "coil 003 was last written on (05 example)");
}

#[test]
fn unknown_device_lists_the_known_profiles_and_lang_ru_shows_document_names() {
    let o = mbtap(&["decode", "--device", "1=nope", "0183030131"], None);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(err.contains("built-in profiles are mk4, mkzp, display"), "{err}");
    let o =
        mbtap(&["decode", "--device", "1=mk4", "--lang", "ru", "010401AE000491D4", "010408090108FA09060900C836"], None);
    assert!(stdout(&o).contains("430 Напряжение фазы А(L1), В = 230.5 V"), "{}", stdout(&o));
}

#[test]
fn user_profiles_are_found_by_name_in_the_profile_directory() {
    let dir = std::env::temp_dir().join(format!("mbtap-user-profiles-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/example-profile.toml"), dir.join("pump.toml"))
        .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_PROFILE_DIR", &dir)
        .args(["decode", "--device", "1=pump", "010401AE000491D4", "010408090108FA09060900C836"])
        .output()
        .unwrap();
    assert!(String::from_utf8(o.stdout).unwrap().contains("230.5 V"));
    let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_PROFILE_DIR", &dir)
        .args(["profiles", "list"])
        .output()
        .unwrap();
    let list = String::from_utf8(o.stdout).unwrap();
    assert!(list.contains("pump") && list.contains("mk4"), "{list}");
}

#[test]
fn the_config_file_assigns_devices_and_the_command_line_overrides_it() {
    let dir = std::env::temp_dir().join(format!("mbtap-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("config.toml");
    std::fs::write(&cfg, "[devices]\n1 = \"mk4\"\n").unwrap();
    let run = |extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .env("MBTAP_CONFIG", &cfg)
            .arg("decode")
            .args(extra)
            .args(["010401AE000491D4", "010408090108FA09060900C836"])
            .output()
            .unwrap();
        String::from_utf8(o.stdout).unwrap()
    };
    assert!(run(&[]).contains("Phase A (L1) voltage = 230.5 V"));
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/example-profile.toml");
    // Registers 465–466: the MK4's water meter, the example profile's 32-bit energy counter.
    let read_465 = |extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .env("MBTAP_CONFIG", &cfg)
            .arg("decode")
            .args(extra)
            .args(["010401D10002200E", "010404000100022B85"])
            .output()
            .unwrap();
        String::from_utf8(o.stdout).unwrap()
    };
    assert!(read_465(&[]).contains("465 Water meter: thousands of m³"), "{}", read_465(&[]));
    let overridden = read_465(&["--device", &format!("1={example}")]);
    assert!(overridden.contains("465 Energy counter = 65538 kWh"), "{overridden}");
    std::fs::write(&cfg, "[devices]\n1 = \"mk4\"\n999 = \"x\"\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_CONFIG", &cfg)
        .args(["decode", "0183030131"])
        .output()
        .unwrap();
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(err.contains("config.toml:3:1: device unit \"999\""), "{err}");
}

/// `010304050001953B00` is a request (read 1 register from 0x0405) followed by the `00` a
/// transceiver leaves at turnaround, not a 9-byte response with byte count 4 — CRC-16/MODBUS
/// validates any valid frame with a `00` appended.
#[test]
fn decode_010304050001953b00_is_a_request_and_a_glitch() {
    let o = mbtap(&["decode", "010304050001953B00"], None);
    let s = stdout(&o);
    assert!(s.contains("request · CRC ok"), "{s}");
    assert!(s.contains("glitch: 00"), "{s}");
    assert!(!s.contains("response"), "{s}");
    assert_eq!(o.status.code(), Some(1), "a line that is more than its frame is a problem");
    let j = stdout(&mbtap(&["decode", "--format", "jsonl", "010304050001953B00"], None));
    let events: Vec<serde_json::Value> = j.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(events.len(), 2, "{j}");
    assert_eq!(events[0]["event"], "frame");
    assert_eq!(events[0]["hex"], "010304050001953b");
    assert_eq!(events[1]["event"], "glitch");
    assert_eq!(events[1]["hex"], "00");
}

/// Three valid frames pasted glued from a sniffer log are split as a replay splits them, not one
/// frame with the CRC taken from the end of the line ("CRC FAILED").
#[test]
fn glued_frames_on_one_line_are_split_into_them() {
    // Read 3 registers from 101 (unit 1), its answer, then an exception from unit 1 to FC 03.
    const GLUED: &str = concat!(
        "01030065000315D4",       // unit 1, read 3 holding registers from 101, CRC
        "0103060000000001902089", // its answer: 0, 0, 400, CRC
        "0183030131",             // unit 1, exception 03 to function 03, CRC
    );
    let o = mbtap(&["decode", GLUED], None);
    let s = stdout(&o);
    assert_eq!(s.matches("CRC ok").count(), 3, "{s}");
    assert!(!s.contains("CRC FAILED"), "{s}");
    assert!(s.contains("transaction: unit 1"), "{s}");
    assert!(s.contains("Exception to Read Holding Registers"), "{s}");
    assert_eq!(o.status.code(), Some(0), "{s}");
}

/// A truncated answer after its request is a bad response in `decode` as in `replay`, never a
/// request with absurd quantities.
#[test]
fn a_truncated_answer_after_its_request_is_a_truncated_response() {
    let o = mbtap(&["decode", "01030065000315D4", "010306000000"], None);
    let s = stdout(&o);
    assert!(s.contains("transaction: unit 1"), "{s}");
    assert!(s.contains("too short"), "{s}");
    assert!(!s.contains("quantity: 0"), "{s}");
    assert_eq!(o.status.code(), Some(1));
}

/// `decode` prints each line's result as the line comes in (`tail -f log | mbtap decode` shows
/// results), never reading all of stdin first.
#[test]
fn decode_streams_one_line_in_one_result_out() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .arg("decode")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    // An exception answer: nothing can pair with it, so it is shown at once — stdin still open.
    stdin.write_all(b"0183030131\n").unwrap();
    stdin.flush().unwrap();
    let first = rx.recv_timeout(std::time::Duration::from_secs(20)).expect("no output while stdin stays open");
    assert!(first.contains("Exception"), "{first}");
    drop(stdin);
    assert_eq!(child.wait().unwrap().code(), Some(0));
}

/// One Latin-1 byte in a comment costs its line, named by number, not the whole input ("stream did
/// not contain valid UTF-8"); a line of megabytes is cut, never held whole.
#[test]
fn decode_reads_bytes_names_bad_lines_and_cuts_endless_ones() {
    let mut input = b"# caf\xe9 au lait\n0183030131\n".to_vec();
    input.extend(std::iter::repeat_n(b'A', 5_000_000));
    input.extend_from_slice(b"\n01 03 06 00 00 00 00 01 90 20 89\nT\xe9: 01 03\n");
    let mut child = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .arg("decode")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(&input));
    let o = child.wait_with_output().unwrap();
    writer.join().unwrap().unwrap();
    let (out, err) = (stdout(&o), String::from_utf8_lossy(&o.stderr).into_owned());
    assert!(out.contains("Exception") && out.contains("3 register(s)"), "{out}");
    assert!(err.contains("line 3 is longer than 4096 characters"), "{err}");
    assert!(err.contains("input 3") || err.contains("input 4"), "the bad lines are named: {err}");
    assert_eq!(o.status.code(), Some(2), "some input was not a frame");
}

/// `decode ":"` counts the one character typed (not "ASCII frame of 3 bytes").
#[test]
fn a_lone_colon_counts_what_was_typed() {
    let o = mbtap(&["decode", ":"], None);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(err.contains("needs at least 6 characters after ':'") && err.contains("has 0"), "{err}");
}

/// Real log formats are read: the timestamp and the tag are set aside (and shown in JSON lines),
/// the tag read as the direction.
#[test]
fn log_formats_are_read_and_what_was_stripped_is_shown() {
    let input = "2024-05-01 12:00:01.123 Tx: 01.03.00.65.00.03.15.D4\n12:00:01.140 Rx: 0x1 0x3 0x6 0x0 0x0 0x0 0x0 0x1 0x90 0x20 0x89\n";
    let o = mbtap(&["decode"], Some(input));
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout(&o).contains("transaction: unit 1"), "{}", stdout(&o));
    let o = mbtap(&["decode", "--format", "jsonl", "12:00:01.123 > 0183030131"], None);
    let j: serde_json::Value = serde_json::from_str(stdout(&o).lines().next().unwrap()).unwrap();
    assert_eq!((j["timestamp"].as_str(), j["tag"].as_str()), (Some("12:00:01.123"), Some(">")));
}

/// A name with an escape sequence (`^[]0;pwned^G^[[2J`) never reaches the terminal raw (it would
/// retitle and clear it); nor does an ASCII frame from the bus.
#[test]
fn control_characters_from_profiles_and_frames_never_reach_the_terminal() {
    let dir = std::env::temp_dir().join(format!("mbtap-escape-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let profile = dir.join("hostile.toml");
    std::fs::write(
        &profile,
        "[profile]\nname = \"hostile\"\ndevice = \"x\"\n\n[[holding_registers]]\naddress = 101\nname = \"pump\\u001b]0;pwned\\u0007\\u001b[2J\"\n",
    )
    .unwrap();
    let device = format!("1={}", profile.display());
    let o = mbtap(&["decode", "--device", &device, "01030065000315D4", "0103060000000001902089"], None);
    let s = stdout(&o);
    assert!(s.contains("pump"), "{s}");
    assert!(!s.contains('\u{1b}') && !s.contains('\u{7}'), "a control character reached stdout: {s:?}");
    assert!(s.contains("\\u{1b}"), "shown escaped: {s}");
}

/// A response cut short (byte count 6, the frame ends 3 bytes early) is not only a request with an
/// absurd quantity, as `replay` calls the same bytes a bad response: without the request before it
/// `decode` cannot choose, so it shows both readings.
#[test]
fn a_truncated_response_is_shown_as_both_readings() {
    // Unit 1, 03, byte count 6, registers 000A 000B and one byte of the third: 3 bytes missing
    // (the third register's low byte and the CRC).
    const CUT: &str = "01 03 06 00 0A 00 0B 00";
    let o = mbtap(&["decode", CUT], None);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("· request ·"), "{text}");
    assert!(text.contains("or: a truncated response — 0x03 whose byte count (6) makes the frame 11 bytes"), "{text}");
    assert!(text.contains("8 received, 3 missing"), "{text}");
    let o = mbtap(&["decode", "--format", "jsonl", CUT], None);
    let j: serde_json::Value = serde_json::from_slice(o.stdout.split(|&b| b == b'\n').next().unwrap()).unwrap();
    assert_eq!(j["or_truncated_response"]["expected_len"], 11, "{j}");
    // A request with a damaged CRC and a plausible structure gets no such second reading.
    let o = mbtap(&["decode", "01 03 00 65 00 03 15 D5"], None);
    assert!(!String::from_utf8_lossy(&o.stdout).contains("truncated"));
}

/// `decode -` reads standard input (`-` is no frame), and Modbus Poll's log lines (`Tx:000001-…`)
/// decode without their counter taken for noise.
#[test]
fn a_dash_reads_stdin_and_modbus_poll_logs_decode() {
    let log = "Tx:000001-01 03 00 65 00 03 15 D4\nRx:000002-01 03 06 00 00 00 00 01 90 20 89\n";
    let o = mbtap(&["decode", "-"], Some(log));
    let out = stdout(&o);
    assert!(o.status.success(), "{out}{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("Read Holding Registers") && !out.contains("noise"), "{out}");
}

/// Pasted verbatim: a request to unit 254 and the `00` a transceiver left after it are a request
/// and a glitch, as for every other unit (units 248–255 included), not one 9-byte "request, CRC ok
/// (0x00C5)" with a trailing byte.
#[test]
fn a_reserved_unit_gets_its_glitch_split_like_any_other() {
    let o = mbtap(&["decode", "FE 04 00 03 00 01 D5 C5 00"], None);
    let out = stdout(&o);
    assert!(out.contains("RTU unit 254 · 0x04 Read Input Registers · request · CRC ok (0xC5D5)"), "{out}");
    assert!(out.contains("glitch: 00 right after the frame"), "{out}");
    assert!(!out.contains("trailing"), "{out}");
}

/// Pasted verbatim: two CRC-valid 5-byte exception answers glued (a slave answering for an absent
/// one) are two frames, not one 10-byte frame with a failed CRC; the first, function 0, is shown as
/// such with a finding.
#[test]
fn glued_exceptions_are_split_and_function_zero_is_named() {
    let o = mbtap(&["decode", "21 80 01 81 CA 21 8A 01 87 6A"], None);
    let out = stdout(&o);
    assert!(out.contains("CRC ok (0xCA81)") && out.contains("CRC ok (0x6A87)"), "{out}");
    assert!(out.contains("an exception to function 0, which does not exist"), "{out}");
    assert!(!out.contains("CRC FAILED"), "{out}");
}
