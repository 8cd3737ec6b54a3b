//! `learn` on inverters read once or twice per block: the shapes in `tests/fixtures/learn/`,
//! made from SunSpec's, SMA's and Growatt's public register maps by `make_inverter_shapes.py`
//! (each `NAME.txt` a frame list, `NAME.json` the map's answer key), generated into a capture
//! and learned as a user would. Scored as `benches/learn_inverters.py` scores them.

use std::collections::BTreeMap;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mbtap");

/// (right as the map types it, right as a 32-bit integer of its width and order whatever its
/// sign, scored, integers drafted as floats) over the map's i16, u32, i32 and text registers.
fn score(name: &str) -> (usize, usize, usize, usize) {
    let fixtures = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/learn");
    let dir = std::env::temp_dir().join(format!("mbtap-learn-inverters-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let pcap = dir.join(format!("{name}.pcapng"));
    let made = Command::new(BIN)
        .args(["generate", pcap.to_str().unwrap(), "--frames", &format!("{fixtures}/{name}.txt")])
        .args(["--baud", "9600", "--parity", "none"])
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    let out = Command::new(BIN).args(["learn", pcap.to_str().unwrap(), "--format", "json"]).output().unwrap();
    std::fs::remove_dir_all(&dir).ok();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let learned: BTreeMap<(String, u64), (String, u64)> = report["units"][0]["registers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            let key = (r["table"].as_str().unwrap().to_owned(), r["address"].as_u64().unwrap());
            (key, (r["type"].as_str().unwrap().to_owned(), r["width"].as_u64().unwrap()))
        })
        .collect();
    let key: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(format!("{fixtures}/{name}.json")).unwrap()).unwrap();
    let (mut right, mut wide_right, mut total, mut floats) = (0, 0, 0, 0);
    for k in &key {
        let (table, address, kind, width) = (
            k["table"].as_str().unwrap().to_owned(),
            k["address"].as_u64().unwrap(),
            k["type"].as_str().unwrap(),
            k["width"].as_u64().unwrap(),
        );
        let covering = learned.iter().filter(|((t, a), (_, w))| *t == table && *a <= address && address < a + w);
        if kind != "text" && covering.clone().any(|(_, (ty, _))| ty.starts_with("f32")) {
            floats += 1;
        }
        if !matches!(kind, "i16" | "u32" | "i32" | "text") {
            continue;
        }
        total += 1;
        let Some((ty, w)) = learned.get(&(table, address)) else { continue };
        let exact = *w == width
            && match kind {
                "i16" => ty == "i16",
                "u32" => ty.starts_with("u32") && ty.ends_with("high word first"),
                "i32" => ty == "i32 high word first",
                _ => ty == "string",
            };
        let wide = *w == width && kind.ends_with("32") && ty.ends_with("high word first") && !ty.starts_with("f32");
        right += usize::from(exact);
        wide_right += usize::from(exact || wide);
    }
    (right, wide_right, total, floats)
}

/// A SunSpec device read with its marker: every point typed by its model (scale factors as
/// i16, the 32-bit energy accumulator, the common model's strings to their 16 and 8 registers).
#[test]
fn an_inverter_that_says_it_is_sunspec_is_typed_by_its_models() {
    let (right, _, total, floats) = score("inverter-sunspec");
    assert_eq!((right, total, floats), (33, 33, 0));
}

/// Growatt's input registers (u32 powers and energies high word first among u16 values) and its
/// version and serial texts, two polls: at least three in four typed as the map says, the texts
/// to their full length, no integer drafted as a float.
#[test]
fn a_growatt_inverters_32_bit_values_and_texts_are_typed_from_two_polls() {
    let (right, _, total, floats) = score("inverter-growatt");
    assert_eq!(floats, 0);
    assert!(right * 4 >= total * 3, "{right} of {total}");
}

/// SMA's U32 and S32 registers, high word first, two polls: every 32-bit value found with its
/// width and word order; signed where a negative was seen (a positive S32 is bit for bit a U32,
/// so its sign cannot be heard), no integer drafted as a float.
#[test]
fn an_sma_inverters_32_bit_values_are_found_from_two_polls() {
    let (right, wide, total, floats) = score("inverter-sma");
    assert_eq!(floats, 0);
    assert!(wide * 4 >= total * 3, "{wide} of {total} as 32-bit integers");
    assert!(right >= 17, "{right} of {total} with their sign");
}

/// SunSpec's inverter model read alone (no marker heard): its negative scale factors and values
/// are i16 by their bits, its rising energy a 32-bit total; what never moved or sat at zero
/// cannot be typed by listening — and nothing is drafted as a float.
#[test]
fn sunspecs_inverter_model_alone_is_never_drafted_as_floats() {
    let (right, _, _, floats) = score("inverter-sunspec-103");
    assert_eq!(floats, 0);
    assert!(right >= 7, "{right}");
}
