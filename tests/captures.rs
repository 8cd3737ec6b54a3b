//! The regression corpus: every capture in `captures/` replayed through the analyzer, its text
//! transcript compared with the golden snapshot (`tests/snapshots/captures__*.snap`). A change
//! in what mbtap sees on a recorded bus shows up here as a diff to review.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap::output::{EventFormat, EventWriter, replay};
use mbtap_core::line_args::LineOverrides;

/// Warnings, then every event, then the summary, as one text. A capture with a `.devices`
/// file beside it (`UNIT=PROFILE` per line) is annotated with those built-in profiles.
fn transcript(path: &std::path::Path, format: EventFormat) -> String {
    let file = std::fs::File::open(path).unwrap();
    let mut w = EventWriter::new(Vec::new(), format);
    if let Ok(devices) = std::fs::read_to_string(path.with_extension("devices")) {
        for line in devices.lines().filter(|l| !l.trim().is_empty()) {
            let (unit, name) = line.split_once('=').unwrap();
            let profile = mbtap_core::profile::builtin::get(name.trim()).unwrap().unwrap();
            w.profiles.insert(unit.trim().parse().unwrap(), profile);
        }
    }
    let mut warnings = Vec::new();
    replay(std::io::BufReader::new(file), LineOverrides::default(), &mut w, &mut warnings).unwrap();
    let mut out = String::from_utf8(warnings).unwrap();
    out.push_str(&String::from_utf8(std::mem::take(&mut w.out)).unwrap());
    out.push_str(&w.stats.text());
    out
}

#[test]
fn golden_transcripts() {
    insta::glob!("../captures", "*.pcap*", |path| {
        insta::assert_snapshot!(transcript(path, EventFormat::Text));
    });
}

/// JSON lines keep the contract of ARCHITECTURE.md on every capture: `event`, `hex`,
/// `check_ok`, `t_ns` on every frame.
#[test]
fn jsonl_contract_on_every_capture() {
    insta::glob!("../captures", "*.pcap*", |path| {
        let t = transcript(path, EventFormat::Jsonl);
        let mut frames = 0;
        for line in t.lines().filter(|l| l.starts_with('{')) {
            let j: serde_json::Value = serde_json::from_str(line).unwrap();
            if j["event"] == "frame" {
                frames += 1;
                assert!(j["hex"].is_string() && j["check_ok"].is_boolean() && j["t_ns"].is_u64(), "{line}");
            }
        }
        assert!(frames > 0, "{}", path.display());
    });
}

/// Issue 31: `replay` did not use the `NAME.devices` file beside a capture (the tests above
/// read it themselves). The real binary annotates the MKZP examples with no `--device`, says
/// where the profiles came from, and `--device` still wins.
#[test]
fn replay_uses_the_devices_file_beside_the_capture() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/mkzp-examples-rtu.pcapng");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap")).args(["replay", capture]).output().unwrap();
    let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{err}");
    assert!(err.contains("mkzp-examples-rtu.devices: 5=mkzp, 247=mkzp"), "{err}");
    assert!(out.contains("Current_Faza_A: phase A current"), "annotated by the MKZP profile:\n{out}");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["replay", capture, "--device", "5=display"])
        .output()
        .unwrap();
    assert!(
        !String::from_utf8_lossy(&o.stdout).contains("     50 Current_Faza_A"),
        "--device 5=display wins for unit 5"
    );
}
