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
