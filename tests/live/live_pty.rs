//! The live path end to end on real pseudo-terminals (socat): `mbtap play` writes a capture
//! into one end with its timing, `mbtap sniff --record` listens on the other; the recording
//! must replay to the same frames as the original, and the live output must equal the replay
//! of the recording (identical chunks, identical output). Needs socat: `#[ignore]`d in a plain
//! `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use common::{BIN, Kill, socat_pair, wait_for};

/// The hex of every frame with a valid check, in order.
fn good_frames(jsonl: &str) -> Vec<String> {
    events(jsonl)
        .filter(|j| j["event"] == "frame" && j["check_ok"] == true)
        .map(|j| j["hex"].as_str().unwrap().to_owned())
        .collect()
}

/// Every byte of every frame, noise burst and turnaround glitch, in order: nothing lost or
/// added. (A glitch is a byte of the line too: when the pty's jitter puts a pause before a
/// damaged frame's last `00`, the framer may cut that byte as a glitch; leaving glitches out
/// made this test fail once under load with every byte there.)
fn all_bytes(jsonl: &str) -> String {
    events(jsonl)
        .filter(|j| j["event"] == "frame" || j["event"] == "noise" || j["event"] == "glitch")
        .map(|j| j["hex"].as_str().unwrap().to_owned())
        .collect()
}

fn events(jsonl: &str) -> impl Iterator<Item = serde_json::Value> + '_ {
    jsonl.lines().map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
}

fn replay(path: &std::path::Path) -> String {
    let o = Command::new(BIN).args(["replay", path.to_str().unwrap(), "--format", "jsonl"]).output().unwrap();
    assert!(o.status.success());
    String::from_utf8(o.stdout).unwrap()
}

#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn sniff_records_what_play_sends_through_a_pty() {
    let dir = std::env::temp_dir().join(format!("mbtap-pty-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (_socat, a, b) = socat_pair(&dir);
    let rec = dir.join("rec.pcapng");
    let sniff = Command::new(BIN)
        .args(["sniff", b.to_str().unwrap(), "--format", "jsonl", "--record", rec.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut sniff = Kill(sniff);
    // Drain the output while it runs, or a full pipe would block the sniffer.
    let mut out = sniff.0.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut out, &mut s).unwrap();
        s
    });
    wait_for(&rec);
    std::thread::sleep(Duration::from_millis(200));
    let original = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-19200-8e1-per-byte.pcapng");
    let play = Command::new(BIN).args(["play", original, a.to_str().unwrap()]).output().unwrap();
    assert!(play.status.success(), "{}", String::from_utf8_lossy(&play.stderr));
    // Let the last frame's silence pass, then stop the sniffer as a user would (SIGTERM).
    std::thread::sleep(Duration::from_millis(300));
    let pid = sniff.0.id().to_string();
    assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
    let start = Instant::now();
    while sniff.0.try_wait().unwrap().is_none() {
        assert!(start.elapsed() < Duration::from_secs(10), "sniff did not stop on SIGTERM");
        std::thread::sleep(Duration::from_millis(20));
    }
    let live = reader.join().unwrap();

    let want = replay(std::path::Path::new(original));
    let recorded = replay(&rec);
    // Valid frames are found by structure and CRC, so the pty's timing jitter cannot change
    // them; how a damaged frame is cut may follow the jitter (a pause inside it longer than
    // t3.5 is real evidence of a boundary), but no byte may be lost or added.
    assert_eq!(good_frames(&recorded), good_frames(&want), "the recording replays to the original's valid frames");
    assert_eq!(all_bytes(&recorded), all_bytes(&want), "every byte is in the recording");
    // Live and replayed output agree event for event (the summary line included) — but for
    // what the replay adds: the latency the live session learned, which the recording stores
    // at its end and the replay reads back.
    assert_eq!(live.lines().count(), recorded.lines().count());
    let (live_events, live_summary) = live.trim_end().rsplit_once('\n').unwrap();
    let (recorded_events, recorded_summary) = recorded.trim_end().rsplit_once('\n').unwrap();
    assert_eq!(live_events, recorded_events);
    let live_summary: serde_json::Value = serde_json::from_str(live_summary).unwrap();
    let mut recorded_summary: serde_json::Value = serde_json::from_str(recorded_summary).unwrap();
    let learned_live = &live_summary["observers"][0]["learned_latency_ns"];
    assert!(learned_live.is_u64(), "the live session learned its reads: {live_summary}");
    let stored = recorded_summary["observers"][0].as_object_mut().unwrap().remove("recorded_latency_ns");
    assert_eq!(stored.as_ref(), Some(learned_live), "the recording stores what the live session learned");
    assert_eq!(live_summary, recorded_summary);
}

