//! `mbtap simulate --from CAPTURE` and `--device FILE@UNIT` behind the bridge's Modbus TCP
//! listener: a recording becomes a device that answers what the recording showed,
//! byte for byte, refuses what it refused, and never invents what it did not show. The
//! expected answers are read from the captures' `.txt` hex (the bytes the recordings were
//! made from), not from our own replay.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::common::{self, BIN, Kill};

// Unit 9, FC 03, address 0, quantity 1, CRC 0x4285 (low byte first).
const POLL_9: [u8; 8] = [
    /* unit */ 0x09, /* fc */ 0x03, /* address */ 0x00, 0x00, /* quantity */ 0x00, 0x01,
    /* crc */ 0x85, 0x42,
];

fn capture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("captures").join(name)
}

/// Starts `mbtap simulate ARGS --listen 127.0.0.1:0`; the process, the address it serves on,
/// and what it said before serving.
pub fn emulate(args: &[&str]) -> (Kill, String, String) {
    let all = [args, &["--listen", "127.0.0.1:0", "--duration", "60"][..]].concat();
    let (child, addr, said, _) = common::simulate_listening(&all);
    (child, addr, said)
}

/// The request/answer pairs of a capture's `.txt`: RTU frames in hex, a request line then its
/// answer line; each as (unit, PDU) with the CRC left off.
/// A frame as (unit, PDU).
type Frame = (u8, Vec<u8>);

fn pairs(txt: &str) -> Vec<(Frame, Frame)> {
    let frames: Vec<Frame> = std::fs::read_to_string(capture(txt))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let bytes: Vec<u8> = l.split_whitespace().map(|h| u8::from_str_radix(h, 16).unwrap()).collect();
            (bytes[0], bytes[1..bytes.len() - 2].to_vec())
        })
        .collect();
    frames.chunks(2).map(|c| (c[0].clone(), c[1].clone())).collect()
}

fn connect(addr: &str) -> std::net::TcpStream {
    let s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(5))).unwrap();
    s
}

#[test]
fn a_recorded_power_meter_answers_every_request_as_recorded() {
    // Input registers 0–41, holding 0–45, coils 0–30, discrete inputs 0–5, read once each.
    let (_sim, addr, said) = emulate(&["--from", capture("rtu-real-power-meter.pcapng").to_str().unwrap()]);
    assert!(said.contains("emulating unit 1"), "{said}");
    assert!(said.contains("42 input registers") && said.contains("46 holding registers"), "{said}");
    let mut s = connect(&addr);
    let pairs = pairs("rtu-real-power-meter.txt");
    assert_eq!(pairs.len(), 4);
    for (i, ((unit, request), (_, answer))) in pairs.into_iter().enumerate() {
        let got = common::call(&mut s, u16::try_from(i).unwrap(), unit, &request);
        assert_eq!(got, answer, "request {request:02X?}");
    }
}

#[test]
fn what_the_recording_never_showed_is_refused_not_invented() {
    let (_sim, addr, _) = emulate(&["--from", capture("rtu-real-power-meter.pcapng").to_str().unwrap()]);
    let mut s = connect(&addr);
    // Input registers 41–42: 42 was never read (MAP v1.1b3 §7: 02).
    assert_eq!(common::call(&mut s, 1, 1, &[0x04, 0x00, 0x29, 0x00, 0x02]), [0x84, 0x02]);
    // FC 2B/0E identity, never asked in the recording: 01.
    assert_eq!(common::call(&mut s, 2, 1, &[0x2B, 0x0E, 0x01, 0x00]), [0xAB, 0x01]);
    // Unit 2 is not in the recording: nobody answers, as on a line (0B).
    assert_eq!(common::call(&mut s, 3, 2, &[0x03, 0x00, 0x00, 0x00, 0x01]), [0x83, 0x0B]);
}

