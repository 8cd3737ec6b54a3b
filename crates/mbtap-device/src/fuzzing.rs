//! Fuzz harness bodies of the device model (profiles, imports, exports, queries, SunSpec): kept in the library so the
//! `fuzz/` targets stay one-liners and the same bodies run over the seed corpus in `cargo test`
//! (tests/decode/fuzz_corpus.rs).
//!
//! Each function must not panic on any input; a body that asserts a property says so in its
//! `# Panics` — there a panic is the finding.

/// Any text as a profile; when it loads, annotate a sweep of values with it.
pub fn profile(data: &[u8]) {
    use crate::profile::Table;
    use crate::profile::annotate::{annotate_bits, annotate_registers};
    let text = String::from_utf8_lossy(data);
    if let Ok(p) = crate::profile::load("fuzz.toml", &text) {
        let values: Vec<u16> =
            data.chunks(2).map(|c| u16::from_le_bytes([c[0], *c.get(1).unwrap_or(&0)])).take(64).collect();
        for table in [Table::HoldingRegisters, Table::InputRegisters] {
            for start in [0u16, 1, 100, 400, 500, 65_500] {
                let _ = annotate_registers(&p, table, start, &values, false);
                let _ = annotate_registers(&p, table, start, &values, true);
            }
        }
        let bits: Vec<bool> = data.iter().map(|b| b & 1 == 1).take(64).collect();
        let _ = annotate_bits(&p, Table::Coils, 0, &bits, true);
        let _ = annotate_bits(&p, Table::DiscreteInputs, 65_535, &bits, false);
    }
}

/// Any text as the items of `mbtap read`/`write` (one per line), with the MK4 profile and with
/// none: parsed, resolved, planned and encoded — never a panic, every planned read inside the
/// spec's quantity limits and the target's addresses, every write within 123 registers.
///
/// # Panics
/// When one of those holds not: that is what the fuzzer looks for.
pub fn query(data: &[u8]) {
    use crate::query::{encode, items, plan, resolve};
    static MK4: std::sync::OnceLock<Option<crate::profile::Profile>> = std::sync::OnceLock::new();
    let mk4 = MK4.get_or_init(|| crate::profile::builtin::get("mk4").and_then(Result::ok));
    let text = String::from_utf8_lossy(data);
    let tokens: Vec<&str> = text.split('\n').collect();
    let Ok(parsed) = items::parse_items(&tokens) else { return };
    for profile in [None, mk4.as_ref()] {
        let targets: Vec<_> = parsed.iter().filter_map(|i| resolve::resolve(i, profile).ok()).collect();
        if let Ok(p) = plan::plan(&targets, profile) {
            for r in &p.reads {
                let max = if crate::query::is_bits(r.table) { plan::MAX_READ_BITS } else { plan::MAX_READ_REGISTERS };
                assert!((1..=max).contains(&r.quantity), "read of {} registers", r.quantity);
                let t = &targets[r.target];
                assert!(r.address >= t.first && u32::from(r.address) + u32::from(r.quantity) - 1 <= u32::from(t.last));
            }
        }
        for t in &targets {
            for force in [false, true] {
                if let Ok(w) = encode::encode_write(t, profile, force) {
                    assert!(!w.words.is_empty() && w.words.len() <= 123, "{} words", w.words.len());
                    let _ = w.pdu();
                }
            }
        }
    }
}

/// Any bytes as a register sheet (lines of `,`-separated cells; the first byte chooses the
/// default table and whether columns are given) and as Home Assistant YAML: read,
/// imported, exported — never a panic, and every imported profile loads and exports.
///
/// # Panics
/// When an imported profile does not load: the fuzzer's finding.
pub fn profile_import(data: &[u8]) {
    use crate::profile::import::{home_assistant, sheet};
    let Some((&mode, rest)) = data.split_first() else { return };
    let text = String::from_utf8_lossy(rest);
    let rows = crate::profile::import::grid::Grid::from_rows(text.lines().map(|l| l.split(',')));
    let table = [
        None,
        Some(crate::profile::Table::HoldingRegisters),
        Some(crate::profile::Table::InputRegisters),
        Some(crate::profile::Table::Coils),
    ][usize::from(mode & 3)];
    let columns = if mode & 4 != 0 {
        sheet::parse_columns("address=A,name=B,type=C,scale=D").unwrap_or_default()
    } else {
        Vec::new()
    };
    let mut imported =
        vec![sheet::parse_sheet(&rows, &sheet::SheetOptions { columns, table, word_order: None, value_type: None })];
    if let Ok((i, _)) = home_assistant::parse_home_assistant(&text, Some(mode)) {
        imported.push(i);
    }
    for i in imported {
        let _ = i.problems.iter().map(ToString::to_string).count();
        let toml = i.to_toml("fuzz", "fuzz \"device\"", "fuzz\ninput");
        let loaded = crate::profile::load("imported.toml", &toml);
        assert!(loaded.is_ok(), "an import that does not load: {loaded:?}\n{toml}");
        // The import's load-back in parts agrees with the whole load.
        let parts = crate::profile::import::load_back("imported.toml", toml.as_bytes());
        assert!(parts.is_ok(), "loads whole, not in parts: {parts:?}\n{toml}");
        if let Ok(p) = loaded {
            for target in [
                crate::profile::export::Target::HomeAssistant,
                crate::profile::export::Target::Esphome,
                crate::profile::export::Target::Telegraf,
            ] {
                let _ = crate::profile::export::export(&p, mode, target);
            }
        }
    }
}

