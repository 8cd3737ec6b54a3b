//! Issue 29: `sniff rtu-over-tcp://HOST:PORT` hears a remote line through a serial server —
//! Debian's ser2net in raw TCP mode in front of `mbtap simulate --poll` (the whole line, master
//! and slaves, on a pseudo-terminal). TCP keeps no timing: frames are found by structure and CRC.
//! Needs ser2net (CI installs it): run with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use crate::common;

use std::process::{Command, Stdio};

use common::{BIN, Kill, wait_port};

#[test]
#[ignore = "needs ser2net; .ci/run installs it and runs this with --ignored"]
fn sniff_hears_a_line_through_ser2net() {
    let dir = std::env::temp_dir().join(format!("mbtap-ser2net-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let line = dir.join("line");
    let _sim = common::simulate(&line, &["--poll"]);
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let config = dir.join("ser2net.yaml");
    std::fs::write(
        &config,
        format!(
            "connection: &line\n  accepter: tcp,127.0.0.1,{port}\n  connector: serialdev,{},19200e81,local\n",
            line.display()
        ),
    )
    .unwrap();
    let _ser2net = Kill(
        Command::new("ser2net")
            .args(["-n", "-d", "-c", config.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("ser2net must be installed"),
    );
    wait_port(port);
    let target = format!("rtu-over-tcp://127.0.0.1:{port}");
    let out = Command::new(BIN)
        .args(["sniff", &target, "--parity", "even", "--duration", "4", "--format", "jsonl"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let events: Vec<serde_json::Value> =
        String::from_utf8_lossy(&out.stdout).lines().filter_map(|l| serde_json::from_str(l).ok()).collect();
    let transactions: Vec<&serde_json::Value> = events.iter().filter(|e| e["event"] == "transaction").collect();
    // The connection opens and closes wherever the line is: the first and last frames may be
    // cut. Every frame between must check.
    let frames: Vec<&serde_json::Value> = events.iter().filter(|e| e["event"] == "frame").collect();
    let inner = frames.get(1..frames.len().saturating_sub(1)).unwrap_or_default();
    let failed = inner.iter().filter(|e| e["check_ok"] == false).count();
    assert!(transactions.len() >= 10, "{} transactions", transactions.len());
    assert_eq!(failed, 0, "{failed} of {} frames failed their check", inner.len());
    let units: std::collections::BTreeSet<u64> = transactions.iter().filter_map(|t| t["unit"].as_u64()).collect();
    for u in [1, 5, 17] {
        assert!(units.contains(&u), "unit {u} not heard: {units:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