/// The adapter is pulled mid-session (socat killed, its pty gone) and comes back (a new socat
/// at the same path): sniff says so, reopens it, and the recording goes on with both halves.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn sniff_survives_the_port_disappearing_and_coming_back() {
    let dir = std::env::temp_dir().join(format!("mbtap-pty-lost-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (a, b, rec) = (dir.join("a"), dir.join("b"), dir.join("rec.pcapng"));
    let pair = |a: &std::path::Path, b: &std::path::Path| {
        let child = Command::new("socat")
            .args([format!("pty,raw,echo=0,link={}", a.display()), format!("pty,raw,echo=0,link={}", b.display())])
            .spawn()
            .expect("socat must be installed for this test");
        wait_for(a);
        wait_for(b);
        Kill(child)
    };
    let frames_file = dir.join("frames.txt");
    std::fs::write(&frames_file, "01 03 00 65 00 03 15 D4\n01 03 06 00 00 00 00 01 90 20 89\n").unwrap();
    let capture = dir.join("two.pcapng");
    let g = Command::new(BIN)
        .args(["generate", capture.to_str().unwrap(), "--frames", frames_file.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(g.status.success());

    let first = pair(&a, &b);
    let sniff = Command::new(BIN)
        .args(["sniff", b.to_str().unwrap(), "--format", "jsonl", "--record", rec.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut sniff = Kill(sniff);
    let mut out = sniff.0.stdout.take().unwrap();
    let mut err = sniff.0.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut out, &mut s).unwrap();
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut err, &mut s).unwrap();
        s
    });
    wait_for(&rec);
    std::thread::sleep(Duration::from_millis(200));
    let play = |a: &std::path::Path| {
        let p = Command::new(BIN).args(["play", capture.to_str().unwrap(), a.to_str().unwrap()]).output().unwrap();
        assert!(p.status.success(), "{}", String::from_utf8_lossy(&p.stderr));
    };
    play(&a);
    std::thread::sleep(Duration::from_millis(300));
    drop(first); // the adapter is pulled
    std::thread::sleep(Duration::from_millis(1500));
    let _second = pair(&a, &b); // and plugged back in
    std::thread::sleep(Duration::from_millis(2500)); // sniff retries once a second
    play(&a);
    std::thread::sleep(Duration::from_millis(300));
    let pid = sniff.0.id().to_string();
    assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
    let live = reader.join().unwrap();
    let messages = err_reader.join().unwrap();
    assert!(messages.contains("lost"), "{messages}");
    assert!(messages.contains("is back"), "{messages}");
    let want = ["01030065000315d4", "0103060000000001902089"].repeat(2);
    assert_eq!(good_frames(&live), want, "live: both halves");
    assert_eq!(good_frames(&replay(&rec)), want, "the recording went on");
}

/// A +1 h clock step in a capture (or a corrupt timestamp near 2^64) never makes `play` wait in
/// silence: a gap is capped at `--max-gap`, and said.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn play_caps_a_clock_step_and_says_so() {
    let dir = std::env::temp_dir().join(format!("mbtap-play-gap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (_socat, a, _b) = socat_pair(&dir);
    // Two frames an hour apart: a pcap (microseconds, link type 147) written by hand.
    let frames: [(u32, &[u8]); 2] = [(0, &[0x01, 0x83, 0x03, 0x01, 0x31]), (3600, &[0x01, 0x83, 0x02, 0xC0, 0xF1])];
    let mut f = Vec::new();
    f.extend_from_slice(&0xA1B2_C3D4u32.to_le_bytes());
    f.extend_from_slice(&[2, 0, 4, 0]);
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&65_535u32.to_le_bytes());
    f.extend_from_slice(&147u32.to_le_bytes());
    for (secs, bytes) in frames {
        f.extend_from_slice(&(1_700_000_000 + secs).to_le_bytes());
        f.extend_from_slice(&0u32.to_le_bytes());
        f.extend_from_slice(&u32::try_from(bytes.len()).unwrap().to_le_bytes());
        f.extend_from_slice(&u32::try_from(bytes.len()).unwrap().to_le_bytes());
        f.extend_from_slice(bytes);
    }
    let capture = dir.join("step.pcap");
    std::fs::write(&capture, f).unwrap();
    let child = Command::new(BIN)
        .args(["play", capture.to_str().unwrap(), a.to_str().unwrap(), "--max-gap", "0.2"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // A bound for the test's own sake (an uncapped play would take an hour), not a speed figure.
    let start = Instant::now();
    let mut child = Kill(child);
    while child.0.try_wait().unwrap().is_none() {
        assert!(start.elapsed() < Duration::from_mins(1), "play waited out the hour");
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut err = String::new();
    std::io::Read::read_to_string(child.0.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(err.contains("3600.0 s of silence") && err.contains("played as 0.2 s"), "{err}");
    assert!(err.contains("played 2 packets"), "{err}");
}

/// `sniff --duration 8` of a port that vanishes (its socat ends) ends on time: the deadline holds
/// while the port is away, for `sniff` and `tap` alike.
#[test]
#[ignore = "needs socat; .ci/run installs it and runs this with --ignored"]
fn sniff_duration_holds_while_the_port_is_gone() {
    let dir = std::env::temp_dir().join(format!("mbtap-vanish-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (socat, _a, b) = socat_pair(&dir);
    let mut sniff = Command::new(BIN)
        .args(["sniff", b.to_str().unwrap(), "--format", "summary", "--duration", "2"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    drop(socat);
    // A hang guard, not a timing assertion: the sniff must end on its own.
    let start = Instant::now();
    let status = loop {
        if let Some(s) = sniff.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > Duration::from_secs(30) {
            let _ = sniff.kill();
            panic!("sniff --duration 2 still running 30 s after its port vanished");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut sniff.stderr.take().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");
    assert!(err.contains("waiting for it to come back"), "the port did vanish: {err}");
}

/// `sniff --learn` drafts a register map from a live line and keeps it up to date:
/// the drafts are there while it still listens (rewritten every 10 s of line time), one per
/// unit heard in the directory given (a file holds one unit's profile), and each
/// loads as a profile.
#[test]
#[ignore = "needs a pseudo-terminal with `mbtap simulate --poll`; .ci/run runs this with --ignored"]
fn sniff_learn_keeps_draft_profiles_up_to_date_while_listening() {
    let dir = std::env::temp_dir().join(format!("mbtap-sniff-learn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let line = dir.join("line");
    let _sim = common::simulate(&line, &["--poll"]);
    let drafts = dir.join("site");
    let mut sniff = Command::new(BIN)
        .args(["sniff", line.to_str().unwrap(), "--parity", "even", "--format", "summary", "--duration", "14"])
        .args(["--learn", &format!("{}/", drafts.display())])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // While it listens: the first drafts are written with the first transactions heard.
    let start = Instant::now();
    let unit1 = drafts.join("learned-unit-1.toml");
    while !unit1.exists() {
        assert!(start.elapsed() < Duration::from_secs(12), "no draft while listening");
        assert!(sniff.try_wait().unwrap().is_none(), "sniff ended early");
        std::thread::sleep(Duration::from_millis(100));
    }
    let status = sniff.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut sniff.stderr.take().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");
    for unit in [1, 5, 17] {
        let file = drafts.join(format!("learned-unit-{unit}.toml"));
        assert!(err.contains(&format!("draft profile of unit {unit} written to {}", file.display())), "{err}");
        let check = Command::new(BIN).args(["profiles", "check", file.to_str().unwrap()]).output().unwrap();
        assert!(check.status.success(), "{}", String::from_utf8_lossy(&check.stderr));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `mbtap learn PORT` listens to a live line (here `simulate --poll` on a pty) for
/// `--duration`, then says what it learned of every unit the master polls, as for a capture.
#[test]
#[ignore = "needs a pseudo-terminal with `mbtap simulate --poll`; .ci/run runs this with --ignored"]
fn learn_listens_to_a_port_for_its_duration() {
    let dir = std::env::temp_dir().join(format!("mbtap-learn-port-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let line = dir.join("line");
    let _sim = common::simulate(&line, &["--poll"]);
    let o = Command::new(BIN)
        .args(["learn", line.to_str().unwrap(), "--parity", "even", "--duration", "4", "--format", "json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let units: Vec<u64> = report["units"].as_array().unwrap().iter().map(|u| u["unit"].as_u64().unwrap()).collect();
    assert_eq!(units, [1, 5, 17], "{report}");
    assert!(report["units"].as_array().unwrap().iter().all(|u| !u["blocks"].as_array().unwrap().is_empty()));
    // --duration belongs to a port; given with a capture, it is refused and said why.
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-real-pm5350-frequency.pcapng");
    let o = Command::new(BIN).args(["learn", capture, "--duration", "4"]).output().unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--duration is for listening to a port"));
    std::fs::remove_dir_all(&dir).unwrap();
}
