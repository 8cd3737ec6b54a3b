//! The profile format: loading, precise errors with file:line:column, and annotation of
//! register and bit values (scaling, enums, bits, 32-bit pairs, blocks, findings).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_device::profile::annotate::{Note, Shown, annotate_bits, annotate_registers};
use mbtap_device::profile::{Table, load};

const EXAMPLE: &str = include_str!("../fixtures/example-profile.toml");

fn example() -> mbtap_device::profile::Profile {
    load("example-profile.toml", EXAMPLE).unwrap()
}

/// The example: MK4 #1 reading input registers 430–433 = 0x0901, 0x08FA, 0x0906, 0x0900.
#[test]
fn phase_voltages_are_scaled() {
    let a = annotate_registers(&example(), Table::InputRegisters, 430, &[0x0901, 0x08FA, 0x0906, 0x0900], false);
    let shown: Vec<String> = a.iter().map(ToString::to_string).collect();
    assert_eq!(
        shown,
        [
            "430 Phase A (L1) voltage = 230.5 V (raw 2305)",
            "431 Phase B (L2) voltage = 229.8 V (raw 2298)",
            "432 Phase C (L3) voltage = 231.0 V (raw 2310)",
            "433 Average phase voltage = 230.4 V (raw 2304)",
        ]
    );
}

#[test]
fn enums_bits_pairs_blocks_and_reserved() {
    let p = example();
    let a = annotate_registers(&p, Table::HoldingRegisters, 101, &[2], false);
    assert_eq!(a[0].shown, Shown::Label("RS-485 control".into()));
    let a = annotate_registers(&p, Table::InputRegisters, 409, &[0b100_0000_0101], false);
    assert_eq!(a[0].shown, Shown::Bits(vec!["DI.1".into(), "DI.3".into(), "DI.11".into()]));
    let a = annotate_registers(&p, Table::InputRegisters, 465, &[0x0001, 0x0002], false);
    assert_eq!((a.len(), a[0].raw), (1, 0x0001_0002));
    let a = annotate_registers(&p, Table::InputRegisters, 466, &[0x0002], false);
    assert_eq!(a[0].notes, vec![Note::HalfOfPair]);
    let a = annotate_registers(&p, Table::InputRegisters, 517, &[24, 32], false);
    assert_eq!(a[0].name.as_deref(), Some("Alarm log record 2: alarm code"));
    assert_eq!(a[1].notes, vec![Note::OutOfRange { min: 1, max: 31 }]);
    let a = annotate_registers(&p, Table::InputRegisters, 477, &[0], false);
    assert_eq!(a[0].notes, vec![Note::Reserved]);
    let a = annotate_registers(&p, Table::InputRegisters, 2000, &[0], false);
    assert_eq!(a[0].notes, vec![Note::Undocumented]);
}

#[test]
fn writes_flag_read_only_clamping_and_commands() {
    let p = example();
    let a = annotate_registers(&p, Table::InputRegisters, 430, &[2300], true);
    assert_eq!(a[0].notes, vec![Note::WriteToReadOnly]);
    let a = annotate_registers(&p, Table::HoldingRegisters, 104, &[12_000], true);
    assert_eq!(a[0].notes, vec![Note::WillClamp { to: 10_000 }]);
    let a = annotate_registers(&p, Table::HoldingRegisters, 126, &[30], true);
    assert_eq!(a[0].notes, vec![Note::Command("clear the alarm log".into())]);
}

#[test]
fn coils_with_runs_and_labels() {
    let a = annotate_bits(&example(), Table::Coils, 12, &[true, false], false);
    assert_eq!(a[0].name.as_deref(), Some("Universal relay K1"));
    assert_eq!(a[1].name.as_deref(), Some("Universal relay K2"));
    let a = annotate_bits(&example(), Table::Coils, 0, &[true], false);
    assert_eq!(a[0].shown, Shown::Bool { on: true, label: Some("on".into()) });
}

#[test]
fn syntax_error_names_line_and_column() {
    let bad =
        "[profile]\nname = \"x\"\ndevice = \"y\"\n\n[[input_registers]]\naddress = 430\nname = \"v\nscale = 0.1\n";
    let e = load("bad.toml", bad).unwrap_err();
    assert_eq!((e.file.as_str(), e.line), ("bad.toml", 7), "{e}");
}

#[test]
fn unknown_key_is_an_error_with_its_position() {
    let bad =
        "[profile]\nname = \"x\"\ndevice = \"y\"\n\n[[input_registers]]\naddress = 430\nname = \"v\"\nscael = 0.1\n";
    let e = load("bad.toml", bad).unwrap_err();
    assert!(e.message.contains("scael"), "{e}");
    assert!(e.line >= 5, "{e}");
}