/// Any strings as a profile's device, name, register names and units: exported to
/// every target, each export parsed back as its tool reads it (YAML, TOML) and every name and
/// unit read back equal — nothing a string holds can end a comment or a scalar early.
///
/// Returns how many names were checked (none when the strings make no loadable profile).
///
/// # Panics
/// When an export does not parse or a string does not come back as written.
pub fn export_escape(data: &[u8]) -> usize {
    use crate::profile::escape::toml_str;
    use crate::profile::export::{Target, export};
    let text = String::from_utf8_lossy(data);
    let mut parts = text.split('\u{1}');
    let device = parts.next().unwrap_or_default();
    let name = parts.next().unwrap_or_default();
    let mut toml = format!("[profile]\nname = {}\ndevice = {}\n", toml_str(name), toml_str(device));
    let mut wanted = Vec::new();
    for (i, reg) in parts.take(8).enumerate() {
        let (reg_name, unit) = reg.split_once('\u{2}').unwrap_or((reg, ""));
        if reg_name.trim().is_empty() || wanted.iter().any(|(n, _)| n == reg_name) {
            continue;
        }
        let _ = std::fmt::Write::write_fmt(
            &mut toml,
            format_args!("[[holding_registers]]\naddress = {}\nname = {}\n", i * 2, toml_str(reg_name)),
        );
        if !unit.is_empty() {
            let _ = std::fmt::Write::write_fmt(&mut toml, format_args!("unit = {}\n", toml_str(unit)));
        }
        wanted.push((reg_name.to_owned(), unit.to_owned()));
    }
    let Ok(p) = crate::profile::load("fuzz.toml", &toml) else { return 0 };
    let names: Vec<(String, Option<String>)> = p
        .tables
        .values()
        .flat_map(|slots| slots.values())
        .filter_map(|slot| p.defs.get(slot.def).map(|d| (slot.name.clone(), d.unit.clone())))
        .collect();
    for target in [Target::HomeAssistant, Target::Esphome, Target::Telegraf] {
        let e = export(&p, 1, target);
        let first = e.text.lines().next().unwrap_or_default();
        assert!(
            first.chars().all(|c| c == ' ' || c.is_ascii_graphic() || (!c.is_ascii() && c.is_alphanumeric())),
            "{first:?}"
        );
        let back: serde_json::Value = if target == Target::Telegraf {
            let v = toml::from_str::<toml::Value>(&e.text);
            assert!(v.is_ok(), "TOML: {v:?}\n{}", e.text);
            v.ok().and_then(|v| serde_json::to_value(v).ok()).unwrap_or_default()
        } else {
            let v = serde_saphyr::from_str::<serde_json::Value>(&e.text);
            assert!(v.is_ok(), "YAML: {v:?}\n{}", e.text);
            v.unwrap_or_default()
        };
        let list = match target {
            Target::HomeAssistant => back["modbus"][0]["sensors"].clone(),
            Target::Esphome => back["sensor"].clone(),
            Target::Telegraf => back["inputs"]["modbus"][0]["holding_registers"].clone(),
        };
        let got: Vec<&str> =
            list.as_array().map(|a| a.iter().filter_map(|x| x["name"].as_str()).collect()).unwrap_or_default();
        for (n, unit) in &names {
            assert!(got.contains(&n.as_str()), "{target:?}: {n:?} not read back from\n{}", e.text);
            if let (Some(u), Target::HomeAssistant) = (unit, target) {
                // A known unit goes out as Home Assistant spells it, any other as written.
                let u = crate::profile::ha_classes::ha_class(u).map_or(u.as_str(), |c| c.unit);
                let found =
                    list.as_array().is_some_and(|a| a.iter().any(|x| x["unit_of_measurement"].as_str() == Some(u)));
                assert!(found, "unit {u:?} not read back\n{}", e.text);
            }
        }
    }
    names.len()
}

/// Any bytes as a SunSpec device's registers: the chain walked from register 0 the
/// way `read --device sunspec` walks it, every model decoded whatever its ID and length, and
/// the bytes as a point name — never a panic.
pub fn sunspec(data: &[u8]) {
    let regs: Vec<u16> = data.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect();
    let _ = crate::sunspec::parse_point_ref(&String::from_utf8_lossy(data));
    let mut at = Some(0u16);
    let mut found = 0;
    while let Some(a) = at {
        let i = usize::from(a);
        let (Some(&id), Some(&len)) = (regs.get(i), regs.get(i + 1)) else { break };
        let f = crate::sunspec::Found { id, address: a, len };
        let end = (i + 2 + usize::from(len)).min(regs.len());
        let values = crate::sunspec::decode_model(crate::sunspec::model(id), f, &regs[i..end]);
        for v in &values {
            let _ = v.shown.as_ref().map(ToString::to_string);
        }
        // Any model's layout over the same registers, too.
        let _ = crate::sunspec::decode_model(
            crate::sunspec::model(u16::from(data.first().copied().unwrap_or(1))),
            f,
            &regs[i..end],
        );
        found += 1;
        at = crate::sunspec::next_header(a, id, len, found);
    }
}

