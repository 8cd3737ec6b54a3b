//! `mbtap simulate --poll` puts a whole line (master and slaves) on a real pseudo-terminal, and
//! `mbtap sniff` hears it: the three devices answering, the injected faults as what they are,
//! and a listener at the wrong settings getting garbage instead of frames. Real ptys and real
//! pacing: `#[ignore]`d in a plain `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::collections::BTreeSet;
use std::process::{Command, Stdio};

use crate::common;
use common::{BIN, Kill, wait_for};

/// Starts `simulate --poll` with `extra` arguments; the link to sniff.
fn line(name: &str, extra: &[&str]) -> (Kill, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("mbtap-poll-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("bus");
    let mut args = vec!["simulate", "--poll", "--link", link.to_str().unwrap(), "--duration", "30"];
    args.extend_from_slice(extra);
    let sim = Kill(Command::new(BIN).args(&args).stderr(Stdio::null()).spawn().unwrap());
    wait_for(&link);
    (sim, link)
}

/// Sniffs `link` for `seconds` with `extra` arguments; the JSON lines.
fn sniff(link: &std::path::Path, seconds: &str, extra: &[&str]) -> Vec<serde_json::Value> {
    let mut args = vec!["sniff", link.to_str().unwrap(), "--format", "jsonl", "--duration", seconds];
    args.extend_from_slice(extra);
    let out = Command::new(BIN).args(&args).stderr(Stdio::null()).output().unwrap();
    assert!(out.status.success());
    String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

fn transactions(events: &[serde_json::Value]) -> impl Iterator<Item = &serde_json::Value> {
    events.iter().filter(|e| e["event"] == "transaction")
}

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn a_sniffer_hears_all_three_devices_answer_on_the_polled_line() {
    let (_sim, link) = line("clean", &[]);
    let events = sniff(&link, "3", &[]);
    let units: BTreeSet<u64> =
        transactions(&events).filter(|t| t["outcome"] == "ok").map(|t| t["unit"].as_u64().unwrap()).collect();
    assert_eq!(units, BTreeSet::from([1, 5, 17]), "{events:#?}");
    // A clean line: every frame's check holds and no noise. (The first frame may be cut by
    // the moment the sniffer opened the port; it is the only one allowed to be partial.)
    let heard = events.iter().filter(|e| e["event"] == "noise" || e["event"] == "frame");
    let bad: Vec<_> = heard.skip(1).filter(|e| e["event"] == "noise" || e["check_ok"] == false).collect();
    assert!(bad.is_empty(), "{bad:#?}");
}

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn injected_faults_reach_the_sniffer_as_what_they_are() {
    let (_sim, link) = line("faults", &["--fault", "silent-slave", "--fault", "corrupt"]);
    let events = sniff(&link, "4", &[]);
    let statuses: BTreeSet<&str> = transactions(&events).map(|t| t["outcome"].as_str().unwrap()).collect();
    assert!(statuses.contains("ok"), "{statuses:?}");
    // Silent slave: the master moves on after its 1 s timeout; the sniffer reports no response.
    assert!(statuses.contains("no_response"), "{statuses:?}");
    // Corrupt: a flipped bit, a response whose CRC fails.
    assert!(events.iter().any(|e| e["event"] == "frame" && e["check_ok"] == false), "no bad CRC heard");
}

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn a_listener_at_the_wrong_baud_rate_hears_garbage_not_frames() {
    // The line runs at 19200 8E1; the listener's UART is at 9600 8N1 (modelled in the
    // simulator, since a pty carries bytes, not bits).
    let (_sim, link) = line("wrong-baud", &["--heard-at", "9600 8N1"]);
    let events = sniff(&link, "3", &["--baud", "9600", "--parity", "none"]);
    let good = events.iter().filter(|e| e["event"] == "frame" && e["check_ok"] == true).count();
    let noise = events.iter().filter(|e| e["event"] == "noise").count();
    assert_eq!(good, 0, "a wrong-baud listener cannot decode frames");
    assert!(noise > 3, "it hears garbage: {noise} noise events");
}

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn a_live_sniffer_reports_bus_health_while_it_runs_and_names_a_second_master() {
    let (_sim, link) = line("second-master", &["--fault", "second-master"]);
    let events = sniff(&link, "5", &["--report-every", "1"]);
    let reports: Vec<&serde_json::Value> = events.iter().filter(|e| e["event"] == "report").collect();
    let interim = reports.iter().filter(|r| r["final"] == false).count();
    assert!(interim >= 3, "a report about every second of 5: {interim}");
    let last = reports.last().unwrap();
    assert_eq!(last["final"], true, "the last report is the final one");
    let kinds: BTreeSet<&str> =
        last["findings"].as_array().unwrap().iter().map(|f| f["kind"].as_str().unwrap()).collect();
    assert!(kinds.contains("second_master"), "{kinds:?}");
    assert!(!kinds.contains("no_response"), "the overlap is not a silent unit: {kinds:?}");
}

#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn a_live_scan_on_a_real_pty_finds_the_baud_rate() {
    // The simulator hears the line at whatever baud rate the scanner set on the pty. A pty
    // keeps the rate in its termios but not parity enable or character size, so only the rate
    // can be found here; parity, stop bits and mode are proven on the UART model
    // (tests/decode/health.rs, scan_finds_the_settings_of_simulated_lines).
    let (_sim, link) = line("scan", &["--baud", "9600", "--parity", "even", "--follow-baud"]);
    let out = Command::new(BIN)
        .args(["scan", link.to_str().unwrap(), "--baud", "4800", "--baud", "9600", "--dwell-ms", "1500"])
        .stderr(Stdio::null())
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(out.status.success(), "{text}");
    let best = text.lines().next().unwrap();
    assert!(best.starts_with("best: 9600 8") && best.contains(" rtu "), "{text}");
    assert!(best.ends_with("units heard: 1, 5, 17"), "{text}");
}
