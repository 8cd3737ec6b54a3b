//! Issue 28: `mbtap probe` against `mbtap simulate` on a pseudo-terminal — the MK4's map found
//! with reads only (the same map as reading every address, in a third of the requests), a
//! skeleton profile that loads, and the first timeout stopping the probe with its reason.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

mod common;

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mbtap");

fn probe(link: &str, args: &[&str]) -> (serde_json::Value, bool) {
    let out = Command::new(BIN)
        .args(["probe", link, "--parity", "even", "--rate", "500", "--format", "json"])
        .args(args)
        .output()
        .unwrap();
    let doc =
        serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    (doc, out.status.success())
}

#[test]
#[ignore = "needs a pseudo-terminal with `mbtap simulate`; .ci/run runs this with --ignored"]
fn probe_finds_the_simulated_mk4s_map_reading_only() {
    let dir = std::env::temp_dir().join(format!("mbtap-probe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("bus");
    let _sim = common::simulate(&link, &[]);
    let link = link.to_str().unwrap();
    let skeleton = dir.join("skeleton.toml");
    let (fast, ok) = probe(link, &["--unit", "1", "--range", "0-999", "-o", skeleton.to_str().unwrap()]);
    assert!(ok, "{fast}");
    // The MK4 document: holding registers 100–399, input registers 400–839 and 900–903.
    assert_eq!(fast["tables"]["holding_registers"]["present"], serde_json::json!([[100, 399]]), "{fast}");
    assert_eq!(fast["tables"]["input_registers"]["present"], serde_json::json!([[400, 839], [900, 903]]), "{fast}");
    let (all, ok) = probe(link, &["--unit", "1", "--range", "0-999", "--thorough"]);
    assert!(ok, "{all}");
    assert_eq!(all["tables"], fast["tables"]);
    assert_eq!(all["assumed_absent"], 0);
    let (n_fast, n_all) = (fast["requests"].as_u64().unwrap(), all["requests"].as_u64().unwrap());
    assert!(n_fast * 2 < n_all, "{n_fast} requests against {n_all} reading every address");
    let check = Command::new(BIN).args(["profiles", "check", skeleton.to_str().unwrap()]).output().unwrap();
    assert!(check.status.success(), "{}", String::from_utf8_lossy(&check.stderr));
    // A unit nobody answers for: stopped at the first timeout, and said why.
    let (silent, ok) = probe(link, &["--unit", "33", "--range", "0-99", "--timeout-ms", "200"]);
    assert!(!ok);
    assert_eq!(silent["requests"], 1, "{silent}");
    assert!(silent["stopped"].as_str().unwrap().contains("no answer"), "{silent}");
    std::fs::remove_dir_all(&dir).unwrap();
}