#[test]
fn duplicate_address_names_both_places() {
    let bad = "[profile]\nname = \"x\"\ndevice = \"y\"\n\n[[input_registers]]\naddress = 430\nname = \"a\"\n\n[[input_registers]]\naddresses = [429, 431]\nname = \"b\"\n";
    let e = load("dup.toml", bad).unwrap_err();
    assert_eq!(e.line, 9, "{e}");
    assert!(e.message.contains("input_registers 430 is already defined at line 5"), "{e}");
}

#[test]
fn enum_without_labels_and_backwards_ranges_are_refused() {
    let e = load(
        "e.toml",
        "[profile]\nname = \"x\"\ndevice = \"y\"\n[[holding_registers]]\naddress = 1\nname = \"m\"\ntype = \"enum\"\n",
    )
    .unwrap_err();
    assert!(e.message.contains("needs `enum"), "{e}");
    let e = load(
        "r.toml",
        "[profile]\nname = \"x\"\ndevice = \"y\"\n[[holding_registers]]\naddress = 1\nname = \"m\"\nrange = [5, 1]\n",
    )
    .unwrap_err();
    assert!(e.message.contains("runs backwards"), "{e}");
}

/// `profiles check` refuses `[line] baud = 0`, `framing = "9Z7"`, `mode = "tcp"`, and `scale = nan`
/// or `inf`, each at its line and column.
#[test]
fn impossible_line_settings_and_scales_are_refused_where_they_stand() {
    let head = "[profile]\nname = \"x\"\ndevice = \"y\"\n\n[line]\n";
    for (line, key) in [("baud = 0", "baud = 0"), ("framing = \"9Z7\"", "9Z7"), ("mode = \"tcp\"", "tcp")] {
        let src = format!("{head}{line}\n");
        let e = load("line.toml", &src).unwrap_err();
        assert_eq!(e.line, 6, "{line}: {e}");
        assert!(e.column >= 1, "{line}: {e}");
        assert!(e.message.contains(key), "{line}: {e}");
    }
    for scale in ["nan", "inf", "-inf", "0.0"] {
        let src = format!(
            "[profile]\nname = \"x\"\ndevice = \"y\"\n\n[[input_registers]]\naddress = 430\nname = \"v\"\nscale = {scale}\n"
        );
        let e = load("scale.toml", &src).unwrap_err();
        assert!(e.message.contains("scale"), "{scale}: {e}");
        assert!(e.line >= 5, "{scale}: {e}");
    }
    // What a document really says still loads.
    let ok = format!("{head}baud = 9600\nframing = \"8N1\"\nmode = \"rtu\"\n");
    assert!(load("ok.toml", &ok).is_ok());
}

/// A profile declares a vendor function's frame lengths (`[[vendor_functions]]`);
/// `replay --device` reads the first answer of a capture at its declared length although its
/// CRC ends in `00` and its `00` glitch is glued to it — 13, 14 and 15 bytes all check, and
/// nothing has been learned from the line yet. Without the profile the glitch is taken into
/// the frame. A code whose structure gives the length, or a length no frame has, is refused
/// with its line.
#[test]
fn a_profile_declares_vendor_frame_lengths() {
    let dir = std::env::temp_dir().join(format!("mbtap-vendor-lengths-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let profile = dir.join("vendor.toml");
    std::fs::write(
        &profile,
        "[profile]\nname = \"vendor\"\ndevice = \"A device with a vendor read\"\n\n\
         [[vendor_functions]]\ncode = 0x41\nrequest_length = 7\nresponse_length = 14\n",
    )
    .unwrap();
    let frames = dir.join("frames.txt");
    // The request (unit 1, code 41, 3 data, CRC 9B FC); the answer (10 data, CRC 38 00) with a
    // 00 glitch after it.
    std::fs::write(&frames, "01 41 09 08 07 9B FC\n01 41 A3 00 00 01 02 03 04 05 06 07 38 00 00\n").unwrap();
    let capture = dir.join("vendor.pcapng");
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let o = std::process::Command::new(bin)
        .args(["generate", capture.to_str().unwrap(), "--frames", frames.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let lengths = |device: Option<&std::path::Path>| -> Vec<(u64, bool)> {
        let mut cmd = std::process::Command::new(bin);
        cmd.args(["replay", capture.to_str().unwrap(), "--format", "jsonl"]);
        if let Some(p) = device {
            cmd.args(["--device", &format!("1={}", p.display())]);
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .filter(|j| j["event"] == "frame")
            .map(|j| (j["hex"].as_str().unwrap().len() as u64 / 2, j["check_ok"] == true))
            .collect()
    };
    assert_eq!(lengths(Some(&profile)), [(7, true), (14, true)]);
    assert_ne!(lengths(None), [(7, true), (14, true)]);
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[profile]\nname = \"bad\"\ndevice = \"x\"\n\n[[vendor_functions]]\ncode = 3\nresponse_length = 9\n",
    )
    .unwrap();
    let e = mbtap_device::profile::load("bad", &std::fs::read_to_string(&bad).unwrap()).unwrap_err().to_string();
    assert!(e.contains("bad:5:") && e.contains("0x03"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
