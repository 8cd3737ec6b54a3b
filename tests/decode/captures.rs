//! The regression corpus: every capture in `captures/` replayed through the analyzer, its text
//! transcript compared with the golden snapshot (`tests/snapshots/captures__*.snap`). A change
//! in what mbtap sees on a recorded bus shows up here as a diff to review.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap::output::{EventFormat, EventWriter, replay};
use mbtap_analysis::line_args::LineOverrides;

/// Warnings, then every event, then the summary, as one text. A capture with a `.devices`
/// file beside it (`UNIT=PROFILE` per line) is annotated with those built-in profiles.
fn transcript(path: &std::path::Path, format: EventFormat) -> String {
    let file = std::fs::File::open(path).unwrap();
    let mut w = EventWriter::new(Vec::new(), format);
    if let Ok(devices) = std::fs::read_to_string(path.with_extension("devices")) {
        for line in devices.lines().filter(|l| !l.trim().is_empty()) {
            let (unit, name) = line.split_once('=').unwrap();
            let profile = mbtap_device::profile::builtin::get(name.trim()).unwrap().unwrap();
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
    insta::glob!("../../captures", "*.pcap*", |path| {
        insta::assert_snapshot!(transcript(path, EventFormat::Text));
    });
}

/// JSON lines keep the contract of ARCHITECTURE.md on every capture: `event`, `hex`,
/// `check_ok`, `t_ns` on every frame.
#[test]
fn jsonl_contract_on_every_capture() {
    insta::glob!("../../captures", "*.pcap*", |path| {
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

/// `replay` uses the `NAME.devices` file beside a capture (the tests above read it themselves): the
/// real binary annotates the MKZP examples with no `--device`, says where the profiles came from,
/// and `--device` still wins.
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

/// `mbtap learn` on a recorded line (the simulated bus, polled many times) drafts a
/// profile per unit that `profiles check` accepts, and finds the blocks the master polls.
#[test]
fn learn_drafts_profiles_that_load() {
    let dir = std::env::temp_dir().join(format!("mbtap-learn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let capture = dir.join("line.pcapng");
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let o = std::process::Command::new(bin)
        .args(["generate", capture.to_str().unwrap(), "--transactions", "600", "--seed", "3"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // `-o FILE` holds one profile; several units heard, it is refused with what to
    // do (it wrote `draft-unit-N.toml` files nobody asked for), and nothing is written.
    let draft = dir.join("draft.toml");
    let o = std::process::Command::new(bin)
        .args(["learn", capture.to_str().unwrap(), "-o", draft.to_str().unwrap(), "--format", "json"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--unit N") && err.contains("--dir DIR"), "{err}");
    assert!(!draft.exists() && !dir.join("draft-unit-1.toml").exists());
    let drafts = dir.join("drafts");
    let o = std::process::Command::new(bin)
        .args(["learn", capture.to_str().unwrap(), "--dir", drafts.to_str().unwrap(), "--format", "json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let units = report["units"].as_array().unwrap();
    assert!(units.len() >= 2, "{report}");
    assert!(units.iter().all(|u| !u["blocks"].as_array().unwrap().is_empty()), "{report}");
    for u in units {
        let n = u["unit"].as_u64().unwrap();
        let file = drafts.join(format!("learned-unit-{n}.toml"));
        let check =
            std::process::Command::new(bin).args(["profiles", "check", file.to_str().unwrap()]).output().unwrap();
        assert!(check.status.success(), "{}: {}", file.display(), String::from_utf8_lossy(&check.stderr));
    }
}

/// `mbtap diff` — a capture against its own register image is the same (exit 0); an
/// image where the operating mode was changed shows that register, named and labelled by the
/// profile, before and after (exit 1, as diff(1)).
#[test]
fn diff_names_what_changed_between_a_capture_and_an_image() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/mk4-doc-examples-rtu.pcapng");
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let dir = std::env::temp_dir().join(format!("mbtap-diff-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let image = dir.join("before.csv");
    let o =
        std::process::Command::new(bin).args(["replay", capture, "--image", image.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let same = std::process::Command::new(bin).args(["diff", capture, image.to_str().unwrap()]).output().unwrap();
    assert_eq!(same.status.code(), Some(0), "{}", String::from_utf8_lossy(&same.stdout));
    // Holding 101 (operating mode) from 0 to 2 in the image.
    let text = std::fs::read_to_string(&image).unwrap();
    let changed: String = text
        .lines()
        .map(|l| if l.starts_with("1,holding_registers,101,") { l.replacen(",0,\"", ",2,\"", 1) } else { l.to_owned() })
        .collect::<Vec<_>>()
        .join("\n");
    let after = dir.join("after.csv");
    std::fs::write(&after, changed).unwrap();
    let o = std::process::Command::new(bin)
        .args(["diff", capture, after.to_str().unwrap(), "--device", "1=mk4"])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("unit 1 holding 101 Operating mode: drain by level sensors (0) → control over RS-485 (2)"),
        "{out}"
    );
    assert!(out.contains("1 differ"), "{out}");
}

/// On recordings of real meters (bytes or register values from public reports, see
/// `captures/README.md`), `mbtap learn` finds the float pairs and their word order the reports
/// give — high word first on the EV meter (six floats at input 6–17) and the PM5350 (frequency
/// at holding 3109), low word first on the device of the Node-RED report (holding 2 and 6) —
/// and joins nothing else.
#[test]
fn learn_finds_float_pairs_and_their_word_order_on_real_meter_recordings() {
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let cases: [(&str, &[(u64, &str)]); 3] = [
        (
            "rtu-real-ev-meter-floats.pcapng",
            &[
                (6, "f32 high word first"),
                (8, "f32 high word first"),
                (10, "f32 high word first"),
                (12, "f32 high word first"),
                (14, "f32 high word first"),
                (16, "f32 high word first"),
            ],
        ),
        ("rtu-real-cdab-floats.pcapng", &[(2, "f32 low word first"), (6, "f32 low word first")]),
        ("rtu-real-pm5350-frequency.pcapng", &[(3109, "f32 high word first")]),
    ];
    for (file, expected) in cases {
        let path = format!("{}/captures/{file}", env!("CARGO_MANIFEST_DIR"));
        let o = std::process::Command::new(bin).args(["learn", &path, "--format", "json"]).output().unwrap();
        assert!(o.status.success(), "{file}: {}", String::from_utf8_lossy(&o.stderr));
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let wide: Vec<(u64, String)> = report["units"][0]["registers"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["width"] == 2)
            .map(|r| (r["address"].as_u64().unwrap(), r["type"].as_str().unwrap().to_owned()))
            .collect();
        let expected: Vec<(u64, String)> = expected.iter().map(|&(a, t)| (a, t.to_owned())).collect();
        assert_eq!(wide, expected, "{file}");
    }
}

/// The registers `learn` drafts for unit 1 of a capture: address → type.
fn learned(file: &str) -> std::collections::BTreeMap<u64, String> {
    let path = format!("{}/captures/{file}", env!("CARGO_MANIFEST_DIR"));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["learn", &path, "--format", "json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{file}: {}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    report["units"][0]["registers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["address"].as_u64().unwrap(), r["type"].as_str().unwrap().to_owned()))
        .collect()
}

/// The pairs of a meter's blocks that are ever non-zero, from its frame list (`NAME.txt` beside
/// the capture): every answer's registers, pairs from each block's first address.
fn non_zero_pairs(txt: &str, first_of: &dyn Fn(usize) -> u64) -> std::collections::BTreeSet<u64> {
    let path = format!("{}/captures/{txt}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap();
    let frames: Vec<Vec<u8>> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect())
        .collect();
    let mut out = std::collections::BTreeSet::new();
    // Requests and answers alternate; answers are unit, function, byte count, data, CRC.
    for (k, answer) in frames.iter().skip(1).step_by(2).enumerate() {
        let data = &answer[3..answer.len() - 2];
        for (i, w) in data.chunks(4).enumerate() {
            if w.iter().any(|&b| b != 0) {
                out.insert(first_of(k) + 2 * i as u64);
            }
        }
    }
    out
}

/// A three-phase meter (FC04 blocks of 82 and 60 registers, 64 polls, every value a
/// float high word first; `captures/rtu-shape-three-phase-floats.txt`): pair by pair, `learn`
/// drafted 1 of its 43 non-zero floats right — constants as two u16 (13.09 = 0x4151 0x70A4),
/// voltages as u32 "carries", 0x4516 1000…4000 as a constant and a u16, 12.0 over a zero low
/// word as u16, two 0.7 as the text "?333?333". Judged by block: all 43, and nothing else joined.
#[test]
fn learn_types_every_float_of_a_three_phase_meter_by_its_blocks() {
    let learned = learned("rtu-shape-three-phase-floats.pcapng");
    let floats = non_zero_pairs("rtu-shape-three-phase-floats.txt", &|k| if k % 2 == 0 { 0 } else { 200 });
    assert_eq!(floats.len(), 43);
    for a in &floats {
        assert_eq!(learned.get(a).map(String::as_str), Some("f32 high word first"), "input {a}: {learned:?}");
    }
    // Constant, moving, carrying, zero-low-word and printable-looking cases by name.
    for a in [6, 8, 0, 12, 34, 30, 32] {
        assert!(floats.contains(&a), "{a}");
    }
    let wide: Vec<&u64> = learned.iter().filter(|(_, t)| t.contains("word first")).map(|(a, _)| a).collect();
    assert_eq!(wide.len(), floats.len(), "{learned:?}");
}

/// A single-phase meter tapped for two polls (FC03 at 0x2000 and 0x4000, floats high word first,
/// zeros between them): the frequency 0x4248 0x3333 (50.05 Hz) at 8206/8207 is joined as the rest
/// of its answer is, never as 8205/8206 low word first (50.0).
#[test]
fn learn_keeps_a_blocks_word_order_and_alignment_on_two_polls() {
    let learned = learned("rtu-shape-single-phase-floats.pcapng");
    let floats = non_zero_pairs("rtu-shape-single-phase-floats.txt", &|k| if k % 2 == 0 { 0x2000 } else { 0x4000 });
    assert_eq!(floats.len(), 9);
    assert!(floats.contains(&8206));
    for a in &floats {
        assert_eq!(learned.get(a).map(String::as_str), Some("f32 high word first"), "holding {a}: {learned:?}");
    }
    assert!(!learned.get(&8205).is_some_and(|t| t.contains("word first")), "{learned:?}");
}

/// `diff` of captures whose every block is corrupt never says "0 differ, 0 the same" with exit 0:
/// the reader's warning is said with the file, and "nothing to compare" exits 2.
#[test]
fn diff_of_unreadable_captures_says_so_and_does_not_claim_sameness() {
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let dir = std::env::temp_dir().join(format!("mbtap-diff-corrupt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A pcap header (magic, v2.4, snaplen 65535, linktype 147) and then a record header whose
    // length (0xFFFFFFF0) no record can have: the rest is corrupt.
    let mut pcap = vec![0xD4, 0xC3, 0xB2, 0xA1, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xFF, 0xFF, 0, 0, 147, 0, 0, 0];
    pcap.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 0, 0xF0, 0xFF, 0xFF, 0xFF, 0xF0, 0xFF, 0xFF, 0xFF]);
    pcap.extend(std::iter::repeat_n(0xA5, 4096));
    let f = dir.join("corrupt.pcap");
    std::fs::write(&f, &pcap).unwrap();
    let o = std::process::Command::new(bin).args(["diff", f.to_str().unwrap(), f.to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("nothing to compare"), "{err}");
    assert!(!String::from_utf8_lossy(&o.stdout).contains("0 the same"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An image file is read row by row into four numbers each, and one larger than any image of every
/// address is refused unread (as a JSON tree, a 100 MB dump takes 2.1–3.7 GB).
#[test]
fn diff_refuses_an_image_file_larger_than_any_image() {
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let dir = std::env::temp_dir().join(format!("mbtap-diff-big-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let big = dir.join("big.json");
    let f = std::fs::File::create(&big).unwrap();
    // 65 MiB, sparse: over the 64 MiB read.
    f.set_len(65 << 20).unwrap();
    let o =
        std::process::Command::new(bin).args(["diff", big.to_str().unwrap(), big.to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("not read"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The commands end through one runner now; the real binary's `replay` still prints,
/// on every capture and in both formats, exactly the events and the summary the analysis gives
/// the library's writer (what the golden transcripts above hold) — byte for byte.
#[test]
fn the_binary_replays_every_capture_as_the_library_writes_it() {
    insta::glob!("../../captures", "*.pcap*", |path| {
        for (format, arg) in [(EventFormat::Text, "text"), (EventFormat::Jsonl, "jsonl")] {
            let mut expected = Vec::new();
            let mut w = EventWriter::new(&mut expected, format);
            if let Ok(devices) = std::fs::read_to_string(path.with_extension("devices")) {
                for line in devices.lines().filter(|l| !l.trim().is_empty()) {
                    let (unit, name) = line.split_once('=').unwrap();
                    let profile = mbtap_device::profile::builtin::get(name.trim()).unwrap().unwrap();
                    w.profiles.insert(unit.trim().parse().unwrap(), profile);
                }
            }
            let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
            replay(file, LineOverrides::default(), &mut w, &mut std::io::sink()).unwrap();
            w.finish().unwrap();
            let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
                .args(["replay", "--format", arg])
                .arg(path)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}: {}", path.display(), String::from_utf8_lossy(&o.stderr));
            assert!(o.stdout == expected, "{} --format {arg}: the binary's output differs", path.display());
        }
    });
}

/// `learn --dir D` writes its drafts through the one writer of whole files: a symbolic link
/// planted at the name an older writer used for its temporary (`learned-unit-1.toml.tmp`), or at
/// the draft's own name, never makes it write into the file the link points to.
#[test]
fn learn_never_writes_through_a_planted_link() {
    let dir = std::env::temp_dir().join(format!("mbtap-learn-links-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let drafts = dir.join("drafts");
    std::fs::create_dir_all(&drafts).unwrap();
    let victim = dir.join("victim.txt");
    std::fs::write(&victim, "keep me").unwrap();
    std::os::unix::fs::symlink(&victim, drafts.join("learned-unit-1.toml.tmp")).unwrap();
    std::os::unix::fs::symlink(&victim, drafts.join("learned-unit-1.toml")).unwrap();
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/mk4-doc-examples-rtu.pcapng");
    let learn = |force: bool| {
        std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .args(["learn", capture, "--dir", drafts.to_str().unwrap(), "--format", "json"])
            .args(force.then_some("--force"))
            .output()
            .unwrap()
    };
    // Something is at the draft's name: kept, and said, unless --force.
    let o = learn(false);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("already exists") && err.contains("--force"), "{err}");
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep me");
    let o = learn(true);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep me");
    let draft = drafts.join("learned-unit-1.toml");
    assert!(!draft.is_symlink() && std::fs::read_to_string(&draft).unwrap().contains("[profile]"));
    std::fs::remove_dir_all(&dir).ok();
}
