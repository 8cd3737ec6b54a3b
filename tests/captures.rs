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
