//! Wireshark export checked by the real `tshark` (installed by `.ci/run`): every frame of every
//! capture in `captures/` decodes as Modbus RTU with the unit, function, direction and CRC
//! status mbtap reported. Needs tshark, so it is `#[ignore]`d in a plain `cargo test`; CI runs
//! it with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::Command;

fn mbtap(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_mbtap")).args(args).output().unwrap();
    assert!(o.status.success(), "mbtap {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout).unwrap()
}

#[test]
#[ignore = "needs tshark; .ci/run installs it and runs this with --ignored"]
fn tshark_decodes_every_exported_frame() {
    let dir = tempdir();
    let captures = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/captures")).unwrap();
    let mut checked = 0;
    for entry in captures {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "pcapng") {
            continue;
        }
        let p = path.to_str().unwrap();
        let out = dir.join(format!("{}.wireshark.pcapng", path.file_stem().unwrap().to_string_lossy()));
        mbtap(&["export", p, "-o", out.to_str().unwrap()]);
        // What mbtap saw: frames in order, with unit, function, direction and check.
        let ours: Vec<serde_json::Value> = mbtap(&["replay", p, "--format", "jsonl"])
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .filter(|j: &serde_json::Value| j["event"] == "frame" && j["unit"].is_u64())
            .collect();
        let o = Command::new("tshark")
            .args(["-r", out.to_str().unwrap(), "-o", "mbrtu.tcp.port:502", "-o", "mbrtu.crc_verification:TRUE"])
            .args([
                "-T",
                "fields",
                "-E",
                "separator=|",
                "-e",
                "mbrtu.unit_id",
                "-e",
                "modbus.func_code",
                "-e",
                "mbtcp.unit_id",
                "-e",
                "mbrtu.crc16.status",
                "-e",
                "_ws.col.Info",
            ])
            .output()
            .expect("tshark must be installed for this test (apt-get install tshark)");
        assert!(o.status.success(), "tshark: {}", String::from_utf8_lossy(&o.stderr));
        let theirs: Vec<String> = String::from_utf8(o.stdout).unwrap().lines().map(str::to_owned).collect();
        assert_eq!(theirs.len(), ours.len(), "{p}: frame count");
        for (i, (t, j)) in theirs.iter().zip(&ours).enumerate() {
            // Wireshark may split a damaged frame into several PDUs by its own length guess:
            // the first one is the frame's start.
            let mut f: Vec<&str> = t.split('|').map(|v| v.split(',').next().unwrap_or("")).collect();
            // Broadcasts and 4-byte frames are exported as Modbus/TCP (Wireshark's mbrtu refuses them).
            let unit = if f[0].is_empty() {
                f.remove(2)
            } else {
                f.remove(2);
                f[0]
            };
            let refused_by_mbrtu = j["unit"] == 0 || j["len"].as_u64().unwrap() < 5;
            if refused_by_mbrtu && j["check_ok"] == false {
                // A damaged frame Wireshark's mbrtu will not take and Modbus/TCP cannot carry
                // (it has no CRC): exported, shown by Wireshark as data.
                assert_eq!(unit, "", "{p} frame {i} ({t})");
                checked += 1;
                continue;
            }
            if refused_by_mbrtu {
                assert_eq!(unit, j["unit"].to_string(), "{p} frame {i}: unit via mbtcp ({t})");
                assert_eq!(
                    f[1].parse::<u64>().unwrap(),
                    j["function"].as_u64().unwrap(),
                    "{p} frame {i}: function ({t})"
                );
                checked += 1;
                continue;
            }
            assert_eq!(unit, j["unit"].to_string(), "{p} frame {i}: unit ({t})");
            if j["check_ok"] == true {
                // tshark shows the function code without the exception bit.
                assert_eq!(
                    f[1].parse::<u64>().unwrap(),
                    j["function"].as_u64().unwrap() & 0x7F,
                    "{p} frame {i}: function ({t})"
                );
                assert_eq!(f[2], "1", "{p} frame {i}: CRC should verify ({t})");
            } else {
                assert_eq!(f[2], "0", "{p} frame {i}: CRC should fail ({t})");
            }
            match j["direction"].as_str().unwrap() {
                "request" => assert!(f[3].contains("Query"), "{p} frame {i}: want query ({t})"),
                "response" => assert!(f[3].contains("Response"), "{p} frame {i}: want response ({t})"),
                _ => {}
            }
            checked += 1;
        }
    }
    assert!(checked > 1000, "only {checked} frames checked");
}

fn tempdir() -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-tshark-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}
