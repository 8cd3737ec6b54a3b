//! `mbtap diff A B`: which registers changed between two register images (each made from a
//! capture, or read back from `replay --image` CSV or JSON) — before and after a settings
//! change or a firmware update. Pure: two images in, the differences out; the readers of the
//! image files are here too, with every problem named by line.

use std::collections::BTreeMap;

use mbtap_device::profile::Table;
use mbtap_device::query::table_word;

/// One unit's register (or bit) and its raw value.
pub type Image = BTreeMap<(u8, Table, u16), u16>;

/// One difference.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Change {
    pub unit: u8,
    pub table: Table,
    pub address: u16,
    /// `None`: not heard in that image.
    pub before: Option<u16>,
    pub after: Option<u16>,
}

/// The differences from `a` to `b`, in address order, and how many values are the same.
#[must_use]
pub fn diff(a: &Image, b: &Image) -> (Vec<Change>, usize) {
    let mut out = Vec::new();
    let mut same = 0;
    let keys: std::collections::BTreeSet<&(u8, Table, u16)> = a.keys().chain(b.keys()).collect();
    for &&(unit, table, address) in &keys {
        let (before, after) = (a.get(&(unit, table, address)).copied(), b.get(&(unit, table, address)).copied());
        if before == after {
            same += 1;
        } else {
            out.push(Change { unit, table, address, before, after });
        }
    }
    (out, same)
}

/// A register image as `replay --image FILE.json` writes it: an array of rows with `unit`,
/// `table`, `address`, `raw` — or a probe dump (`probe --format json`), whose `image` holds
/// the same rows: every value the probe read.
///
/// # Errors
/// What is wrong and in which row.
pub fn parse_image_json(text: &str) -> Result<Image, String> {
    parse_image_json_from(text.as_bytes())
}

/// One row of an image file: only the four fields compared; the others (names, values, times)
/// are skipped as they are read, never held.
#[derive(serde::Deserialize)]
struct RowIn {
    unit: Option<u64>,
    table: Option<String>,
    address: Option<u64>,
    raw: Option<u64>,
}

/// A probe dump: its `image` rows; its other keys skipped.
#[derive(serde::Deserialize)]
struct DumpIn {
    image: Vec<RowIn>,
}

/// [`parse_image_json`] from a reader: rows are read into four numbers each as they stream by,
/// never into a JSON tree (a 100 MB dump took 2.1–3.7 GB as one).
///
/// # Errors
/// What is wrong and in which row, or where the JSON breaks (line and column).
pub fn parse_image_json_from<R: std::io::Read>(reader: R) -> Result<Image, String> {
    let mut reader = std::io::BufReader::new(reader);
    let first = loop {
        let buf = std::io::BufRead::fill_buf(&mut reader).map_err(|e| format!("cannot read it: {e}"))?;
        let Some(&b) = buf.first() else { return Err("empty: expected an array of rows".into()) };
        if b.is_ascii_whitespace() {
            std::io::BufRead::consume(&mut reader, 1);
            continue;
        }
        break b;
    };
    let rows: Vec<RowIn> = match first {
        b'[' => serde_json::from_reader(reader).map_err(|e| format!("not an array of image rows: {e}"))?,
        b'{' => {
            serde_json::from_reader::<_, DumpIn>(reader)
                .map_err(|e| format!("not a probe dump with an image: {e}"))?
                .image
        }
        _ => {
            return Err(
                "expected an array of rows (as replay --image FILE.json writes) or a probe dump (probe --format json)"
                    .into(),
            );
        }
    };
    let mut out = Image::new();
    for (i, r) in rows.iter().enumerate() {
        let unit = r.unit.and_then(|u| u8::try_from(u).ok());
        let table = r.table.as_deref().and_then(table_word);
        let address = r.address.and_then(|a| u16::try_from(a).ok());
        let raw = r.raw.and_then(|a| u16::try_from(a).ok());
        match (unit, table, address, raw) {
            (Some(u), Some(t), Some(a), Some(v)) => {
                out.insert((u, t, a), v);
            }
            _ => {
                return Err(format!(
                    "row {}: unit, table, address or raw missing or out of range (unit {:?}, table {:?}, address {:?}, raw {:?})",
                    i + 1,
                    r.unit,
                    r.table,
                    r.address,
                    r.raw
                ));
            }
        }
    }
    Ok(out)
}

