//! `mbtap profiles import` on register sheets in the shapes vendors publish (Modicon
//! numbers, `0000H`, `0x`, title rows, merged and section rows in XLSX, German and Chinese
//! headers, a function-code column, tabs, units in names, scales as `/10`, `÷100`, `x10^-2`)
//! and Home Assistant YAML — each profile then annotates traffic of that device, read by
//! `mbtap decode`. Unreadable rows are named with row, column and why.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const MBTAP: &str = env!("CARGO_BIN_EXE_mbtap");

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sheets").join(name)
}

fn run(args: &[&str]) -> Output {
    Command::new(MBTAP).args(args).env("MBTAP_PROFILE_DIR", std::env::temp_dir()).output().unwrap()
}

/// Imports `sheet` with `extra` options into a temporary profile; its path and the import's
/// stderr.
fn import(sheet: &str, extra: &[&str]) -> (tempfile_path::TempProfile, String) {
    let out_path = tempfile_path::TempProfile::new(sheet);
    let f = fixture(sheet);
    let mut args = vec!["profiles", "import", f.to_str().unwrap(), "-o", out_path.path.to_str().unwrap()];
    args.extend_from_slice(extra);
    let out = run(&args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{sheet}: {err}");
    let check = run(&["profiles", "check", out_path.path.to_str().unwrap()]);
    assert!(check.status.success(), "{sheet}: {}", String::from_utf8_lossy(&check.stderr));
    (out_path, err)
}

/// A temporary profile file, removed when dropped.
mod tempfile_path {
    pub struct TempProfile {
        pub path: std::path::PathBuf,
    }
    impl TempProfile {
        pub fn new(tag: &str) -> Self {
            // Tests run in parallel and may import the same sheet: one file each.
            static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
            let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let path = std::env::temp_dir().join(format!("mbtap-import-{}-{n}-{tag}.toml", std::process::id()));
            Self { path }
        }
    }
    impl Drop for TempProfile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

fn hex(b: &[u8]) -> String {
    use std::fmt::Write as _;
    b.iter().fold(String::new(), |mut s, x| {
        let _ = write!(s, "{x:02X}");
        s
    })
}

/// An RTU read of `quantity` registers at `address` (function `fc`) from unit 1, answered with
/// `words`: the two frames as hex.
fn read(fc: u8, address: u16, words: &[u16]) -> [String; 2] {
    let q = u16::try_from(words.len()).unwrap();
    let mut req = vec![fc];
    req.extend_from_slice(&address.to_be_bytes());
    req.extend_from_slice(&q.to_be_bytes());
    let mut resp = vec![fc, u8::try_from(words.len() * 2).unwrap()];
    for w in words {
        resp.extend_from_slice(&w.to_be_bytes());
    }
    let (mut a, mut b) = (Vec::new(), Vec::new());
    mbtap_proto::encode_rtu(1, &req, &mut a);
    mbtap_proto::encode_rtu(1, &resp, &mut b);
    [hex(&a), hex(&b)]
}

/// What `decode` says of `frames` with `profile` on unit 1.
fn annotate(profile: &Path, frames: &[String; 2]) -> String {
    let device = format!("1={}", profile.display());
    let out = run(&["decode", "--device", &device, &frames[0], &frames[1]]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn f32_words(v: f32) -> [u16; 2] {
    let b = v.to_bits();
    [u16::try_from(b >> 16).unwrap(), u16::try_from(b & 0xFFFF).unwrap()]
}

#[test]
fn an_energy_meter_sheet_with_modicon_numbers_and_floats() {
    let (p, err) = import("energy-meter-modicon.csv", &[]);
    assert!(err.contains("Modicon"), "{err}");
    let text = annotate(&p.path, &read(0x04, 0, &f32_words(230.5)));
    assert!(text.contains("Phase 1 line to neutral volts = 230.5 V"), "{text}");
}

/// A sheet with no type column (the vendor says "all registers are floats" in prose), headed `Input
/// Register Address`: the header is read as an address column, the u16 reading is said as a warning
/// naming --type, and `--type f32` makes floats of it. Without --table the closing hint names
/// --table, not --columns.
#[test]
fn a_sheet_without_a_type_column_says_so_and_takes_type() {
    let (p, err) = import("floats-no-type.csv", &["--table", "input"]);
    assert!(err.contains("no type column") && err.contains("--type f32"), "{err}");
    let text = annotate(&p.path, &read(0x04, 0, &[0x4366, 0x1999]));
    assert!(text.contains("Voltage = 17254"), "{text}");
    let (p, err) = import("floats-no-type.csv", &["--table", "input", "--type", "f32"]);
    assert!(!err.contains("no type column"), "{err}");
    // Units as Home Assistant spells them: `Volts` → `V`, `kWH` → `kWh`.
    let toml = std::fs::read_to_string(&p.path).unwrap();
    assert!(toml.contains("unit = \"V\"") && toml.contains("unit = \"kWh\"") && !toml.contains("Volts"), "{toml}");
    let text = annotate(&p.path, &read(0x04, 0, &f32_words(230.1)));
    assert!(text.contains("Voltage = 230.1"), "{text}");
    let f = fixture("floats-no-type.csv");
    let out = run(&["profiles", "import", f.to_str().unwrap(), "-o", "/dev/null"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("give --table holding|input"), "{err}");
}

/// After `profiles import` into the profile directory ("usable by name at once"), `profiles check
/// NAME` finds the name as `show` and `export` do, and counts entries as import counts them (13,
/// not the 21 registers the floats cover). One resolver, one count.
#[test]
fn an_imported_profile_is_checked_by_name_with_import_s_count() {
    let name = format!("issue42-{}", std::process::id());
    let f = fixture("floats-no-type.csv");
    let out = run(&["profiles", "import", f.to_str().unwrap(), "--table", "input", "--type", "f32", "--name", &name]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("3 input registers"), "{err}");
    let check = run(&["profiles", "check", &name]);
    let said = String::from_utf8_lossy(&check.stdout);
    let _ = std::fs::remove_file(std::env::temp_dir().join(format!("{name}.toml")));
    assert!(check.status.success(), "{}", String::from_utf8_lossy(&check.stderr));
    assert!(said.contains("3 (6 registers) input registers"), "{said}");
}

#[test]
fn a_german_sheet_with_semicolons_hex_h_addresses_and_divisor_scales() {
    let (p, _) = import("inverter-german-hex-h.csv", &["--table", "holding"]);
    let text = annotate(&p.path, &read(0x03, 0, &[2305, 0xFF38]));
    assert!(text.contains("Netzspannung = 230.5 V"), "{text}");
    assert!(text.contains("Netzstrom = -2"), "{text}");
}

#[test]
fn a_sheet_with_title_rows_hex_addresses_and_word_swapped_floats() {
    let (p, err) = import("heatpump-title-rows.csv", &["--table", "holding"]);
    assert!(err.contains("header on row 4"), "{err}");
    let [hi, lo] = f32_words(45.5);
    let text = annotate(&p.path, &read(0x03, 0x100, &[lo, hi]));
    assert!(text.contains("Flow temperature = 45.5 °C"), "{text}");
}

#[test]
fn an_xlsx_with_merged_title_section_rows_and_chinese_headers() {
    let (p, err) = import("merged-chinese.xlsx", &[]);
    assert!(err.contains("header on row 4"), "{err}");
    assert!(err.contains("row 5, column A (address): no address (a section title or a note?)"), "{err}");
    let text = annotate(&p.path, &read(0x04, 0, &[5230]));
    assert!(text.contains("电池电压 = 52.30 V"), "{text}");
}

#[test]
fn six_digit_modicon_numbers_units_in_names_and_powers_of_ten() {
    let (p, _) = import("pump-modicon6.csv", &[]);
    let text = annotate(&p.path, &read(0x03, 0, &[125]));
    // `m3/h` in the header, `m³/h` as Home Assistant spells it.
    assert!(text.contains("Flow = 12.5 m³/h"), "{text}");
    let text = annotate(&p.path, &read(0x04, 0, &[0xFFF6]));
    assert!(text.contains("Motor temperature = -1.0 °C"), "{text}");
}

#[test]
fn a_function_code_column_low_word_first_and_strings() {
    let (p, _) = import("meter-function-column.csv", &[]);
    // 230 500 = 0x0003_8464, low word first.
    let text = annotate(&p.path, &read(0x04, 0, &[0x8464, 0x0003]));
    assert!(text.contains("Voltage = 230.5"), "{text}");
    let text = annotate(&p.path, &read(0x03, 100, &[0x4142, 0x4344, 0x3132, 0x3334, 0, 0, 0, 0]));
    assert!(text.contains("Serial number = \"ABCD1234\""), "{text}");
}

#[test]
fn a_tab_separated_sheet_with_plc_type_names() {
    let (p, _) = import("drive-tab.tsv", &["--table", "input"]);
    let text = annotate(&p.path, &read(0x04, 200, &[1450, 0xFF9C]));
    assert!(text.contains("Motor speed = 1450 rpm"), "{text}");
    assert!(text.contains("Motor current = -1.00 A"), "{text}");
}

#[test]
fn rows_that_cannot_be_read_are_named_with_row_column_and_why() {
    let (p, err) = import("bad-rows.csv", &[]);
    for expected in [
        "row 3, column C (type): \"float64\": 64-bit floats are not in the profile format",
        "row 4, column D (scale): \"ten\" is not a scale",
        "row 5, column A (address): \"banana\" is not an address",
        "row 6: input_registers 1 overlaps \"Voltage\" (row 2, address 0)",
        "row 7, column C (type): a string needs its length",
        "1 input registers, 0 coils, 0 discrete inputs; 5 skipped",
    ] {
        assert!(err.contains(expected), "missing {expected:?} in:\n{err}");
    }
    let text = annotate(&p.path, &read(0x04, 0, &f32_words(229.9)));
    assert!(text.contains("Voltage = 229.9"), "{text}");
}

#[test]
fn home_assistant_yaml_becomes_a_profile() {
    let (p, err) = import("ha-modbus.yaml", &[]);
    assert!(err.contains("device 1"), "{err}");
    let text = annotate(&p.path, &read(0x04, 0, &f32_words(231.25)));
    assert!(text.contains("Grid voltage = 231.2"), "{text}");
    // 12 345.67 kWh = 1 234 567 hundredths = 0x0012_D687, low word first.
    let text = annotate(&p.path, &read(0x04, 2, &[0xD687, 0x0012]));
    assert!(text.contains("Imported energy = 12345.67 kWh"), "{text}");
}

#[test]
fn a_sheet_that_says_nothing_usable_fails_and_says_why() {
    let dir = std::env::temp_dir().join(format!("mbtap-import-empty-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sheet = dir.join("notes.csv");
    std::fs::write(&sheet, "just,some,notes\n1,2,3\n").unwrap();
    let out = run(&["profiles", "import", sheet.to_str().unwrap(), "-o", dir.join("x.toml").to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no header row") && err.contains("--columns"), "{err}");
    assert!(!dir.join("x.toml").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn imported_profiles_are_listed_with_where_they_came_from() {
    let dir = std::env::temp_dir().join(format!("mbtap-import-list-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = fixture("pump-modicon6.csv");
    let out = Command::new(MBTAP)
        .args(["profiles", "import", f.to_str().unwrap(), "--name", "pump"])
        .env("MBTAP_PROFILE_DIR", &dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("pump.toml").exists());
    let list = Command::new(MBTAP).args(["profiles", "list"]).env("MBTAP_PROFILE_DIR", &dir).output().unwrap();
    let list = String::from_utf8_lossy(&list.stdout);
    assert!(list.contains("pump") && list.contains("imported from") && list.contains("pump-modicon6.csv"), "{list}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// What `profiles export` writes is accepted by the tools that read it — Home
/// Assistant's own `modbus` schema, `esphome config`, and Telegraf's plugin keys — for a
/// built-in profile and for one imported from Home Assistant YAML (a round trip). Needs the
/// homeassistant and esphome Python packages (CI installs them): run with `--ignored`.
#[test]
#[ignore = "needs homeassistant and esphome (CI installs them)"]
fn exports_are_accepted_by_home_assistant_esphome_and_telegraf() {
    let (imported, _) = import("ha-modbus.yaml", &[]);
    // An energy meter's sheet (kWh: `device_class: energy`, `total_increasing`).
    let (meter, _) = import("energy-meter-modicon.csv", &[]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/export_check.py");
    for profile in ["mk4", "mkzp", "display", imported.path.to_str().unwrap(), meter.path.to_str().unwrap()] {
        for (format, ext) in [("home-assistant", "yaml"), ("esphome", "yaml"), ("telegraf", "conf")] {
            let out = std::env::temp_dir().join(format!("mbtap-export-{}-{format}.{ext}", std::process::id()));
            let o =
                run(&["profiles", "export", profile, "--format", format, "--unit", "3", "-o", out.to_str().unwrap()]);
            assert!(o.status.success(), "{profile} {format}: {}", String::from_utf8_lossy(&o.stderr));
            let check = if format == "esphome" {
                // `esphome config` validates only; it builds nothing and fetches no toolchain.
                Command::new("esphome").args(["config", out.to_str().unwrap()]).output().unwrap()
            } else {
                Command::new("python3")
                    .args([script.to_str().unwrap(), format, out.to_str().unwrap()])
                    .output()
                    .unwrap()
            };
            assert!(
                check.status.success(),
                "{profile} {format} refused:\n{}\n{}",
                String::from_utf8_lossy(&check.stdout),
                String::from_utf8_lossy(&check.stderr)
            );
            std::fs::remove_file(&out).unwrap();
        }
    }
}

/// A profile of hostile strings: the device carries U+2028 and U+0085 each
/// followed by YAML keys (`shell_command`, `external_components`), a vertical tab, and register
/// names a YAML 1.1 resolver types (`yes`, `off`, `1:20`, `1_000`, `2001-12-14`, `<<`, `=`) or a
/// spreadsheet runs (`=HYPERLINK`). Field by field: device line, then one register per name.
const HOSTILE_PROFILE: &str = "[profile]\n\
name = \"hostile\"\n\
device = \"meter\\u2028shell_command:\\n  x: rm -rf /\\u0085external_components: evil\\u000Bend\"\n\
[[holding_registers]]\naddress = 0\nname = \"yes\"\nunit = \"on\"\n\
[[holding_registers]]\naddress = 1\nname = \"off\"\n\
[[holding_registers]]\naddress = 2\nname = \"1:20\"\n\
[[holding_registers]]\naddress = 3\nname = \"1_000\"\n\
[[holding_registers]]\naddress = 4\nname = \"2001-12-14\"\n\
[[holding_registers]]\naddress = 5\nname = \"<<\"\n\
[[holding_registers]]\naddress = 6\nname = \"=\"\n\
[[holding_registers]]\naddress = 7\nname = \"=HYPERLINK(\\\"http://x\\\")\"\n\
[[holding_registers]]\naddress = 8\nname = \"a\\u2029b: c\"\n";

/// The names of [`HOSTILE_PROFILE`]'s registers, as they must come back.
const HOSTILE_NAMES: [&str; 9] =
    ["yes", "off", "1:20", "1_000", "2001-12-14", "<<", "=", "=HYPERLINK(\"http://x\")", "a\u{2029}b: c"];

/// Every export of [`HOSTILE_PROFILE`] read back by PyYAML (YAML 1.1, as Home Assistant and ESPHome
/// read) and tomllib has only the keys mbtap writes and every name as written; the exports pass
/// Home Assistant's own schema and `esphome config`. The device's line separators cannot end the
/// header comment and inject top-level keys, nor the vertical tab make the file unreadable. Needs
/// PyYAML, homeassistant and esphome (CI installs them): run with `--ignored`.
#[test]
#[ignore = "needs PyYAML, homeassistant and esphome (CI installs them)"]
fn hostile_strings_stay_values_in_every_export() {
    let dir = std::env::temp_dir().join(format!("mbtap-export-hostile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let profile = dir.join("hostile.toml");
    std::fs::write(&profile, HOSTILE_PROFILE).unwrap();
    let readback = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/export_readback.py");
    let check = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/export_check.py");
    let names = serde_json::to_string(&HOSTILE_NAMES).unwrap();
    for (format, kind, top) in [
        ("home-assistant", "yaml", r#"["modbus"]"#),
        ("esphome", "yaml", r#"["esphome","esp32","uart","modbus","modbus_controller","sensor"]"#),
        ("telegraf", "toml", r#"["inputs"]"#),
    ] {
        let out = dir.join(format!("export-{format}"));
        let o =
            run(&["profiles", "export", profile.to_str().unwrap(), "--format", format, "-o", out.to_str().unwrap()]);
        assert!(o.status.success(), "{format}: {}", String::from_utf8_lossy(&o.stderr));
        let expected = format!(r#"{{"top": {top}, "names": {names}}}"#);
        let r = Command::new("python3")
            .args([readback.to_str().unwrap(), kind, out.to_str().unwrap(), &expected])
            .output()
            .unwrap();
        assert!(
            r.status.success(),
            "{format}:\n{}\n{}\n{}",
            String::from_utf8_lossy(&r.stdout),
            String::from_utf8_lossy(&r.stderr),
            std::fs::read_to_string(&out).unwrap()
        );
        let tool = match format {
            "home-assistant" => Some(
                Command::new("python3")
                    .args([check.to_str().unwrap(), format, out.to_str().unwrap()])
                    .output()
                    .unwrap(),
            ),
            // ESPHome's own loader and schema (validates only, builds nothing).
            "esphome" => Some(Command::new("esphome").args(["config", out.to_str().unwrap()]).output().unwrap()),
            _ => None,
        };
        if let Some(c) = tool {
            assert!(
                c.status.success(),
                "{format} refused: {}{}",
                String::from_utf8_lossy(&c.stdout),
                String::from_utf8_lossy(&c.stderr)
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `profiles import FILE --name NAME` into its own profile directory, with `extra` options.
fn import_into(dir: &Path, name: &str, extra: &[&str]) -> Output {
    let f = fixture("pump-modicon6.csv");
    let mut args = vec!["profiles", "import", f.to_str().unwrap(), "--name", name];
    args.extend_from_slice(extra);
    Command::new(MBTAP).args(&args).env("MBTAP_PROFILE_DIR", dir).output().unwrap()
}

/// An import never replaces a profile without `--force` (a hand-tuned profile of the same name
/// stays), and never writes through a link placed in the profile directory — with `--force` the
/// link itself is replaced.
#[test]
fn import_keeps_an_existing_profile_and_never_writes_through_a_link() {
    let dir = std::env::temp_dir().join(format!("mbtap-import-force-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mine = dir.join("pump.toml");
    std::fs::write(&mine, "# hand-tuned\n").unwrap();
    let o = import_into(&dir, "pump", &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("already exists") && err.contains("--force"), "{err}");
    assert_eq!(std::fs::read_to_string(&mine).unwrap(), "# hand-tuned\n");
    let o = import_into(&dir, "pump", &["--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read_to_string(&mine).unwrap().contains("[profile]"));

    let outside = dir.join("outside.txt");
    std::fs::write(&outside, "keep me\n").unwrap();
    let link = dir.join("linked.toml");
    std::os::unix::fs::symlink(&outside, &link).unwrap();
    assert!(!import_into(&dir, "linked", &[]).status.success());
    assert_eq!(std::fs::read_to_string(&outside).unwrap(), "keep me\n");
    assert!(import_into(&dir, "linked", &["--force"]).status.success());
    assert_eq!(std::fs::read_to_string(&outside).unwrap(), "keep me\n", "written through the link");
    assert!(!std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 3, "no temporary file left");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A name a built-in profile already has is written, and the user told that the built-in is what
/// the name finds.
#[test]
fn an_import_named_like_a_built_in_is_said_to_be_shadowed() {
    let dir = std::env::temp_dir().join(format!("mbtap-import-shadow-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let o = import_into(&dir, "mk4", &[]);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("also a built-in profile"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An OpenDocument workbook of one table whose `rows` (the XML of its `table:table-row`s) follow
/// a header row `Address | Name`, written to a temporary file.
fn ods(tag: &str, rows: &str) -> tempfile_path::TempProfile {
    use std::io::Write as _;
    let content = format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<office:document-content xmlns:office="urn:oasis:names:tc:opendocument:xmlns:office:1.0" xmlns:table="urn:oasis:names:tc:opendocument:xmlns:table:1.0" xmlns:text="urn:oasis:names:tc:opendocument:xmlns:text:1.0" office:version="1.2"><office:body><office:spreadsheet><table:table table:name="Sheet1"><table:table-row><table:table-cell office:value-type="string"><text:p>Address</text:p></table:table-cell><table:table-cell office:value-type="string"><text:p>Name</text:p></table:table-cell></table:table-row>{rows}</table:table></office:spreadsheet></office:body></office:document-content>"#
    );
    let mut file = tempfile_path::TempProfile::new(tag);
    file.path.set_extension("ods");
    let mut z = zip::ZipWriter::new(std::fs::File::create(&file.path).unwrap());
    let stored = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    z.start_file("mimetype", stored).unwrap();
    z.write_all(b"application/vnd.oasis.opendocument.spreadsheet").unwrap();
    z.start_file("META-INF/manifest.xml", stored).unwrap();
    z.write_all(br#"<?xml version="1.0" encoding="UTF-8"?><manifest:manifest xmlns:manifest="urn:oasis:names:tc:opendocument:xmlns:manifest:1.0" manifest:version="1.2"><manifest:file-entry manifest:full-path="/" manifest:media-type="application/vnd.oasis.opendocument.spreadsheet"/><manifest:file-entry manifest:full-path="content.xml" manifest:media-type="text/xml"/></manifest:manifest>"#).unwrap();
    z.start_file("content.xml", stored).unwrap();
    z.write_all(content.as_bytes()).unwrap();
    z.finish().unwrap();
    file
}

/// A row holding register `address` named `name`.
fn ods_row(address: u16, name: &str) -> String {
    format!(
        r#"<table:table-row><table:table-cell office:value-type="float" office:value="{address}"><text:p>{address}</text:p></table:table-cell><table:table-cell office:value-type="string"><text:p>{name}</text:p></table:table-cell></table:table-row>"#
    )
}

/// A workbook of a few hundred bytes whose repeated empty rows and cells stand for 17 billion cells
/// between two values (expanded, past 17 GB) is refused by counting them from its XML, before the
/// reader expands them — and a plain OpenDocument sheet still imports.
#[test]
fn an_ods_whose_repeats_expand_past_memory_is_refused_unexpanded() {
    let filler = r#"<table:table-row table:number-rows-repeated="1048000"><table:table-cell table:number-columns-repeated="16000"/></table:table-row>"#;
    let wide = r#"<table:table-row><table:table-cell table:number-columns-repeated="16000"/><table:table-cell office:value-type="string"><text:p>x</text:p></table:table-cell></table:table-row>"#;
    let bomb = ods("bomb", &format!("{}{filler}{wide}", ods_row(100, "volts")));
    let out_path = tempfile_path::TempProfile::new("bomb-out");
    let out = run(&["profiles", "import", bomb.path.to_str().unwrap(), "-o", out_path.path.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("expand to") && err.contains("1048003 rows × 16001 columns"), "{err}");
    assert!(!out_path.path.exists());

    let plain = ods("plain", &format!("{}{}", ods_row(100, "volts"), ods_row(101, "amps")));
    let out_path = tempfile_path::TempProfile::new("plain-out");
    let out = run(&[
        "profiles",
        "import",
        plain.path.to_str().unwrap(),
        "-o",
        out_path.path.to_str().unwrap(),
        "--table",
        "holding",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&out_path.path).unwrap();
    assert!(text.contains("volts") && text.contains("amps"), "{text}");
}

/// `profiles import FILE --table holding` into a temporary profile: exit code, what it said,
/// the profile written (empty if none).
fn import_holding(f: &tempfile_path::TempProfile) -> (Option<i32>, String, String) {
    let out_path = tempfile_path::TempProfile::new("import-out");
    let out = run(&[
        "profiles",
        "import",
        f.path.to_str().unwrap(),
        "-o",
        out_path.path.to_str().unwrap(),
        "--table",
        "holding",
    ]);
    let text = std::fs::read_to_string(&out_path.path).unwrap_or_default();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned(), text)
}

/// A BIFF8 record: type, size, data ([MS-XLS] 2.1.4).
fn biff(typ: u16, data: &[u8]) -> Vec<u8> {
    let mut v = typ.to_le_bytes().to_vec();
    v.extend(u16::try_from(data.len()).unwrap().to_le_bytes());
    v.extend(data);
    v
}

/// `BOF` of BIFF8 globals (`dt` 0x0005) or a worksheet (0x0010), the rest of its 16 bytes 0.
fn bof(dt: u16) -> Vec<u8> {
    let mut d = 0x0600u16.to_le_bytes().to_vec();
    d.extend(dt.to_le_bytes());
    d.resize(16, 0);
    biff(0x0809, &d)
}

/// `Label` at (row, col): row, column, format index 0, an 8-bit string (length, flags 0, bytes).
fn label(row: u16, col: u16, text: &str) -> Vec<u8> {
    let mut d = [row.to_le_bytes(), col.to_le_bytes(), [0, 0]].concat();
    d.extend(u16::try_from(text.len()).unwrap().to_le_bytes());
    d.push(0);
    d.extend(text.as_bytes());
    biff(0x0204, &d)
}

/// `Number` at (row, col): row, column, format index 0, the f64.
fn number(row: u16, col: u16, v: f64) -> Vec<u8> {
    let mut d = [row.to_le_bytes(), col.to_le_bytes(), [0, 0]].concat();
    d.extend(v.to_le_bytes());
    biff(0x0203, &d)
}

/// An XLS workbook (a compound file holding a `Workbook` stream) whose globals start with
/// `globals` and name one sheet "regs" holding `Address | Name`, `100 | volts`, then `cells`.
fn xls(tag: &str, globals: &[u8], cells: &[Vec<u8>]) -> tempfile_path::TempProfile {
    xls_at(tag, "/Workbook", globals, cells)
}

/// [`xls`] with its workbook stream at `stream` (a storage of its own is made for a nested one).
fn xls_at(tag: &str, stream_path: &str, globals: &[u8], cells: &[Vec<u8>]) -> tempfile_path::TempProfile {
    use std::io::Write as _;
    let stream = workbook_stream(globals, cells);
    let mut file = tempfile_path::TempProfile::new(tag);
    file.path.set_extension("xls");
    let mut cfb = cfb::create(&file.path).unwrap();
    if let Some((storage, _)) = stream_path.rsplit_once('/').filter(|(d, _)| !d.is_empty()) {
        cfb.create_storage_all(storage).unwrap();
    }
    cfb.create_stream(stream_path).unwrap().write_all(&stream).unwrap();
    cfb.flush().unwrap();
    file
}

/// The BIFF8 records of [`xls`]'s workbook stream.
fn workbook_stream(globals: &[u8], cells: &[Vec<u8>]) -> Vec<u8> {
    let eof = biff(0x000A, &[]);
    // BoundSheet8: the sheet's offset, visible, a worksheet, a 4-character 8-bit name.
    let bound = |pos: u32| biff(0x0085, &[&pos.to_le_bytes()[..], &[0, 0, 4, 0], b"regs"].concat());
    let head = [bof(0x0005), globals.to_vec()].concat();
    let pos = u32::try_from(head.len() + bound(0).len() + eof.len()).unwrap();
    let mut stream = [head, bound(pos), eof.clone(), bof(0x0010)].concat();
    for c in
        [label(0, 0, "Address"), label(0, 1, "Name"), number(1, 0, 100.0), label(1, 1, "volts")].iter().chain(cells)
    {
        stream.extend(c);
    }
    stream.extend(eof);
    stream
}

/// XLS workbooks of a few kilobytes that a dense reader cannot open — cells at A1 and IV65536 (16.7
/// M cells between them: 1.05 GB laid out), a `Dimensions` record whose last row comes before its
/// first (~2³² rows reserved, the process aborted), a `CodePage` too short to read (a panic) — are
/// read record by record, nothing laid out: the far cell is one cell (said skipped, no address),
/// `Dimensions` is not needed, and a record too short to read is said, with its offset.
#[test]
fn xls_workbooks_the_reader_blew_up_on_are_read_cell_by_cell() {
    let (code, err, text) = import_holding(&xls("plain", &[], &[]));
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("volts"), "{text}");

    let (code, err, text) = import_holding(&xls("far", &[], &[number(65_535, 255, 1.0)]));
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("volts") && err.contains("row 65536"), "{err}");

    // The same, its workbook stream inside a storage: found by name anywhere.
    let (code, err, _) = import_holding(&xls_at("nested", "/Deep/Workbook", &[], &[number(65_535, 255, 1.0)]));
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("row 65536"), "{err}");

    // Dimensions: first row 5, last row + 1 = 2, columns 0..2.
    let dims = biff(0x0200, &[&5u32.to_le_bytes()[..], &2u32.to_le_bytes(), &[0, 0, 2, 0, 0, 0]].concat());
    let (code, err, text) = import_holding(&xls("dims", &[], &[dims]));
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("volts"), "{text}");

    // A CodePage record of no bytes among the globals.
    let (code, err, _) = import_holding(&xls("codepage", &biff(0x0042, &[]), &[]));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("record 0x0042 at offset 20") && err.contains("save it again"), "{err}");

    // A sheet cut inside a record: said where.
    let mut cut = workbook_stream(&[], &[]);
    cut.truncate(cut.len() - 6);
    let (code, err, _) = import_holding(&xls_bytes("cut", &compound(&[("/Workbook", cut)])));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("ends inside a record at offset"), "{err}");
}

/// A compound file (512-byte sectors) holding `streams` in order, as bytes to patch.
fn compound(streams: &[(&str, Vec<u8>)]) -> Vec<u8> {
    use std::io::Write as _;
    let mut cfb = cfb::CompoundFile::create_with_version(cfb::Version::V3, std::io::Cursor::new(Vec::new())).unwrap();
    for (name, data) in streams {
        cfb.create_stream(name).unwrap().write_all(data).unwrap();
    }
    cfb.flush().unwrap();
    cfb.into_inner().into_inner()
}

/// Directory entry `i`'s offset in `file` (the directory's first sector; [MS-CFB] §2.2 header
/// field at 48, entries of 128 bytes).
fn entry_at(file: &[u8], i: usize) -> usize {
    let dir = u32::from_le_bytes(file[48..52].try_into().unwrap()) as usize;
    (dir + 1) * 512 + i * 128
}

/// Entry `i`'s name, sibling and child ids ([MS-CFB] §2.6.1: name 0–63, its length 64–65,
/// left 68, right 72, child 76).
fn set_entry(file: &mut [u8], i: usize, name: Option<&str>, links: [u32; 3]) {
    let at = entry_at(file, i);
    if let Some(name) = name {
        let units: Vec<u8> = name.encode_utf16().chain([0]).flat_map(u16::to_le_bytes).collect();
        file[at..at + 64].fill(0);
        file[at..at + units.len()].copy_from_slice(&units);
        file[at + 64..at + 66].copy_from_slice(&u16::try_from(units.len()).unwrap().to_le_bytes());
    }
    for (k, id) in links.into_iter().enumerate() {
        file[at + 68 + 4 * k..at + 72 + 4 * k].copy_from_slice(&id.to_le_bytes());
    }
}

fn xls_bytes(tag: &str, bytes: &[u8]) -> tempfile_path::TempProfile {
    let mut file = tempfile_path::TempProfile::new(tag);
    file.path.set_extension("xls");
    std::fs::write(&file.path, bytes).unwrap();
    file
}

/// The workbook reader takes the first directory entry named `Workbook` in the directory's order —
/// linked into the tree or not — so the container is checked as that reader reads it, not by a
/// library that walks the tree: an entry no storage links to, holding cells at A1 and IV65536, is
/// the one read (cell by cell: its far cell is said), and a chain that loops and a length past the
/// file are refused.
#[test]
fn an_xls_container_is_read_as_the_workbook_reader_reads_it() {
    const NOSTREAM: u32 = 0xFFFF_FFFF;
    let far = workbook_stream(&[], &[number(65_535, 255, 1.0)]);
    let plain = workbook_stream(&[], &[]);
    // Entries: 0 the root, 1 "Hidden" (far cells), 2 "Workbook" (plain).
    let mut bytes = compound(&[("/Hidden", far), ("/Workbook", plain.clone())]);
    let (code, err, _) = import_holding(&xls_bytes("linked", &bytes));
    assert_eq!(code, Some(0), "the plain workbook, found by name: {err}");
    // The root links only entry 2; entry 1, renamed `Workbook`, is linked by nothing — and
    // comes first in the directory, where the reader's search finds it.
    set_entry(&mut bytes, 0, None, [NOSTREAM, NOSTREAM, 2]);
    set_entry(&mut bytes, 2, None, [NOSTREAM, NOSTREAM, NOSTREAM]);
    set_entry(&mut bytes, 1, Some("Workbook"), [NOSTREAM, NOSTREAM, NOSTREAM]);
    let (code, err, _) = import_holding(&xls_bytes("orphan", &bytes));
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("row 65536"), "the entry first in the directory is read: {err}");

    // A workbook stream of regular sectors (≥ 4 096 bytes) whose last sector leads back to its
    // first: the FAT (its first sector is the header's first DIFAT entry, at 76).
    let rows: Vec<Vec<u8>> = (2..400).map(|r| number(r, 0, f64::from(r))).collect();
    let mut bytes = compound(&[("/Workbook", workbook_stream(&[], &rows))]);
    let fat = (u32::from_le_bytes(bytes[76..80].try_into().unwrap()) as usize + 1) * 512;
    let start = u32::from_le_bytes(bytes[entry_at(&bytes, 1) + 116..entry_at(&bytes, 1) + 120].try_into().unwrap());
    let (mut id, mut last) = (start, start);
    while id != 0xFFFF_FFFE {
        last = id;
        id = u32::from_le_bytes(bytes[fat + 4 * id as usize..fat + 4 * id as usize + 4].try_into().unwrap());
    }
    bytes[fat + 4 * last as usize..fat + 4 * last as usize + 4].copy_from_slice(&start.to_le_bytes());
    let (code, err, _) = import_holding(&xls_bytes("loop", &bytes));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("workbook chain loops"), "{err}");

    // A length of 2 GiB on a file of a few kilobytes: the reader reserves it.
    let mut bytes = compound(&[("/Workbook", plain)]);
    let at = entry_at(&bytes, 1) + 120;
    bytes[at..at + 4].copy_from_slice(&(1u32 << 31).to_le_bytes());
    let (code, err, _) = import_holding(&xls_bytes("length", &bytes));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("2147483648 bytes, more than the file"), "{err}");
}

/// `LabelSst` at (row, col): row, column, format 0, the shared string's index.
fn label_sst(row: u16, col: u16, i: u32) -> Vec<u8> {
    biff(0x00FD, &[&row.to_le_bytes()[..], &col.to_le_bytes(), &[0, 0], &i.to_le_bytes()].concat())
}

/// `RK` at (row, col): row, column, format 0, the `RkNumber`.
fn rk(row: u16, col: u16, rk: u32) -> Vec<u8> {
    biff(0x027E, &[&row.to_le_bytes()[..], &col.to_le_bytes(), &[0, 0], &rk.to_le_bytes()].concat())
}

/// `Formula` at (row, col) with the cached `value` (8 bytes), flags and cache 0, and the
/// formula `=5` (`cce` 3: `PtgInt` 5).
fn formula(row: u16, col: u16, value: [u8; 8]) -> Vec<u8> {
    let fixed = [&row.to_le_bytes()[..], &col.to_le_bytes(), &[0, 0], &value, &[0, 0], &[0, 0, 0, 0]].concat();
    biff(0x0006, &[fixed, vec![3, 0, 0x1E, 5, 0]].concat())
}

/// A `FormulaValue` that is not a number: type, the byte that says which, 0xFFFF at the end.
fn special(kind: u8, v: u8) -> [u8; 8] {
    [kind, 0, v, 0, 0, 0, 0xFF, 0xFF]
}

/// An 8-bit shared string: length, flags 0, the bytes.
fn sst_8bit(s: &str) -> Vec<u8> {
    [&u16::try_from(s.len()).unwrap().to_le_bytes()[..], &[0], s.as_bytes()].concat()
}

fn utf16(s: &str) -> Vec<u8> {
    s.encode_utf16().flat_map(u16::to_le_bytes).collect()
}

/// Globals holding a code page (1200) and a shared-string table carried on in three `Continue`
/// records: 8-bit and UTF-16 strings, a rich one (2 runs), one with phonetic data (6 bytes), an
/// empty one, one split inside its characters (8-bit, then UTF-16 after the `Continue`'s own
/// flags byte), one starting a `Continue`, one whose runs are split, then one more.
fn xls_shared_strings() -> Vec<u8> {
    let wide = [&7u16.to_le_bytes()[..], &[1], &utf16("Ström Ω")].concat();
    let rich = [&4u16.to_le_bytes()[..], &[0x08], &2u16.to_le_bytes(), b"rich", &[1; 8]].concat();
    let ext = [&3u16.to_le_bytes()[..], &[0x04], &6u32.to_le_bytes(), b"ext", &[9; 6]].concat();
    let split = [&15u16.to_le_bytes()[..], &[0], b"abcdefghij"].concat();
    let sst = [
        &10u32.to_le_bytes()[..],
        &10u32.to_le_bytes(),
        &sst_8bit("Address"),
        &sst_8bit("volts"),
        &wide,
        &rich,
        &ext,
        &[0, 0, 0],
        &split,
    ]
    .concat();
    let cont1 = [&[1u8][..], &utf16("Ωmega")].concat();
    let runs_cut = [&3u16.to_le_bytes()[..], &[0x08], &1u16.to_le_bytes(), b"abc", &[2, 2]].concat();
    let cont2 = [sst_8bit("after"), runs_cut].concat();
    let cont3 = [&[2u8, 2][..], &sst_8bit("last")].concat();
    [
        biff(0x0042, &1200u16.to_le_bytes()),
        biff(0x00FC, &sst),
        biff(0x003C, &cont1),
        biff(0x003C, &cont2),
        biff(0x003C, &cont3),
    ]
    .concat()
}

/// Cells of every kind the workbook reader reads, then rows of numbers to put the stream in
/// regular sectors (≥ 4 096 bytes).
fn xls_cells_of_every_kind() -> Vec<Vec<u8>> {
    let rk_int = |v: i32| u32::from_le_bytes((v << 2).to_le_bytes()) | 2;
    let rk_f64 = |v: f64| u32::try_from(v.to_bits() >> 32).unwrap() & !3;
    let mut mul = [&5u16.to_le_bytes()[..], &1u16.to_le_bytes()].concat();
    for v in [rk_int(7), rk_f64(0.5), rk_int(250) | 1] {
        mul.extend([0, 0]);
        mul.extend(v.to_le_bytes());
    }
    mul.extend(3u16.to_le_bytes());
    let wide_label =
        [&7u16.to_le_bytes()[..], &2u16.to_le_bytes(), &[0, 0], &6u16.to_le_bytes(), &[1], &utf16("Wide ☃")].concat();
    let string = [&12u16.to_le_bytes()[..], &[0], b"formula text"].concat();
    let mut cells = vec![
        label_sst(2, 0, 2),
        label_sst(2, 1, 3),
        label_sst(2, 2, 5),
        label_sst(2, 3, 6),
        label_sst(3, 0, 4),
        label_sst(3, 1, 7),
        label_sst(3, 2, 8),
        label_sst(3, 3, 9),
        label_sst(3, 4, 99),
        rk(4, 0, rk_int(40_001)),
        rk(4, 1, rk_int(123) | 1),
        rk(4, 2, rk_int(500) | 1),
        rk(4, 3, rk_f64(2.5)),
        rk(4, 4, rk_f64(1234.5) | 1),
        rk(4, 5, rk_int(-3)),
        biff(0x00BD, &mul),
        formula(6, 0, 3.25f64.to_le_bytes()),
        formula(6, 1, special(1, 1)),
        formula(6, 2, special(2, 0x07)),
        formula(6, 3, special(0, 0)),
        biff(0x0207, &string),
        formula(6, 4, special(3, 0)),
        biff(0x0205, &[&7u16.to_le_bytes()[..], &0u16.to_le_bytes(), &[0, 0, 0, 0]].concat()),
        biff(0x0205, &[&7u16.to_le_bytes()[..], &1u16.to_le_bytes(), &[0, 0, 0x2A, 1]].concat()),
        biff(0x0204, &wide_label),
        number(8, 0, -0.5),
        number(8, 1, 1e20),
        number(8, 5, 42.0),
    ];
    cells.extend((9..400).map(|r| number(r, 0, f64::from(r))));
    cells
}

/// calamine's rows of `sheet`, each cell as the import turns a calamine cell into text, padded
/// to the sheet's own row and column numbers, trailing empty cells left off.
fn calamine_rows(path: &std::path::Path, sheet: &str) -> Vec<(usize, Vec<String>)> {
    use calamine::Reader as _;
    let mut wb = calamine::open_workbook_auto(path).unwrap();
    let range = wb.worksheet_range(sheet).unwrap();
    let (row0, col0) = range.start().map(|(r, c)| (r as usize, c as usize)).unwrap();
    let text = |d: &calamine::Data| match d {
        calamine::Data::Float(f) => mbtap_device::profile::import::grid::number_text(*f),
        calamine::Data::Error(e) => format!("#{e:?}"),
        calamine::Data::Empty => String::new(),
        other => other.to_string(),
    };
    let mut theirs: Vec<(usize, Vec<String>)> = Vec::new();
    for (i, r) in range.rows().enumerate() {
        let mut cells: Vec<String> = std::iter::repeat_n(String::new(), col0).chain(r.iter().map(text)).collect();
        while cells.last().is_some_and(String::is_empty) {
            cells.pop();
        }
        theirs.push((row0 + i, cells));
    }
    theirs
}

/// Calamine lays every sheet of an XLS out densely when it opens the file (38.7 MB for
/// a 4.4 MB sheet; 1 GB for cells at A1 and IV65536); the import now reads the sheet's records
/// itself. What it reads must be what calamine reads: every row at the same number with the same
/// cells, for cells of every kind and shared strings carried on across `Continue` records — and
/// the stream read in pieces from the file as from memory.
#[test]
fn an_xls_sheet_read_by_its_records_reads_as_the_workbook_reader_reads_it() {
    use mbtap_device::profile::import::{xls_container, xls_rows};
    use std::ops::ControlFlow;
    // Version 3 (512-byte sectors): calamine opens a version 4 file only with a mini stream.
    let stream = workbook_stream(&xls_shared_strings(), &xls_cells_of_every_kind());
    let file = xls_bytes("kinds", &compound(&[("/Workbook", stream)]));
    let theirs = calamine_rows(&file.path, "regs");
    // Ours: the stream found in the file, read in its pieces and gathered.
    let bytes = std::fs::read(&file.path).unwrap();
    let xls_container::WorkbookStream::InFile(pieces) = xls_container::parse_xls_stream(&bytes).unwrap() else {
        panic!("the stream is in regular sectors");
    };
    let gathered = xls_container::parse_xls_container(&bytes).unwrap();
    let read = |stream: &mut dyn FnMut() -> Box<dyn ReadSeek>| {
        let book = xls_rows::parse_xls_book(stream()).unwrap();
        let mut ours: Vec<(usize, Vec<String>)> = Vec::new();
        let got = xls_rows::parse_xls_rows(stream(), &book, 0, &mut |i, cells| {
            ours.push((i, cells.iter().map(|c| (*c).to_owned()).collect()));
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(got.cut_cells, 0);
        (book.sheets, ours)
    };
    let (sheets, in_pieces) =
        read(&mut || Box::new(xls_container::StreamReader::new(std::io::Cursor::new(bytes.clone()), &pieces)));
    let (_, held) = read(&mut || Box::new(std::io::Cursor::new(gathered.clone())));
    assert_eq!(in_pieces, held);
    assert_eq!(sheets.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(), ["regs"]);
    assert_eq!(in_pieces, theirs);
    let row = |i: usize| in_pieces[i].1.join("|");
    assert_eq!(row(2), "Ström Ω|rich||abcdefghijΩmega");
    assert_eq!(row(3), "ext|after|abc|last");
    assert_eq!(row(4), "40001|1.23|5|2.5|12.345|-3");
    assert_eq!(row(5), "|7|0.5|2.5");
    assert_eq!(row(6), "3.25|true|#Div0|formula text");
    assert_eq!(row(7), "false|#NA|Wide ☃");
    assert_eq!(row(8), "-0.5|100000000000000000000||||42");
    // And the import reads its header and rows from there.
    let (code, err, text) = import_holding(&file);
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("volts"), "{text}");
}

/// What the XLS reader reads from, boxed.
trait ReadSeek: std::io::Read + std::io::Seek {}
impl<T: std::io::Read + std::io::Seek> ReadSeek for T {}

/// An XLSB record ([MS-XLSB] 2.1.4): its type and size each in 7-bit groups, low first, the
/// top bit saying another byte follows; then the data.
fn xlsb_record(typ: u16, data: &[u8]) -> Vec<u8> {
    let low = u8::try_from(typ & 0x7F).unwrap();
    let mut v = if typ < 0x80 { vec![low] } else { vec![low | 0x80, u8::try_from(typ >> 7).unwrap()] };
    let mut n = data.len();
    loop {
        let b = u8::try_from(n & 0x7F).unwrap();
        n >>= 7;
        v.push(if n > 0 { b | 0x80 } else { b });
        if n == 0 {
            break;
        }
    }
    v.extend(data);
    v
}

/// An XLSB workbook of one sheet "regs": `Address | Name`, `100 | volts`, and one number at
/// `far` (row, column) if given.
fn xlsb(tag: &str, far: Option<(u32, u32)>) -> tempfile_path::TempProfile {
    use std::io::Write as _;
    // A string as XLSB writes it: its length in characters (u32), UTF-16LE.
    let wide = |s: &str| {
        let mut v = u32::try_from(s.len()).unwrap().to_le_bytes().to_vec();
        v.extend(s.encode_utf16().flat_map(u16::to_le_bytes));
        v
    };
    // BrtRowHdr: the row, then 13 bytes of its formatting.
    let row = |r: u32| xlsb_record(0x0000, &[&r.to_le_bytes()[..], &[0; 13]].concat());
    // BrtCellReal: column, style, the f64; BrtCellSt: column, style, the string.
    let real = |c: u32, v: f64| xlsb_record(0x0005, &[&c.to_le_bytes()[..], &[0; 4], &v.to_le_bytes()].concat());
    let text = |c: u32, s: &str| xlsb_record(0x0006, &[&c.to_le_bytes()[..], &[0; 4], &wide(s)].concat());
    // BrtBundleSh (visible, tab 1, relationship rId1, name), BrtEndBundleShs, BrtCalcProp.
    let book = [
        xlsb_record(0x009C, &[&0u32.to_le_bytes()[..], &1u32.to_le_bytes(), &wide("rId1"), &wide("regs")].concat()),
        xlsb_record(0x0090, &[]),
        xlsb_record(0x009D, &[]),
    ]
    .concat();
    let (last_row, last_col) = far.unwrap_or((1, 1));
    // BrtBeginSheet, BrtWsDim (first and last row and column), BrtBeginSheetData, the rows,
    // BrtEndSheetData.
    let mut sheet = [
        xlsb_record(0x0081, &[]),
        xlsb_record(0x0094, &[0u32, last_row, 0, last_col].map(u32::to_le_bytes).concat()),
        xlsb_record(0x0091, &[]),
        row(0),
        text(0, "Address"),
        text(1, "Name"),
        row(1),
        real(0, 100.0),
        text(1, "volts"),
    ]
    .concat();
    if let Some((r, c)) = far {
        sheet.extend([row(r), real(c, 1.0)].concat());
    }
    sheet.extend(xlsb_record(0x0092, &[]));
    let rels = r#"<?xml version="1.0"?><Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships"><Relationship Id="rId1" Type="http://schemas.openxmlformats.org/officeDocument/2006/relationships/worksheet" Target="worksheets/sheet1.bin"/></Relationships>"#;
    let mut file = tempfile_path::TempProfile::new(tag);
    file.path.set_extension("xlsb");
    let mut z = zip::ZipWriter::new(std::fs::File::create(&file.path).unwrap());
    let stored = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, data) in [
        ("xl/workbook.bin", &book[..]),
        ("xl/_rels/workbook.bin.rels", rels.as_bytes()),
        ("xl/worksheets/sheet1.bin", &sheet),
    ] {
        z.start_file(name, stored).unwrap();
        z.write_all(data).unwrap();
    }
    z.finish().unwrap();
    file
}

/// An 878-byte XLSB with one cell at XFD1048576 costs one cell (laid out, the 17 billion cells
/// between A1 and it abort the process): XLSB sheets are read cell by cell as XLSX ones are — the
/// far row refused, a far column's cell counted, a plain sheet imported.
#[test]
fn an_xlsb_cell_far_away_costs_one_cell() {
    let (code, err, text) = import_holding(&xlsb("plain", None));
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("volts"), "{text}");
    let (code, err, _) = import_holding(&xlsb("far", Some((1_048_575, 16_383))));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("a cell at row 1048576"), "{err}");
    let (code, err, text) = import_holding(&xlsb("wide", Some((5, 16_383))));
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("1 cell(s) past column IV") && text.contains("volts"), "{err}");
}

/// A sheet out of address order, with an overlap, a blank row and a row that cannot be read:
/// four tables' worth of shapes (header row first, then the rows by line).
const SHUFFLED_SHEET: &str = "address,name,table,type,length\n\
    10,Alpha,holding,u32,\n\
    11,Beta,holding,u16,\n\
    5,Pump,coils,,\n\
    0,Serial,input,string,3\n\
    \n\
    0,Zero,holding,u16,\n\
    x,Broken,holding,u16,\n\
    12,Gamma,holding,f32,\n";

/// The import writes each point as it is read and keeps no points or profile text in
/// memory (80 MB for a 4 MB sheet of tiny rows, 20×). What it writes must be what the collected
/// import writes — the same profile, entries in address order — and an overlap must still name
/// the point it overlaps (read back from the import's scratch file), with nothing left beside
/// the profile.
#[test]
fn a_streamed_import_writes_what_the_collected_one_does() {
    use mbtap_device::profile::import::grid::Grid;
    use mbtap_device::profile::import::sheet::{SheetOptions, parse_sheet};
    let dir = std::env::temp_dir().join(format!("mbtap-import-stream-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let sheet = dir.join("shuffled.csv");
    std::fs::write(&sheet, SHUFFLED_SHEET).unwrap();
    let out = dir.join("out.toml");
    let o = run(&["profiles", "import", sheet.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("row 3: holding_registers 11 overlaps \"Alpha\" (row 2, address 10)"), "{err}");
    assert!(err.contains("row 8, column A (address)"), "{err}");
    assert!(err.contains("2 holding registers") || err.contains("3 holding registers"), "{err}");

    let mut collected =
        parse_sheet(&Grid::from_rows(SHUFFLED_SHEET.lines().map(|l| l.split(','))), &SheetOptions::default());
    let source = sheet.display().to_string();
    collected.notes = collected.notes.iter().map(|n| format!("{source}: {n}")).collect();
    let expected = collected.to_toml("shuffled", "shuffled", &source);
    let written = std::fs::read_to_string(&out).unwrap();
    assert_eq!(written, expected);
    let order: Vec<&str> = written.lines().filter(|l| l.starts_with("name = ")).skip(1).collect();
    assert_eq!(
        order,
        ["name = \"Pump\"", "name = \"Zero\"", "name = \"Alpha\"", "name = \"Gamma\"", "name = \"Serial\""]
    );
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 2, "only the sheet and the profile: {left:?}");

    // Rows as a spreadsheet shows them: a blank line is a row, a quoted cell over two lines is
    // one, and a last row without a line end is counted like the others (the CSV reader skips
    // blank lines: rows after one were named a row early).
    std::fs::write(&sheet, "address,name,description\n1,A,\"two\nlines\"\n\nx,B,c\n\ny,C,d").unwrap();
    let o = run(&[
        "profiles",
        "import",
        sheet.to_str().unwrap(),
        "--table",
        "holding",
        "-o",
        out.to_str().unwrap(),
        "--force",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("row 5, column A (address): \"x\""), "{err}");
    assert!(err.contains("row 7, column A (address): \"y\""), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Rows of every shape a spreadsheet program writes: repeated rows and cells, leading empty
/// rows and columns, paragraphs, spaces, spans, an annotation, numbers, a percentage, a
/// boolean, a date, a covered cell, and a million empty rows at the end.
const ODS_SHAPES: &str = r#"<table:table-row table:number-rows-repeated="2"><table:table-cell/></table:table-row><table:table-row><table:table-cell table:number-columns-repeated="2"/><table:table-cell office:value-type="float" office:value="1.5"><text:p>1.5</text:p></table:table-cell><table:table-cell office:value-type="string"><text:p>two<text:s text:c="3"/>spaces</text:p><text:p>and <text:span>a span</text:span> &amp; more</text:p><office:annotation><text:p>not this</text:p></office:annotation></table:table-cell><table:table-cell office:value-type="boolean" office:boolean-value="true"><text:p>TRUE</text:p></table:table-cell><table:table-cell office:value-type="percentage" office:value="0.25"><text:p>25%</text:p></table:table-cell><table:table-cell office:value-type="date" office:date-value="2026-12-04"><text:p>04.12.26</text:p></table:table-cell><table:covered-table-cell office:value-type="string" office:string-value="covered"/><table:table-cell office:value-type="float" office:value="40001" table:number-columns-repeated="3"/></table:table-row><table:table-row table:number-rows-repeated="2"><table:table-cell office:value-type="float" office:value="7"><text:p>7</text:p></table:table-cell></table:table-row><table:table-row table:number-rows-repeated="5"><table:table-cell table:number-columns-repeated="4"/></table:table-row><table:table-row><table:table-cell/><table:table-cell><text:p>untyped: empty</text:p></table:table-cell><table:table-cell office:value-type="string"><text:p/></table:table-cell><table:table-cell office:value-type="float" office:value="-3"/></table:table-row><table:table-row table:number-rows-repeated="1000000"><table:table-cell table:number-columns-repeated="1024"/></table:table-row>"#;

/// The workbook reader expands every table of an ODS into memory when it opens it
/// (52.9 MB for a 655 kB sheet); the import now streams the sheet's rows itself. What it reads
/// must be what the workbook reader reads: every row at the same number with the same cells.
#[test]
fn an_ods_sheet_streamed_reads_as_the_workbook_reader_reads_it() {
    use std::io::Read as _;
    use std::ops::ControlFlow;
    let file = ods("shapes", ODS_SHAPES);
    // The workbook reader's rows, the empty ones left out (our reader does not hand them on).
    let mut theirs = calamine_rows(&file.path, "Sheet1");
    theirs.retain(|(_, cells)| !cells.is_empty());
    // Ours, from content.xml.
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&file.path).unwrap()).unwrap();
    let mut xml = Vec::new();
    zip.by_name("content.xml").unwrap().read_to_end(&mut xml).unwrap();
    let mut ours: Vec<(usize, Vec<String>)> = Vec::new();
    let read = mbtap_device::profile::import::ods_rows::parse_ods_rows(&xml[..], None, &mut |i, cells| {
        if !cells.is_empty() {
            ours.push((i, cells.iter().map(|c| (*c).to_owned()).collect()));
        }
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(read.cut_cells, 0);
    assert_eq!(ours, theirs);
    assert_eq!(ours.len(), 5, "{ours:?}");
    assert!(ours[1].1.contains(&"two   spaces\nand a span & more".to_owned()), "{ours:?}");
    // And the import takes its header and rows from there.
    let (code, err, text) = import_holding(&file);
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("volts") || text.contains("[[holding_registers]]"), "{text}");
}

/// A sheet saved by Excel as "CSV" on a Western system (Windows-1252) and as "Unicode text"
/// (UTF-16 with its mark) imports with its accents and degree signs right, and says how it was
/// read.
#[test]
fn a_csv_in_windows_1252_or_utf16_is_read_right_and_said() {
    let dir = std::env::temp_dir().join(format!("mbtap-csv-encodings-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = "Address;Name;Type;Unit\n0;Température;uint16;°C\n";
    // é is E9 and ° B0 in Windows-1252.
    let latin = dir.join("latin.csv");
    std::fs::write(&latin, b"Address;Name;Type;Unit\n0;Temp\xe9rature;uint16;\xb0C\n").unwrap();
    let utf16 = dir.join("utf16.csv");
    let mut bytes = vec![0xFF, 0xFE];
    bytes.extend(text.encode_utf16().flat_map(u16::to_le_bytes));
    std::fs::write(&utf16, bytes).unwrap();
    for (file, said) in [(&latin, "Windows-1252"), (&utf16, "UTF-16")] {
        let out = dir.join("out.toml");
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .args(["profiles", "import", file.to_str().unwrap(), "--table", "holding", "--name", "enc"])
            .args(["-o", out.to_str().unwrap(), "--force"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success() && err.contains(said), "{}: {err}", file.display());
        let profile = std::fs::read_to_string(&out).unwrap();
        assert!(profile.contains("name = \"Température\"") && profile.contains("unit = \"°C\""), "{profile}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A minimal XLSX (ECMA-376 SpreadsheetML): one sheet whose rows are `rows`, each cell either a
/// number or the index of a shared string (`t="s"`), and the shared strings.
fn xlsx_with_shared_strings(path: &std::path::Path, strings: &[String], rows: &[Vec<(bool, String)>]) {
    use std::fmt::Write as _;
    use std::io::Write as _;
    let mut z = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let o: zip::write::SimpleFileOptions = zip::write::SimpleFileOptions::default();
    let mut put = |name: &str, text: &str| {
        z.start_file(name, o).unwrap();
        z.write_all(text.as_bytes()).unwrap();
    };
    put(
        "[Content_Types].xml",
        r#"<?xml version="1.0" encoding="UTF-8"?><Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types"><Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/><Default Extension="xml" ContentType="application/xml"/><Override PartName="/xl/workbook.xml" ContentType="application/vnd.openxmlformats-officedocument.spreadsheetml.sheet.main+xml"/><Override PartName="/xl/worksheets/sheet1.xml" ContentType="application/vnd.openxmlformats-officedocument.spreadsheetml.worksheet+xml"/><Override PartName="/xl/sharedStrings.xml" ContentType="application/vnd.openxmlformats-officedocument.spreadsheetml.sharedStrings+xml"/></Types>"#,
    );
    put(
        "_rels/.rels",
        r#"<?xml version="1.0" encoding="UTF-8"?><Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships"><Relationship Id="rId1" Type="http://schemas.openxmlformats.org/officeDocument/2006/relationships/officeDocument" Target="xl/workbook.xml"/></Relationships>"#,
    );
    put(
        "xl/workbook.xml",
        r#"<?xml version="1.0" encoding="UTF-8"?><workbook xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main" xmlns:r="http://schemas.openxmlformats.org/officeDocument/2006/relationships"><sheets><sheet name="Map" sheetId="1" r:id="rId1"/></sheets></workbook>"#,
    );
    put(
        "xl/_rels/workbook.xml.rels",
        r#"<?xml version="1.0" encoding="UTF-8"?><Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships"><Relationship Id="rId1" Type="http://schemas.openxmlformats.org/officeDocument/2006/relationships/worksheet" Target="worksheets/sheet1.xml"/><Relationship Id="rId2" Type="http://schemas.openxmlformats.org/officeDocument/2006/relationships/sharedStrings" Target="sharedStrings.xml"/></Relationships>"#,
    );
    let mut sst = format!(
        r#"<?xml version="1.0" encoding="UTF-8"?><sst xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main" count="{0}" uniqueCount="{0}">"#,
        strings.len()
    );
    for s in strings {
        let _ = write!(sst, "<si><t>{s}</t></si>");
    }
    sst.push_str("</sst>");
    put("xl/sharedStrings.xml", &sst);
    let mut sheet = String::from(
        r#"<?xml version="1.0" encoding="UTF-8"?><worksheet xmlns="http://schemas.openxmlformats.org/spreadsheetml/2006/main"><sheetData>"#,
    );
    for (r, row) in rows.iter().enumerate() {
        let _ = write!(sheet, "<row r=\"{}\">", r + 1);
        for (c, (shared, v)) in row.iter().enumerate() {
            let col = char::from(b'A' + u8::try_from(c).unwrap());
            let t = if *shared { " t=\"s\"" } else { "" };
            let _ = write!(sheet, "<c r=\"{col}{}\"{t}><v>{v}</v></c>", r + 1);
        }
        sheet.push_str("</row>");
    }
    sheet.push_str("</sheetData></worksheet>");
    put("xl/worksheets/sheet1.xml", &sheet);
    z.finish().unwrap();
}

/// Three shared strings of 65 535 characters cited by 2 000 rows: a 35 kB XLSX that would make
/// a 787 MB profile. Refused at the row where the text passes the budget, naming it; nothing
/// written. The same sheet with short names imports.
#[test]
fn shared_strings_cited_many_times_are_counted_at_each_citation() {
    let dir = std::env::temp_dir().join(format!("mbtap-shared-strings-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let header = |names: usize| -> Vec<(bool, String)> {
        vec![(true, names.to_string()), (true, (names + 1).to_string()), (true, (names + 2).to_string())]
    };
    let run = |strings: Vec<String>, file: &str| {
        let n = strings.len();
        let mut all = strings;
        all.extend(["Address".to_owned(), "Name".to_owned(), "Description".to_owned()]);
        let mut rows = vec![header(n)];
        for a in 0..2000 {
            rows.push(vec![(false, a.to_string()), (true, (a % n).to_string()), (true, ((a + 1) % n).to_string())]);
        }
        let path = dir.join(file);
        xlsx_with_shared_strings(&path, &all, &rows);
        let out = dir.join(format!("{file}.toml"));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .args(["profiles", "import", path.to_str().unwrap(), "--table", "holding", "--name", "ss"])
            .args(["-o", out.to_str().unwrap()])
            .output()
            .unwrap();
        (o, out, std::fs::metadata(&path).unwrap().len())
    };
    let long: Vec<String> = (b'a'..=b'c').map(|c| String::from(char::from(c)).repeat(65_535)).collect();
    let (o, out, size) = run(long, "long.xlsx");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(size < 100_000, "the file is small: {size} bytes");
    assert!(!o.status.success() && err.contains("nothing imported") && err.contains("16777216"), "{err}");
    assert!(err.contains("row "), "the row where it ran over is named: {err}");
    assert!(!out.exists(), "no profile written");
    assert!(err.lines().all(|l| l.chars().count() < 1_000), "no line quotes the long text whole");
    let short: Vec<String> = ["Voltage", "Current", "Power"].map(String::from).to_vec();
    let (o, out, _) = run(short, "short.xlsx");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read_to_string(&out).unwrap().contains("address = 1999"));
    std::fs::remove_dir_all(&dir).ok();
}

/// A copy of the zip at `from` to `to`, every part as it is but `part`, whose bytes `write`
/// writes as it likes.
fn rewrite_part(
    from: &std::path::Path,
    to: &std::path::Path,
    part: &str,
    write: impl FnOnce(Vec<u8>, &mut zip::ZipWriter<std::fs::File>),
) {
    use std::io::Write as _;
    let mut zin = zip::ZipArchive::new(std::fs::File::open(from).unwrap()).unwrap();
    let mut z = zip::ZipWriter::new(std::fs::File::create(to).unwrap());
    let o: zip::write::SimpleFileOptions = zip::write::SimpleFileOptions::default();
    let mut write = Some(write);
    for i in 0..zin.len() {
        let mut entry = zin.by_index(i).unwrap();
        let name = entry.name().to_owned();
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut entry, &mut bytes).unwrap();
        z.start_file(name.as_str(), o).unwrap();
        match write.take_if(|_| name == part) {
            Some(w) => w(bytes, &mut z),
            None => z.write_all(&bytes).unwrap(),
        }
    }
    z.finish().unwrap();
}

/// An XLSX whose local and central headers both say 1 000 bytes for a `sharedStrings.xml` that
/// inflates past the 128 MiB read: the sizes are claims; what inflates is counted, and the
/// inflater stops at the budget. Refused naming the part.
#[test]
fn a_zip_part_that_lies_about_its_size_is_refused_by_what_it_inflates_to() {
    use std::io::Write as _;
    let dir = std::env::temp_dir().join(format!("mbtap-zip-lies-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("lies.xlsx");
    let strings = vec!["Address".to_owned(), "Name".to_owned()];
    xlsx_with_shared_strings(&path, &strings, &[vec![(true, "0".into()), (true, "1".into())]]);
    // Rewritten with a 129 MiB sharedStrings.xml (compressible: the file stays small).
    let lying = dir.join("lying.xlsx");
    rewrite_part(&path, &lying, "xl/sharedStrings.xml", |bytes, z| {
        let chunk = vec![b' '; 1 << 20];
        for _ in 0..129 {
            z.write_all(&chunk).unwrap();
        }
        z.write_all(&bytes).unwrap();
    });
    // Both headers of that part now say 1 000 bytes unpacked (APPNOTE 4.3.7 and 4.3.12: the
    // local header's uncompressed size at +22, the central directory's at +24).
    let mut data = std::fs::read(&lying).unwrap();
    let name = b"xl/sharedStrings.xml";
    let mut at = 0;
    while let Some(j) = data[at..].windows(name.len()).position(|w| w == name).map(|p| p + at) {
        if j >= 30 && data[j - 30..j - 26] == *b"PK\x03\x04" {
            data[j - 30 + 22..j - 30 + 26].copy_from_slice(&1000u32.to_le_bytes());
        } else if j >= 46 && data[j - 46..j - 42] == *b"PK\x01\x02" {
            data[j - 46 + 24..j - 46 + 28].copy_from_slice(&1000u32.to_le_bytes());
        }
        at = j + 1;
    }
    std::fs::write(&lying, &data).unwrap();
    assert!(data.len() < 2 << 20, "a small file: {} bytes", data.len());
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["profiles", "import", lying.to_str().unwrap(), "--table", "holding", "--name", "lies"])
        .args(["-o", dir.join("lies.toml").to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("xl/sharedStrings.xml") && err.contains("says 1000 bytes"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// An XLSX whose workbook names more sheets than any register map has (5 000, each pointing at
/// the one sheet): refused before the workbook reader lays them out, naming the count (2.5
/// million of them in 12.7 MB take 574 MB to open: BENCHMARKS.md).
#[test]
fn a_workbook_naming_thousands_of_sheets_is_refused_before_it_is_opened() {
    use std::fmt::Write as _;
    use std::io::Write as _;
    let dir = std::env::temp_dir().join(format!("mbtap-many-sheets-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("one.xlsx");
    let strings = vec!["Address".to_owned(), "Name".to_owned()];
    xlsx_with_shared_strings(&path, &strings, &[vec![(true, "0".into()), (true, "1".into())]]);
    let many = dir.join("many.xlsx");
    rewrite_part(&path, &many, "xl/workbook.xml", |bytes, z| {
        let mut sheets = String::new();
        for k in 0..5_000 {
            let _ = write!(sheets, r#"<sheet name="S{k}" sheetId="{}" r:id="rId1"/>"#, k + 1);
        }
        let text = String::from_utf8(bytes).unwrap().replace(r#"<sheet name="Map" sheetId="1" r:id="rId1"/>"#, &sheets);
        z.write_all(text.as_bytes()).unwrap();
    });
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["profiles", "import", many.to_str().unwrap(), "--table", "holding", "--name", "many"])
        .args(["-o", dir.join("many.toml").to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("names 5000 sheets, over the 4096"), "{err}");
    assert!(!dir.join("many.toml").exists(), "nothing written");
    std::fs::remove_dir_all(&dir).ok();
}

/// An XLSX of more than a million tiny shared strings (`<si><t>a</t></si>`, honest sizes, a
/// file of ~40 kB): refused before the workbook reader holds them all, naming the count
/// (7.4 million of them from 307 kB take 413 MB to open: BENCHMARKS.md).
#[test]
fn a_million_tiny_shared_strings_are_refused_before_they_are_held() {
    let dir = std::env::temp_dir().join(format!("mbtap-tiny-strings-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tiny.xlsx");
    let mut strings = vec!["Address".to_owned(), "Name".to_owned()];
    strings.resize(1_000_001, "a".to_owned());
    xlsx_with_shared_strings(&path, &strings, &[vec![(true, "0".into()), (true, "1".into())]]);
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["profiles", "import", path.to_str().unwrap(), "--table", "holding", "--name", "tiny"])
        .args(["-o", dir.join("tiny.toml").to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("1000001 shared strings, over the 1000000"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A CSV of one 17 MiB quoted field, and the same with the quote never closed (as a truncated
/// export leaves it): refused by the text budget, naming the row — never built into a profile (a
/// 60 MB field is refused at 132 MB peak: BENCHMARKS.md).
#[test]
fn a_csv_field_longer_than_the_text_budget_is_refused_naming_the_row() {
    let dir = std::env::temp_dir().join(format!("mbtap-long-field-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let long = "A".repeat(17 << 20);
    for (name, text) in [
        ("closed.csv", format!("name,address\n\"{long}\",1\n")),
        ("unclosed.csv", format!("name,address\n\"{long},1\n")),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let out = dir.join(format!("{name}.toml"));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .args(["profiles", "import", path.to_str().unwrap(), "--table", "holding", "--name", "long"])
            .args(["-o", out.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains("row 2") && err.contains("16777216"), "{name}: {err}");
        assert!(!out.exists(), "{name}: no profile written");
    }
    std::fs::remove_dir_all(&dir).ok();
}