/// A recording that only ever read holding register 0 of unit 1: a read of input registers —
/// a function the device never showed — is answered 01, as the docs and the start line say; a
/// holding register it never showed is answered 02.
#[test]
fn a_function_the_recording_never_showed_is_01_and_an_address_02() {
    let dir = std::env::temp_dir().join(format!("mbtap-never-shown-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut text = String::new();
    // FC 03 holding 0, one register, answered 42 (MAP v1.1b3 §6.3), three times.
    for pdu in [[0x03u8, 0x00, 0x00, 0x00, 0x01].as_slice(), [0x03, 0x02, 0x00, 0x2A].as_slice()].repeat(3) {
        let mut frame = Vec::new();
        mbtap_proto::rtu::encode_rtu(1, pdu, &mut frame);
        let hex: Vec<String> = frame.iter().map(|b| format!("{b:02X}")).collect();
        text.push_str(&hex.join(" "));
        text.push('\n');
    }
    let (frames, capture) = (dir.join("holding.txt"), dir.join("holding.pcapng"));
    std::fs::write(&frames, text).unwrap();
    let g = Command::new(BIN)
        .args(["generate", capture.to_str().unwrap(), "--frames", frames.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(g.status.success(), "{}", String::from_utf8_lossy(&g.stderr));
    let (_sim, addr, _) = emulate(&["--from", capture.to_str().unwrap()]);
    let mut s = connect(&addr);
    assert_eq!(common::call(&mut s, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]), [0x03, 0x02, 0x00, 0x2A]);
    assert_eq!(common::call(&mut s, 2, 1, &[0x04, 0x00, 0x00, 0x00, 0x01]), [0x84, 0x01], "a function never shown");
    assert_eq!(common::call(&mut s, 3, 1, &[0x03, 0x00, 0x05, 0x00, 0x01]), [0x83, 0x02], "an address never shown");
    std::fs::remove_dir_all(&dir).ok();
}

/// `simulate --read-only` refuses what could change a device with 01 and still answers reads;
/// a broadcast write (unit 0) over TCP is refused with 01 as the bridge refuses it, and with
/// `--allow-broadcast` reaches the device (unanswered, as a broadcast is) — one rule for both.
#[test]
fn read_only_and_broadcasts_follow_the_bridges_rules() {
    // FC 06 holding 101 (MK4 operating mode) := 1, and := 2 (MAP v1.1b3 §6.6).
    const SET_MODE_1: [u8; 5] = [0x06, 0x00, 0x65, 0x00, 0x01];
    const SET_MODE_2: [u8; 5] = [0x06, 0x00, 0x65, 0x00, 0x02];
    const READ_MODE: [u8; 5] = [0x03, 0x00, 0x65, 0x00, 0x01];
    let (_sim, addr, _) = emulate(&["--device", "mk4@1", "--read-only"]);
    let mut s = connect(&addr);
    assert_eq!(common::call(&mut s, 1, 1, &SET_MODE_1), [0x86, 0x01], "a write under --read-only");
    assert_eq!(common::call(&mut s, 2, 1, &READ_MODE), [0x03, 0x02, 0x00, 0x00], "reads still answered");
    let (_sim, addr, _) = emulate(&["--device", "mk4@1"]);
    let mut s = connect(&addr);
    assert_eq!(common::call(&mut s, 3, 0, &SET_MODE_1), [0x86, 0x01], "a broadcast without --allow-broadcast");
    assert_eq!(common::call(&mut s, 4, 1, &READ_MODE), [0x03, 0x02, 0x00, 0x00], "and nothing changed");
    let (_sim, addr, _) = emulate(&["--device", "mk4@1", "--allow-broadcast"]);
    let mut s = connect(&addr);
    // The broadcast goes unanswered; the next answer is the read's, under its own id.
    let mut frame = vec![0x00, 0x05, 0x00, 0x00, 0x00, 0x06, 0x00];
    frame.extend_from_slice(&SET_MODE_2);
    std::io::Write::write_all(&mut s, &frame).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert_eq!(common::call(&mut s, 6, 1, &READ_MODE), [0x03, 0x02, 0x00, 0x02], "the broadcast was applied");
}

#[test]
fn a_recorded_mk4_gives_its_exceptions_keeps_its_writes_and_reads_by_name() {
    let (_sim, addr, said) = emulate(&["--from", capture("mk4-doc-examples-rtu.pcapng").to_str().unwrap()]);
    assert!(said.contains("1 requests refused as recorded"), "{said}");
    let mut s = connect(&addr);
    // The recording's FC 03 at 0x12 ×6 was refused with 03: so is ours.
    assert_eq!(common::call(&mut s, 1, 1, &[0x03, 0x00, 0x12, 0x00, 0x06]), [0x83, 0x03]);
    // Holding 101–105 as the recording's FC 10 left them: 0, 0, 400, 300, 10.
    let out = Command::new(BIN)
        .args(["read", &addr, "--device", "mk4", "--unit", "1", "--format", "jsonl", "holding", "101..105"])
        .args(["Control"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}{}", String::from_utf8_lossy(&out.stderr));
    let raws: Vec<i64> =
        text.lines().map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["raw"].as_i64().unwrap()).collect();
    // Input 400 "Control" answered 2 (motor M2 on) in the recording.
    assert_eq!(raws, [0, 0, 400, 300, 10, 2], "{text}");
    // A write to a register the recording showed is kept and read back.
    assert_eq!(common::call(&mut s, 2, 1, &[0x06, 0x00, 0x68, 0x00, 0x07]), [0x06, 0x00, 0x68, 0x00, 0x07]);
    assert_eq!(common::call(&mut s, 3, 1, &[0x03, 0x00, 0x68, 0x00, 0x01]), [0x03, 0x02, 0x00, 0x07]);
}

#[test]
fn an_ascii_recording_emulates_the_same_device_as_the_rtu_one() {
    let (_a, rtu, _) = emulate(&["--from", capture("mk4-doc-examples-rtu.pcapng").to_str().unwrap()]);
    let (_b, ascii, said) = emulate(&["--from", capture("mk4-doc-examples-ascii.pcapng").to_str().unwrap()]);
    assert!(said.contains("emulating unit 1"), "{said}");
    let (mut r, mut a) = (connect(&rtu), connect(&ascii));
    for pdu in [[0x04, 0x01, 0x90, 0x00, 0x03], [0x03, 0x00, 0x65, 0x00, 0x05], [0x02, 0x00, 0x32, 0x00, 0x10]] {
        assert_eq!(common::call(&mut r, 1, 1, &pdu), common::call(&mut a, 1, 1, &pdu), "{pdu:02X?}");
    }
}

#[test]
fn a_profile_file_is_a_device_too() {
    let profile = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/example-profile.toml");
    let spec = format!("{}@7", profile.display());
    let (_sim, addr, said) = emulate(&["--device", &spec]);
    assert!(said.contains("simulating mk4-example at address 7"), "{said}");
    let out = Command::new(BIN)
        .args([
            "read",
            &addr,
            "--device",
            profile.to_str().unwrap(),
            "--unit",
            "7",
            "--format",
            "jsonl",
            "input",
            "430..433",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // The file maps input registers 430–433 (phase voltages): all four answered, none refused.
    let text = String::from_utf8_lossy(&out.stdout);
    let answered = text.lines().filter(|l| l.contains("\"raw\":") && !l.contains("\"error\"")).count();
    assert_eq!(answered, 4, "{text}");
}

#[test]
fn bad_sources_are_refused_with_what_to_do() {
    let run = |args: &[&str]| {
        let out = Command::new(BIN).arg("simulate").args(args).args(["--listen", "127.0.0.1:0"]).output().unwrap();
        assert!(!out.status.success(), "{args:?} was accepted");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let meter = capture("rtu-real-power-meter.pcapng");
    let err = run(&["--from", &format!("{}@5", meter.display())]);
    assert!(err.contains("unit 5 did not answer") && err.contains("units that did: 1"), "{err}");
    let err = run(&["--from", "/nonexistent/site.pcapng"]);
    assert!(err.contains("no such file"), "{err}");
    let err = run(&["--device", "no-such-profile@3"]);
    assert!(err.contains("no profile named"), "{err}");
    let err = run(&["--from", meter.to_str().unwrap(), "--device", "mk4@1"]);
    assert!(err.contains("two devices at address 1"), "{err}");
    let err = run(&[
        "--mirror",
        "127.0.0.1:1",
        "--mirror-device",
        "mk4@1",
        "--as",
        "mkzp@2",
        "--map",
        "Phase Z current=input 430",
    ]);
    assert!(err.contains("--map") && err.contains("the served profile mkzp"), "{err}");
    let err = run(&["--mirror", "127.0.0.1:1", "--mirror-device", "mk4@1", "--as", "mkzp@2"]);
    assert!(err.contains("--map"), "{err}");
    // A capture in which nobody answered: five polls of unit 9, 100 ms apart, no answer.
    let dir = std::env::temp_dir().join(format!("mbtap-emulate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let silent = dir.join("silent.pcapng");
    let mut w = mbtap_analysis::capture::PcapNgWriter::new(Vec::new()).unwrap();
    let i = w.add_serial_interface("/dev/ttyUSB0", "mbtap rtu 9600 8E1").unwrap();
    for k in 0..5u64 {
        w.write_packet(i, mbtap_analysis::chunk::Timestamp(k * 100_000_000), &POLL_9).unwrap();
    }
    std::fs::write(&silent, w.into_inner()).unwrap();
    let err = run(&["--from", silent.to_str().unwrap()]);
    assert!(err.contains("no unit answered") && err.contains("units 9 were asked"), "{err}");
    // A pcap whose one record claims 4 GB: said as the reader says it (where, and what), as
    // `replay` and `learn` say it — not as a line where nobody answered.
    let liar = dir.join("liar.pcap");
    let mut bytes = Vec::new();
    // Global header: magic, version 2.4, zone 0, accuracy 0, snaplen 65535, linktype 147 (USER0).
    for word in [0xA1B2_C3D4u32, 0x0004_0002, 0, 0, 65_535, 147] {
        bytes.extend(word.to_le_bytes());
    }
    // One record header: seconds, microseconds, included and original length 0xFFFF_FFF0.
    for word in [0u32, 0, 0xFFFF_FFF0, 0xFFFF_FFF0] {
        bytes.extend(word.to_le_bytes());
    }
    bytes.extend(&POLL_9);
    std::fs::write(&liar, bytes).unwrap();
    let err = run(&["--from", liar.to_str().unwrap()]);
    assert!(err.contains("offset 24") && !err.contains("no unit answered"), "{err}");
}

/// Reads an f32 (high word first) at input register `address` of `unit`; `None` on an exception.
fn read_f32(s: &mut std::net::TcpStream, unit: u8, address: u16) -> Result<f32, Vec<u8>> {
    let [hi, lo] = address.to_be_bytes();
    let answer = common::call(s, 1, unit, &[/* fc */ 0x04, hi, lo, /* quantity */ 0x00, 0x02]);
    match answer[..] {
        [0x04, 4, a, b, c, d] => Ok(f32::from_bits(u32::from_be_bytes([a, b, c, d]))),
        _ => Err(answer),
    }
}

/// Waits up to 10 s for `f` to hold.
fn eventually(what: &str, mut f: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !f() {
        assert!(start.elapsed() < std::time::Duration::from_secs(10), "{what} never happened");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

#[test]
fn a_mirror_serves_another_devices_values_under_another_map_and_0b_while_it_is_away() {
    let dir = std::env::temp_dir().join(format!("mbtap-mirror-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // The served profile: an imported energy meter's sheet (f32 volts at input 0, watts at 12).
    let meter = common::imported_meter(&dir);
    // The source: the built-in MK4 on a pty, mirrored through it as an RTU master would.
    let line = dir.join("mk4");
    let source = common::simulate(&line, &["--device", "mk4@1", "--duration", "60"]);
    let map = "Phase 1 line to neutral volts=Phase A (L1) voltage,Phase 1 active power=input 430*10";
    let as_meter = format!("{}@2", meter.display());
    let (_mirror, addr, _, said) = common::simulate_listening(&[
        "--mirror",
        line.to_str().unwrap(),
        "--mirror-device",
        "mk4@1",
        "--as",
        &as_meter,
        "--map",
        map,
        "--fresh",
        "200ms",
        "--listen",
        "127.0.0.1:0",
        "--duration",
        "60",
    ]);
    let mut s = connect(&addr);
    eventually("a first value", || read_f32(&mut s, 2, 0).is_ok());
    // Volts and watts come from one read of the source: watts are volts × 10 exactly (the MK4's
    // 0.1 V raw value scaled, rounded to whole watts).
    let volts = read_f32(&mut s, 2, 0).unwrap();
    let watts = read_f32(&mut s, 2, 12).unwrap();
    assert!((200.0..260.0).contains(&volts), "{volts} V is not the MK4's mains voltage");
    assert!((watts - volts * 10.0).abs() < 1.0, "{watts} W from {volts} V × 10");
    // The source goes away: every request gets 0B, said.
    drop(source);
    eventually("exception 0B", || read_f32(&mut s, 2, 0) == Err(vec![0x84, 0x0B]));
    assert!(said.lock().unwrap().contains("clients get exception 0B until it answers"), "{}", said.lock().unwrap());
    // It comes back on the same line: values again, said.
    let _back = common::simulate(&line, &["--device", "mk4@1", "--duration", "60"]);
    eventually("values again", || read_f32(&mut s, 2, 0).is_ok());
    eventually("the return said", || said.lock().unwrap().contains("answering again"));
}

/// `simulate --serial PORT`: the devices as slaves on a real serial port (here one end of a pty
/// pair; the other end is the master's), through the bridge's serial front.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn a_recorded_device_answers_on_a_serial_port() {
    let dir = std::env::temp_dir().join(format!("mbtap-emulate-serial-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (_socat, device_side, master_side) = common::socat_pair(&dir);
    let meter = capture("rtu-real-power-meter.pcapng");
    let _sim = Kill(
        Command::new(BIN)
            .args(["simulate", "--from", meter.to_str().unwrap(), "--serial", device_side.to_str().unwrap()])
            .args(["--duration", "60"])
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let expected = pairs("rtu-real-power-meter.txt");
    // Holding registers 0–45 as the recording's answer holds them.
    let (_, (_, answer)) = expected.iter().find(|((_, r), _)| r[0] == 0x03).unwrap().clone();
    let holding: Vec<i64> = answer[2..].chunks(2).map(|w| i64::from(u16::from_be_bytes([w[0], w[1]]))).collect();
    let start = std::time::Instant::now();
    let out = loop {
        let out = Command::new(BIN)
            .args(["read", master_side.to_str().unwrap(), "--unit", "1", "--format", "jsonl", "holding", "0..45"])
            .output()
            .unwrap();
        if out.status.success() || start.elapsed() > std::time::Duration::from_secs(10) {
            break out;
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    let raws: Vec<i64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()?["raw"].as_i64())
        .collect();
    assert_eq!(raws, holding, "{}", String::from_utf8_lossy(&out.stderr));
}

/// `--replay-values`: a recording's values in their time course — at the start, as first heard;
/// without it, as last heard. The three-phase meter's shape (64 polls 4 s apart, voltages
/// moving) tells them apart.
#[test]
fn replayed_values_start_as_first_heard_last_heard_without() {
    let shape = capture("rtu-shape-three-phase-floats.pcapng");
    let all = pairs("rtu-shape-three-phase-floats.txt");
    let first = all.first().unwrap().clone();
    let last = all.iter().rev().find(|(req, _)| *req == first.0).unwrap().clone();
    assert_ne!(first.1, last.1, "the voltages moved over the recording");
    let (_a, replayed, said) = emulate(&["--from", shape.to_str().unwrap(), "--replay-values"]);
    assert!(said.contains("recorded values replayed in their time course"), "{said}");
    let (_b, held, _) = emulate(&["--from", shape.to_str().unwrap()]);
    let ((unit, request), _) = &first;
    assert_eq!(common::call(&mut connect(&replayed), 1, *unit, request), first.1.1);
    assert_eq!(common::call(&mut connect(&held), 1, *unit, request), last.1.1);
}

/// `simulate --serial` on a real bus answers at its own devices' addresses only: a request to
/// another unit (a battery, a second meter beside it) gets silence, not exception 0B — a real
/// slave does not answer for its neighbours.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn an_emulated_device_on_a_serial_bus_is_silent_for_other_units() {
    use std::io::{Read, Write};
    let d = std::env::temp_dir().join(format!("mbtap-emulate-silent-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let (_socat, device_side, master_side) = common::socat_pair(&d);
    let mut sim = Command::new(BIN)
        .args(["simulate", "--device", "mk4@1", "--serial", device_side.to_str().unwrap(), "--duration", "30"])
        .args(["--turnaround-ms", "0"])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(700));
    let mut port = std::fs::OpenOptions::new().read(true).write(true).open(&master_side).unwrap();
    // One reader for the whole test: every byte the bus brings, in order.
    let (tx, heard) = std::sync::mpsc::channel::<Vec<u8>>();
    let mut reader = port.try_clone().unwrap();
    std::thread::spawn(move || {
        let mut buf = [0u8; 64];
        while let Ok(n) = reader.read(&mut buf) {
            if n == 0 || tx.send(buf[..n].to_vec()).is_err() {
                return;
            }
        }
    });
    let mut ask = |unit: u8| -> Vec<u8> {
        // Read input register 430, one (MAP v1.1b3 §6.4): FC 04, address 01AE, quantity 0001.
        let mut frame = Vec::new();
        mbtap_proto::encode_rtu(unit, &[0x04, 0x01, 0xAE, 0x00, 0x01], &mut frame);
        port.write_all(&frame).unwrap();
        let mut got = Vec::new();
        let until = std::time::Instant::now() + std::time::Duration::from_millis(700);
        while let Some(left) = until.checked_duration_since(std::time::Instant::now()) {
            match heard.recv_timeout(left) {
                Ok(bytes) => got.extend_from_slice(&bytes),
                Err(_) => break,
            }
        }
        got
    };
    let other = ask(3);
    let own = ask(1);
    let _ = sim.kill();
    let _ = sim.wait();
    std::fs::remove_dir_all(&d).ok();
    assert!(other.is_empty(), "unit 3 is not emulated here: silence, not {other:02x?}");
    // Unit 1, FC 04, 2 bytes: the MK4's L1 voltage.
    assert_eq!(own.get(..3), Some(&[0x01, 0x04, 0x02][..]), "unit 1 is emulated: {own:02x?}");
}

/// The start lines name the options the user gave: `simulate --serial` with a port that is not
/// there says `simulate --serial PORT: cannot open it`, never `--listen-serial` (the bridge's
/// option, which the user did not give).
#[test]
fn a_serial_front_that_cannot_open_names_the_option_given() {
    let out = Command::new(BIN)
        .args(["simulate", "--device", "sdm630@1", "--serial", "/nonexistent/tty-for-mbtap", "--duration", "1"])
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("simulate --serial /nonexistent/tty-for-mbtap: cannot open it"), "{err}");
    assert!(!err.contains("--listen-serial"), "{err}");
}

/// A read across a meter's gaps with its profile: `read … --device sdm630 input 0..343` gives
/// every value the map names (0 to 342) and says what it left out: the gaps are not read, so
/// no 02 for them fails the read.
#[test]
fn a_read_across_a_profiles_gaps_gives_the_mapped_values_and_says_what_it_left_out() {
    let (_sim, addr, _) = emulate(&["--device", "sdm630@1"]);
    let out = Command::new(BIN)
        .args(["read", &addr, "--unit", "1", "--device", "sdm630", "--format", "jsonl", "input", "0..343"])
        .output()
        .unwrap();
    let (text, err) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{text}{err}");
    let values: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert!(values.iter().all(|v| v.get("error").is_none()), "{text}");
    let names: Vec<&str> = values.iter().filter_map(|v| v["name"].as_str()).collect();
    assert!(names.contains(&"Phase 1 line to neutral volts") && names.contains(&"Total kWh"), "{names:?}");
    assert!(err.contains("input 44..45 not in the profile's map"), "{err}");
}

/// The README's fake-meter story, as written with built-in profiles: an EM24 on its own 9600
/// 8N1 line (played by `simulate` on a pty) served as an SDM630 on an inverter's 19200 8E1
/// RS-485 port (one end of a pty pair; the inverter, here `mbtap read`, on the other), its map
/// naming each SDM630 value by the EM24's. The inverter reads the EM24's volts and energy in the
/// SDM630's floats; the mirror says which line it reads the source on, apart from the served one.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn a_fake_meter_on_an_inverters_port_serves_another_meters_values_on_its_own_line() {
    let dir = std::env::temp_dir().join(format!("mbtap-fake-meter-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let em24 = dir.join("em24");
    let _meter =
        common::simulate(&em24, &["--device", "em24@1", "--baud", "9600", "--parity", "none", "--duration", "60"]);
    let (_socat, meter_side, inverter_side) = common::socat_pair(&dir);
    let map = "Phase 1 line to neutral volts=V L1-N,Phase 2 line to neutral volts=V L2-N,\
               Phase 3 line to neutral volts=V L3-N,Total system power=W sys,Total kWh=kWh (+) TOT";
    let mut fake = Command::new(BIN)
        .args(["simulate", "--mirror", em24.to_str().unwrap(), "--mirror-device", "em24@1"])
        .args(["--mirror-line", "9600 8N1", "--as", "sdm630@2", "--map", map, "--fresh", "300ms"])
        .args(["--serial", meter_side.to_str().unwrap(), "--baud", "19200", "--parity", "even"])
        .args(["--duration", "60"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let said = {
        use std::io::BufRead;
        let mut lines = std::io::BufReader::new(fake.stderr.take().unwrap()).lines();
        let said = lines.by_ref().map_while(Result::ok).find(|l| l.contains("mirroring")).unwrap_or_default();
        std::thread::spawn(move || lines.for_each(drop));
        said
    };
    let _fake = Kill(fake);
    assert!(said.contains("on a 9600 8N1 rtu line"), "the source's own line is said: {said}");
    let read = || {
        Command::new(BIN)
            .args(["read", inverter_side.to_str().unwrap(), "--unit", "2", "--device", "sdm630"])
            .args(["--baud", "19200", "--parity", "even", "--format", "jsonl"])
            .args(["Phase 1 line to neutral volts", "Total kWh"])
            .output()
            .unwrap()
    };
    let start = std::time::Instant::now();
    let values = loop {
        let out = read();
        let values: Vec<f64> = String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()?["value"].as_f64())
            .collect();
        if values.len() == 2 || start.elapsed() > std::time::Duration::from_secs(15) {
            break values;
        }
        std::thread::sleep(std::time::Duration::from_millis(300));
    };
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(values.len(), 2, "the inverter reads both values: {values:?}");
    assert!((225.0..235.0).contains(&values[0]), "the EM24's L1 volts as the SDM630's float: {}", values[0]);
    assert!(values[1] > 1234.0, "the EM24's import energy as the SDM630's Total kWh: {}", values[1]);
}