/// Any bytes as an OpenDocument `content.xml`, counted: never a panic, and the counts agree with
/// themselves (a table's area is never counted larger than all tables'; no text without cells).
///
/// # Panics
/// When they do not: that is what the fuzzer looks for.
pub fn ods_size(data: &[u8]) {
    use crate::profile::import::ods_size::parse_ods_size;
    if let Ok(s) = parse_ods_size(data) {
        if let Some((_, rows, cols)) = &s.largest {
            assert!(rows.saturating_mul(*cols) <= s.area_cells, "{s:?}");
        }
        assert!(s.text_bytes == 0 || s.cells_read > 0, "{s:?}");
    }
}

/// Any bytes as an XLS workbook stream: its globals and its first sheets read without a panic,
/// each sheet's rows handed on in order — numbered 0, 1, 2… — each of at most
/// [`MAX_COLUMNS`](crate::profile::import::grid::MAX_COLUMNS) cells, never past
/// [`MAX_ROWS`](crate::profile::import::grid::MAX_ROWS).
///
/// # Panics
/// When they are not: that is what the fuzzer looks for.
pub fn xls_rows(data: &[u8]) {
    use crate::profile::import::grid::{MAX_COLUMNS, MAX_ROWS};
    use crate::profile::import::xls_rows::{parse_xls_book, parse_xls_rows};
    let Ok(book) = parse_xls_book(data) else { return };
    for sheet in 0..book.sheets.len().min(4) {
        let mut next = 0usize;
        let _ = parse_xls_rows(std::io::Cursor::new(data), &book, sheet, &mut |i, cells| {
            assert!(i == next && i < MAX_ROWS && cells.len() <= MAX_COLUMNS, "row {i} after {next}");
            next += 1;
            std::ops::ControlFlow::Continue(())
        });
    }
}

/// Any bytes as an XLS file's compound-file container: read without a panic and without a
/// loop, the workbook stream found never longer than the file (each sector of a chain is read
/// once at most; a chain that comes back is refused), and the same read from its pieces of the
/// file as gathered.
///
/// # Panics
/// When it is longer: that is what the fuzzer looks for.
pub fn xls_container(data: &[u8]) {
    use crate::profile::import::xls_container::{StreamReader, WorkbookStream, parse_xls_container, parse_xls_stream};
    use std::io::Read as _;
    if let Ok(stream) = parse_xls_container(data) {
        assert!(stream.len() <= data.len(), "{} bytes from a {}-byte file", stream.len(), data.len());
        // The stream read from its pieces of the file is the stream gathered.
        if let Ok(WorkbookStream::InFile(pieces)) = parse_xls_stream(data) {
            let mut read = Vec::new();
            assert!(StreamReader::new(std::io::Cursor::new(data), &pieces).read_to_end(&mut read).is_ok());
            assert!(read == stream, "{} bytes read from the pieces, {} gathered", read.len(), stream.len());
        }
    }
}

/// Any bytes as a `content.xml`: its first sheet's rows come in order, each numbered after the
/// one before, each at most [`MAX_COLUMNS`](crate::profile::import::grid::MAX_COLUMNS) cells and
/// never more than [`MAX_ROWS`](crate::profile::import::grid::MAX_ROWS) of them.
///
/// # Panics
/// When they do not: that is what the fuzzer looks for.
pub fn ods_rows(data: &[u8]) {
    use crate::profile::import::grid::{MAX_COLUMNS, MAX_ROWS};
    let mut last: Option<usize> = None;
    let _ = crate::profile::import::ods_rows::parse_ods_rows(data, None, &mut |i, cells| {
        assert!(last.is_none_or(|l| i > l) && i < MAX_ROWS, "row {i} after {last:?}");
        assert!(cells.len() <= MAX_COLUMNS, "{} cells", cells.len());
        last = Some(i);
        std::ops::ControlFlow::Continue(())
    });
}

#[cfg(test)]
mod tests {
    /// The fuzz target's seed (`fuzz/seeds/export_escape/hostile`): device with U+2028 and
    /// U+0085 before YAML keys, registers `yes` (unit `kWh`), `1:20` (unit `=cmd`), `<<`, and
    /// ` a<VT>b` (unit `V`), fields split by 0x01, name and unit by 0x02.
    const HOSTILE_SEED: &[u8] =
        b"meter\xe2\x80\xa8shell_command:\x01evil\xc2\x85x\x01yes\x02kWh\x011:20\x02=cmd\x01<<\x01 a\x0bb\x02V";

    #[test]
    fn every_export_of_hostile_strings_reads_back_as_written() {
        assert!(super::export_escape(HOSTILE_SEED) >= 3);
    }
}
