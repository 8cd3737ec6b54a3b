//! `bridge --listen-serial`: a master already on a device's line (the "inverter",
//! pymodbus on a pty) and a TCP client (mbpoll) share one device through the bridge. The device
//! is the power meter of a public recording emulated on the line (`simulate --from`, its values
//! fixed), so every answer each master gets can be checked against the recording: both get
//! every answer right, neither one meant for the other. Real ptys and peers: `#[ignore]`d in a
//! plain `cargo test`, run by `.ci/run` with `--ignored`.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use super::serial::{bridge, dir, simulator};
use crate::common::{Kill, socat_pair};

/// The registers of the recording's answer line that starts `starts` (unit, fc, count, data, CRC).
fn recorded(starts: &str) -> Vec<u16> {
    let txt = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/rtu-real-power-meter.txt");
    let line = std::fs::read_to_string(txt)
        .unwrap()
        .lines()
        .find(|l| l.to_ascii_lowercase().starts_with(starts))
        .unwrap()
        .to_owned();
    let bytes: Vec<u8> = line.split_whitespace().map(|h| u8::from_str_radix(h, 16).unwrap()).collect();
    bytes[3..bytes.len() - 2].chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect()
}

#[test]
#[ignore = "needs socat, pymodbus and mbpoll; .ci/run installs them and runs this with --ignored"]
fn an_existing_master_and_a_tcp_client_share_one_device() {
    let d = dir("listen-serial");
    let (_socat, inverter_side, inverter) = socat_pair(&d);
    let bus = d.join("bus");
    let meter = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/rtu-real-power-meter.pcapng");
    let _sim = simulator(&bus, &["--from", meter.to_str().unwrap(), "--paced"]);
    let (_bridge, tcp, _) = bridge(&bus, &["--listen-serial", inverter_side.to_str().unwrap()]);
    let input = recorded("01 04 54");
    let holding = recorded("01 03 5c");
    let seconds = 10;
    let expected: Vec<String> = input.iter().map(u16::to_string).collect();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/pymodbus_poll_loop.py");
    let mut inverter_run = Kill(
        Command::new("python3")
            .arg(script)
            .arg(&inverter)
            .args(["1", "input", "0", "42", &seconds.to_string(), &expected.join(",")])
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    );
    // Meanwhile mbpoll (libmodbus) over Modbus TCP: holding registers 0–45, one poll per run.
    let (host, port) = tcp.rsplit_once(':').unwrap();
    let start = Instant::now();
    let (mut right, mut wrong) = (0, Vec::new());
    while start.elapsed() < Duration::from_secs(seconds) {
        let out = Command::new("mbpoll")
            .args(["-m", "tcp", "-p", port, "-a", "1", "-t", "4", "-0", "-r", "0", "-c", "46", "-1", host])
            .output()
            .expect("mbpoll must be installed for this test");
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        let got: Vec<u16> = text
            .lines()
            .filter_map(|l| l.trim().strip_prefix('[')?.split_once("]:")?.1.split_whitespace().next()?.parse().ok())
            .collect();
        if got == holding { right += 1 } else { wrong.push(text) }
    }
    let status = inverter_run.0.wait().unwrap();
    let mut report = String::new();
    std::io::Read::read_to_string(&mut inverter_run.0.stdout.take().unwrap(), &mut report).unwrap();
    assert!(status.success(), "{report}");
    let inverter: serde_json::Value = serde_json::from_str(&report).unwrap();
    assert_eq!((inverter["wrong"].as_u64(), inverter["errors"].as_u64()), (Some(0), Some(0)), "{report}");
    assert!(inverter["right"].as_u64().unwrap() > 20, "{report}");
    assert!(wrong.is_empty(), "mbpoll got {} other answers, the first:\n{}", wrong.len(), wrong[0]);
    assert!(right > 20, "mbpoll got {right} answers in {seconds} s");
}
