//! `mbtap demo`, the README's first command, run as a user would: the real binary, its JSON
//! lines read back. It must show traffic of all three simulated devices, annotated, clean.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::collections::BTreeSet;
use std::process::Command;

#[test]
fn demo_shows_all_three_devices_annotated() {
    // One cycle of the poll list (9 transactions, ~100 ms apart) fits in 1.5 s of line time.
    let out = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["demo", "--format", "jsonl", "--duration", "1.5"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let lines: Vec<serde_json::Value> =
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let transactions: Vec<&serde_json::Value> = lines.iter().filter(|l| l["event"] == "transaction").collect();
    let units: BTreeSet<u64> = transactions.iter().map(|t| t["unit"].as_u64().unwrap()).collect();
    assert_eq!(units, BTreeSet::from([1, 5, 17]), "every simulated device is polled and heard");
    for t in &transactions {
        assert_eq!(t["outcome"], "ok", "{t}");
        assert!(!t["annotations"].as_array().unwrap().is_empty(), "annotated by its profile: {t}");
    }
    let volts =
        transactions.iter().find(|t| t["annotations"][0]["address"] == 430).expect("the MK4 voltages are polled");
    let l1 = volts["annotations"][0]["value"].as_f64().unwrap();
    assert!((200.0..260.0).contains(&l1), "phase A = {l1} V");
    let summary = lines.iter().find(|l| l["event"] == "summary").expect("a summary at the end");
    assert_eq!(summary["bad_frames"], 0, "{summary}");
    assert_eq!(summary["gap_violations"], 0, "{summary}");
    assert_eq!(summary["transactions"], summary["ok"], "{summary}");
}

/// Runs `demo` as fast as it goes for 10 s of line time with one fault, returning the summary.
fn summary_with_fault(fault: &str) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["demo", "--format", "jsonl", "--speed", "0", "--duration", "10", "--fault", fault])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    serde_json::from_str(text.lines().last().unwrap()).unwrap()
}

/// Each injected fault shows up in the sniffer as what it is, and only as that.
#[test]
fn injected_faults_are_seen_as_what_they_are() {
    let s = summary_with_fault("corrupt");
    assert!(s["bad_frames"].as_u64().unwrap() > 0 && s["bad_responses"] == s["bad_frames"], "{s}");
    assert_eq!(s["no_response"], 0, "{s}");

    let s = summary_with_fault("noise");
    assert!(s["noise_events"].as_u64().unwrap() > 0, "{s}");
    assert_eq!(s["transactions"], s["ok"], "noise between transactions spoils none: {s}");

    let s = summary_with_fault("slow-slave");
    assert!(s["gap_violations"].as_u64().unwrap() > 0, "{s}");
    assert_eq!(s["bad_frames"], 0, "a slow answer is still a good frame: {s}");

    let s = summary_with_fault("silent-slave");
    assert!(s["no_response"].as_u64().unwrap() > 0, "{s}");
    assert_eq!(s["bad_frames"], 0, "{s}");

    let s = summary_with_fault("collision");
    assert!(s["bad_responses"].as_u64().unwrap() > 0, "{s}");

    let s = summary_with_fault("fast-master");
    assert!(s["short_gaps"].as_u64().unwrap() > 0, "{s}");
    assert_eq!(s["transactions"], s["ok"], "{s}");
}

/// Without faults the line is clean: the faults above are the injector's doing, not noise of
/// the simulation itself.
#[test]
fn no_fault_no_finding() {
    let out = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["demo", "--format", "jsonl", "--speed", "0", "--duration", "10"])
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let s: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    for key in ["bad_frames", "noise_events", "gap_violations", "short_gaps", "no_response", "bad_responses"] {
        assert_eq!(s[key], 0, "{key}: {s}");
    }
    assert!(s["transactions"].as_u64().unwrap() > 50, "{s}");
}

/// One duration syntax everywhere: `demo --duration 2s` is taken as `--interval 1s` is elsewhere (a
/// bare number is still seconds).
#[test]
fn durations_take_one_syntax_everywhere() {
    for d in ["1500ms", "1.5s", "1.5"] {
        let out = Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .args(["demo", "--format", "summary", "--duration", d])
            .output()
            .unwrap();
        assert!(out.status.success(), "--duration {d}: {}", String::from_utf8_lossy(&out.stderr));
    }
    let out = Command::new(env!("CARGO_BIN_EXE_mbtap")).args(["demo", "--duration", "2x"]).output().unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("250ms, 1s, 2min or 1h"));
    // The bridge's --idle-timeout the same way.
    let out = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["bridge", "--serial", "/nonexistent/tty", "--listen", "127.0.0.1:0", "--idle-timeout", "5min"])
        .args(["--duration", "200ms"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// `demo --record FILE --report`: what the listener heard goes to a pcapng that replays to the
/// same transactions (its line settings stored with it, so no default is guessed), and the health
/// report ends the output — a demo that leaves something to try the other commands on.
#[test]
fn a_demo_records_what_it_heard_and_reports_on_it() {
    let dir = std::env::temp_dir().join(format!("mbtap-demo-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let recording = dir.join("demo.pcapng");
    let out = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["demo", "--format", "jsonl", "--speed", "0", "--duration", "10", "--fault", "corrupt"])
        .args(["--report", "--record", recording.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let lines: Vec<serde_json::Value> =
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let summary = lines.iter().find(|l| l["event"] == "summary").expect("a summary");
    assert!(lines.iter().any(|l| l["event"] == "report"), "the health report ends a demo given --report");
    let replayed = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["replay", recording.to_str().unwrap(), "--format", "jsonl"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&replayed.stderr);
    assert!(replayed.status.success() && !said.contains("stores no line settings"), "{said}");
    let again: Vec<serde_json::Value> =
        String::from_utf8(replayed.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let replayed_summary = again.iter().find(|l| l["event"] == "summary").expect("a summary");
    std::fs::remove_dir_all(&dir).ok();
    for field in ["transactions", "ok", "bad_frames"] {
        assert_eq!(replayed_summary[field], summary[field], "{field}: the recording holds what the demo heard");
    }
    assert!(summary["bad_frames"].as_u64().unwrap() > 0, "the injected corruption is in it: {summary}");
}