/// The fields of one CSV line (RFC 4180 quoting: `"a ""b"", c"` is one field).
fn csv_fields(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut field = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(std::mem::take(&mut field)),
            (c, _) => field.push(c),
        }
    }
    out.push(field);
    out
}

/// A register image as `replay --image FILE.csv` writes it (header
/// `unit,table,address,name,raw,…`).
///
/// # Errors
/// What is wrong and on which line.
pub fn parse_image_csv(text: &str) -> Result<Image, String> {
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, h)| csv_fields(h)).unwrap_or_default();
    let col = |name: &str| header.iter().position(|h| h == name).ok_or_else(|| format!("line 1: no column {name:?}"));
    let (cu, ct, ca, cr) = (col("unit")?, col("table")?, col("address")?, col("raw")?);
    let mut out = Image::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f = csv_fields(line);
        let get = |c: usize| f.get(c).map(|s| s.trim()).unwrap_or_default();
        let parsed =
            (get(cu).parse::<u8>().ok(), table_word(get(ct)), get(ca).parse::<u16>().ok(), get(cr).parse::<u16>().ok());
        match parsed {
            (Some(u), Some(t), Some(a), Some(v)) => {
                out.insert((u, t, a), v);
            }
            _ => return Err(format!("line {}: unit, table, address or raw not readable: {line:?}", i + 1)),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changed_added_and_removed_values_are_told_apart() {
        let h = Table::HoldingRegisters;
        let a: Image = [((1, h, 105), 150), ((1, h, 106), 7), ((1, h, 107), 1)].into_iter().collect();
        let b: Image = [((1, h, 105), 275), ((1, h, 106), 7), ((1, h, 108), 3)].into_iter().collect();
        let (changes, same) = diff(&a, &b);
        assert_eq!(same, 1);
        assert_eq!(
            changes.iter().map(|c| (c.address, c.before, c.after)).collect::<Vec<_>>(),
            [(105, Some(150), Some(275)), (107, Some(1), None), (108, None, Some(3))]
        );
    }

    #[test]
    fn images_are_read_back_as_replay_writes_them() {
        let csv = "unit,table,address,name,raw,value,unit_of_measure,t_ns,transaction\n\
                   1,holding_registers,105,\"Level 2, \"\"set\"\" point\",150,\"1.50\",\"m\",5,1\n";
        let img = parse_image_csv(csv).unwrap();
        assert_eq!(img.get(&(1, Table::HoldingRegisters, 105)), Some(&150));
        let e = parse_image_csv("unit,table,address,raw\n1,holding_registers,x,1\n").unwrap_err();
        assert!(e.starts_with("line 2"), "{e}");
        let json = r#"[{"unit": 1, "table": "coils", "address": 3, "raw": 1}]"#;
        assert_eq!(parse_image_json(json).unwrap().get(&(1, Table::Coils, 3)), Some(&1));
        assert!(parse_image_json(r#"[{"unit": 1}]"#).unwrap_err().contains("row 1"));
        // A probe dump: its image rows, the rest of the report ignored.
        let dump = r#"{"unit": 3, "requests": 9, "tables": {}, "image": [{"unit": 3, "table": "holding_registers", "address": 7, "raw": 42}]}"#;
        assert_eq!(parse_image_json(dump).unwrap().get(&(3, Table::HoldingRegisters, 7)), Some(&42));
        assert!(parse_image_json(r#"{"unit": 3}"#).unwrap_err().contains("probe dump"));
    }
}
