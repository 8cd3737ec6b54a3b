//! `mbtap probe` against `mbtap simulate` on a pseudo-terminal, through `mbtap tap`
//! recording the line: each simulated device's map found exactly as its built-in profile defines
//! it, with reads only (every request on the recorded line is a read or an identification), the
//! same map as reading every address in fewer than half the requests, a skeleton profile that
//! loads, and the first timeout stopping the probe with its reason.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use crate::common;

use std::process::{Command, Stdio};

use common::{BIN, Kill, wait_for};
use mbtap_device::profile::Table;

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

/// The runs of addresses a built-in profile defines in `table` — described or reserved by the
/// device's document (a reserved address exists and answers) — as probe reports them.
fn defined(name: &str, table: Table) -> serde_json::Value {
    let p = mbtap_device::profile::builtin::get(name).unwrap().unwrap();
    let mut all: std::collections::BTreeSet<u16> = p.addresses(table).collect();
    for &(t, a, b) in &p.reserved {
        if t == table {
            all.extend(a..=b);
        }
    }
    let mut runs: Vec<[u16; 2]> = Vec::new();
    for a in all {
        match runs.last_mut() {
            Some(r) if u32::from(r[1]) + 1 == u32::from(a) => r[1] = a,
            _ => runs.push([a, a]),
        }
    }
    serde_json::json!(runs)
}

#[test]
#[ignore = "needs pseudo-terminals with `mbtap simulate` and `mbtap tap`; .ci/run runs this with --ignored"]
fn probe_finds_each_simulated_devices_map_reading_only() {
    let dir = std::env::temp_dir().join(format!("mbtap-probe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bus = dir.join("bus");
    let _sim = common::simulate(&bus, &[]);
    let (app, rec) = (dir.join("app"), dir.join("line.pcapng"));
    let tap = Kill(
        Command::new(BIN)
            .args(["tap", bus.to_str().unwrap(), "--link", app.to_str().unwrap(), "--format", "summary"])
            .args(["--parity", "even", "--record", rec.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    wait_for(&app);
    let link = app.to_str().unwrap();
    let tables = [Table::Coils, Table::DiscreteInputs, Table::HoldingRegisters, Table::InputRegisters];
    let mut requests = 0;
    for (unit, name) in [(1, "mk4"), (5, "display"), (17, "mkzp")] {
        let (found, ok) = probe(
            link,
            &["--unit", &unit.to_string(), "--range", "0-1999", "--tables", "holding,input,coils,discrete"],
        );
        assert!(ok, "{name}: {found}");
        for t in tables {
            let got = &found["tables"][t.name()]["present"];
            let want = defined(name, t);
            // A table the device does not support answers exception 01: nothing present.
            assert_eq!(
                got.as_array().map_or(0, Vec::len),
                want.as_array().unwrap().len(),
                "{name} {}: {got} vs {want}",
                t.name()
            );
            if !want.as_array().unwrap().is_empty() {
                assert_eq!(got, &want, "{name} {}", t.name());
            }
        }
        eprintln!("{name}: {} read requests", found["requests"]);
        requests += found["requests"].as_u64().unwrap();
    }
    // Every address read instead: the same map, in more than twice the requests (MK4).
    let (fast, _) = probe(link, &["--unit", "1", "--range", "0-999"]);
    let (all, ok) = probe(link, &["--unit", "1", "--range", "0-999", "--thorough"]);
    assert!(ok, "{all}");
    assert_eq!(all["tables"], fast["tables"]);
    assert_eq!(all["assumed_absent"], 0);
    let (n_fast, n_all) = (fast["requests"].as_u64().unwrap(), all["requests"].as_u64().unwrap());
    assert!(n_fast * 2 < n_all, "{n_fast} requests against {n_all} reading every address");
    let skeleton = dir.join("skeleton.toml");
    let (_, ok) = probe(link, &["--unit", "17", "--range", "0-299", "-o", skeleton.to_str().unwrap()]);
    assert!(ok);
    let check = Command::new(BIN).args(["profiles", "check", skeleton.to_str().unwrap()]).output().unwrap();
    assert!(check.status.success(), "{}", String::from_utf8_lossy(&check.stderr));
    // A unit nobody answers for: stopped at the first timeout, and said why.
    let (silent, ok) = probe(link, &["--unit", "33", "--range", "0-99", "--timeout-ms", "200"]);
    assert!(!ok);
    assert_eq!(silent["requests"], 1, "{silent}");
    assert!(silent["stopped"].as_str().unwrap().contains("no answer"), "{silent}");
    // What went over the line: reads and identification only, never a write.
    drop(tap);
    let replay = Command::new(BIN).args(["replay", rec.to_str().unwrap(), "--format", "jsonl"]).output().unwrap();
    let text = String::from_utf8_lossy(&replay.stdout);
    let functions: std::collections::BTreeSet<u64> = text
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|j| j["event"] == "transaction")
        .filter_map(|j| j["function"].as_u64())
        .collect();
    assert!(requests > 50 && !functions.is_empty(), "{functions:?}");
    assert!(functions.iter().all(|f| matches!(f, 1..=4 | 0x11 | 0x2B)), "functions on the line: {functions:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `mbtap diff` of two probe dumps — the MK4 probed, its operating mode written
/// (holding 101), probed again: the diff names that register, labelled by the profile, with
/// the value before and the value written, and exits 1 (as diff(1)).
#[test]
#[ignore = "needs a pseudo-terminal with `mbtap simulate`; .ci/run runs this with --ignored"]
fn diff_of_two_probe_dumps_names_the_setting_written_between() {
    let dir = std::env::temp_dir().join(format!("mbtap-probe-diff-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bus = dir.join("bus");
    let _sim = common::simulate(&bus, &[]);
    wait_for(&bus);
    let link = bus.to_str().unwrap();
    let dump = |name: &str| {
        let (doc, ok) = probe(link, &["--unit", "1", "--range", "100-110", "--tables", "holding"]);
        assert!(ok, "{doc}");
        assert!(doc["image"].as_array().is_some_and(|rows| !rows.is_empty()), "{doc}");
        let path = dir.join(name);
        std::fs::write(&path, doc.to_string()).unwrap();
        path
    };
    let before = dump("before.json");
    let w = Command::new(BIN)
        .args(["write", link, "--parity", "even", "--unit", "1", "--device", "mk4", "Operating mode=2"])
        .output()
        .unwrap();
    assert!(w.status.success(), "{}", String::from_utf8_lossy(&w.stderr));
    let after = dump("after.json");
    let o = Command::new(BIN)
        .args(["diff", before.to_str().unwrap(), after.to_str().unwrap(), "--device", "1=mk4"])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    let line =
        out.lines().find(|l| l.starts_with("unit 1 holding 101 Operating mode:")).unwrap_or_else(|| panic!("{out}"));
    assert!(line.ends_with("→ control over RS-485 (2)"), "{line}");
    std::fs::remove_dir_all(&dir).unwrap();
}
