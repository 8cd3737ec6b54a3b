//! `--device sunspec`: the device's SunSpec model chain discovered over the link (the `SunS`
//! marker at 40000, 0 or 50000, then model headers until `0xFFFF`), the models asked for read
//! whole (in requests of at most 125 registers, MAP v1.1b3 §6.3) and their points named
//! `MODEL.POINT`, scaled by their scale factors (`mbtap_device::sunspec`).

use mbtap_device::profile::Table;
use mbtap_device::query::plan::Read;
use mbtap_device::query::rows::Row;
use mbtap_device::sunspec::{self, Found, PointRef, Shown};

use super::exec::{Answer, Op, send};
use super::link::Link;
use super::show::Failure;

/// Registers per read request (MAP v1.1b3 §6.3: at most 125).
const MAX_READ: u16 = 125;

/// Reads `quantity` holding registers at `address` in requests of at most [`MAX_READ`].
async fn read_regs(link: &mut Link, unit: u8, address: u16, quantity: u32) -> Result<Vec<u16>, String> {
    let mut out = Vec::new();
    let mut at = u32::from(address);
    let end = at + quantity;
    while at < end {
        let n = u16::try_from((end - at).min(u32::from(MAX_READ))).unwrap_or(MAX_READ);
        let a = u16::try_from(at).map_err(|_| format!("the chain runs past register 65535 (at {at})"))?;
        let read = Read { target: 0, table: Table::HoldingRegisters, address: a, quantity: n };
        match send(link, unit, Op::Read(read)).await.0 {
            Answer::Values(v) => out.extend(v),
            other => {
                return Err(format!(
                    "holding {a}..{}: {}",
                    u32::from(a) + u32::from(n) - 1,
                    other.problem().unwrap_or_default()
                ));
            }
        }
        at += u32::from(n);
    }
    Ok(out)
}

/// The device's model chain.
///
/// # Errors
/// No `SunS` marker at any base, or a header that could not be read.
pub async fn discover(link: &mut Link, unit: u8) -> anyhow::Result<Vec<Found>> {
    let mut tried = Vec::new();
    for base in sunspec::BASES {
        match read_regs(link, unit, base, 2).await {
            Ok(m) if m == sunspec::MARKER => {
                let mut found = Vec::new();
                let mut at = base.checked_add(2);
                let mut ended = false;
                while let Some(a) = at {
                    let h = read_regs(link, unit, a, 2)
                        .await
                        .map_err(|e| anyhow::anyhow!("reading the model header at {a}: {e}"))?;
                    let (id, len) = (h[0], h[1]);
                    at = sunspec::next_header(a, id, len, found.len());
                    ended |= id == sunspec::END_ID;
                    if id != sunspec::END_ID {
                        found.push(Found { id, address: a, len });
                    }
                }
                if !ended {
                    // Cut by the model bound or the address space, not by the end marker: what
                    // follows is not the whole chain, and the user is told so.
                    eprintln!(
                        "mbtap: unit {unit}: the SunSpec chain has no end marker within {} models (or runs past register 65535): only its first {} are used",
                        sunspec::MAX_MODELS,
                        found.len()
                    );
                }
                return Ok(found);
            }
            Ok(m) => tried.push(format!("{base}: {m:04X?}")),
            Err(e) => tried.push(format!("{base}: {e}")),
        }
    }
    anyhow::bail!("unit {unit} is not a SunSpec device: no \"SunS\" marker at 40000, 0 or 50000 ({})", tried.join("; "))
}

/// The rows for `items` (`MODEL.POINT`, `MODEL`) from `unit`'s chain; failures for items not
/// found or not read.
pub async fn read_items(link: &mut Link, unit: u8, items: &[String]) -> anyhow::Result<(Vec<Row>, Vec<Failure>)> {
    let refs: Vec<(String, PointRef)> = items
        .iter()
        .map(|i| sunspec::parse_point_ref(i).map(|r| (i.clone(), r)).map_err(anyhow::Error::msg))
        .collect::<anyhow::Result<_>>()?;
    let chain = discover(link, unit).await?;
    let names: Vec<String> = chain.iter().map(Found::name).collect();
    let (mut rows, mut failures) = (Vec::new(), Vec::new());
    let mut blocks: Vec<(Found, Vec<u16>)> = Vec::new();
    for (text, r) in refs {
        let fail = |problem: String| Failure { unit, item: text.clone(), read: None, problem };
        let Some(&found) = chain.iter().filter(|f| r.is_model(f.id)).nth(r.instance - 1) else {
            failures.push(fail(format!("the device has no such model (its chain: {})", names.join(", "))));
            continue;
        };
        let block = match blocks.iter().find(|(f, _)| *f == found) {
            Some((_, b)) => b.clone(),
            None => match read_regs(link, unit, found.address, found.registers()).await {
                Ok(b) => {
                    blocks.push((found, b.clone()));
                    b
                }
                Err(e) => {
                    failures.push(fail(e));
                    continue;
                }
            },
        };
        let values = sunspec::decode_model(sunspec::model(found.id), found, &block);
        let wanted: Vec<_> = match &r.point {
            Some(p) => values.iter().filter(|v| v.point.eq_ignore_ascii_case(p)).collect(),
            None => values.iter().collect(),
        };
        if wanted.is_empty() {
            let known: Vec<&str> = values.iter().map(|v| v.point.as_str()).take(12).collect();
            failures.push(fail(format!(
                "model {} has no point {:?} (it has {}, …)",
                found.name(),
                r.point.as_deref().unwrap_or(""),
                known.join(", ")
            )));
            continue;
        }
        for v in wanted {
            let name = match &r.point {
                Some(_) => text.clone(),
                None => format!("{text}.{}", v.point),
            };
            let raw = v.registers.iter().fold(0i64, |acc, &w| acc.wrapping_shl(16) | i64::from(w));
            let (value, shown) = match &v.shown {
                None => (serde_json::Value::Null, "— (not implemented)".to_owned()),
                Some(Shown::Number { value, decimals }) => {
                    let s = format!("{value:.*}", usize::from(*decimals));
                    let json = s
                        .parse::<f64>()
                        .ok()
                        .and_then(serde_json::Number::from_f64)
                        .map_or(serde_json::Value::Null, serde_json::Value::Number);
                    let shown = match &v.units {
                        Some(u) => format!("{s} {u}"),
                        None => s,
                    };
                    (json, shown)
                }
                Some(Shown::Text(t)) => (serde_json::Value::String(t.clone()), format!("{t:?}")),
            };
            rows.push(Row {
                unit,
                table: Table::HoldingRegisters,
                address: v.address,
                name: Some(name),
                raw,
                value,
                unit_of_measure: v.units.clone(),
                notes: Vec::new(),
                shown,
            });
        }
    }
    Ok((rows, failures))
}

/// The device's chain as profile points (`profiles import --format sunspec --from TARGET`):
/// every model's points named `MODEL.POINT` (`MODEL[2].POINT` for a second instance) at their
/// addresses, typed, each scaled by its scale factor as read now (a device's scale factors are
/// fixed in practice; they are not re-read by the profile). Scale-factor points, pads and
/// 64-bit values (not in the profile format) are left out; models nobody defines are listed.
pub async fn import(link: &mut Link, unit: u8) -> anyhow::Result<mbtap_device::profile::import::Imported> {
    use mbtap_device::profile::format::{Access, ValueType, WordOrder};
    use mbtap_device::profile::import::{Imported, Point, Problem};
    let chain = discover(link, unit).await?;
    let mut out = Imported::default();
    let mut seen: Vec<u16> = Vec::new();
    for found in &chain {
        seen.push(found.id);
        let instance = seen.iter().filter(|&&i| i == found.id).count();
        let model = found.name();
        let prefix = if instance > 1 { format!("{model}[{instance}]") } else { model.clone() };
        let Some(def) = sunspec::model(found.id) else {
            out.problems.push(Problem {
                at: format!("model {} at {}", found.id, found.address),
                column: None,
                why: "a model no SunSpec definition names: not imported".into(),
            });
            continue;
        };
        let block = read_regs(link, unit, found.address, found.registers())
            .await
            .map_err(|e| anyhow::anyhow!("reading model {model} at {}: {e}", found.address))?;
        let values = sunspec::decode_model(Some(def), *found, &block);
        for v in &values {
            let base = v.point.rsplit('.').next().unwrap_or(&v.point);
            let pdef =
                def.points.iter().chain(def.repeat.iter().flat_map(|r| r.points.iter())).find(|p| p.name == base);
            let Some(pdef) = pdef else { continue };
            let value_type = match pdef.kind.as_str() {
                "uint16" | "enum16" | "bitfield16" | "count" | "acc16" => ValueType::U16,
                "int16" => ValueType::I16,
                "uint32" | "enum32" | "bitfield32" | "acc32" => ValueType::U32,
                "int32" => ValueType::I32,
                "uint64" | "acc64" => ValueType::U64,
                "int64" => ValueType::I64,
                "float32" => ValueType::F32,
                "string" => ValueType::String,
                _ => continue,
            };
            if matches!(base, "ID" | "L") {
                continue;
            }
            // The scale factor this point had when read: 10^(decimals shown) as a multiplier.
            let scale = match (&pdef.sf, &v.shown) {
                (Some(_), Some(Shown::Number { decimals, .. })) if *decimals > 0 => {
                    Some(10f64.powi(-i32::from(*decimals)))
                }
                _ => None,
            };
            out.add(Point {
                table: Table::HoldingRegisters,
                address: v.address,
                name: format!("{prefix}.{}", v.point),
                value_type,
                word_order: WordOrder::HighFirst,
                scale,
                unit: v.units.clone(),
                access: Access::Read,
                length: (value_type == ValueType::String).then_some(pdef.size),
                description: None,
                origin: format!("SunSpec model {} at {}", found.id, found.address),
            });
        }
    }
    out.notes.push(format!(
        "SunSpec chain of unit {unit}: {} (definitions: {})",
        chain.iter().map(Found::name).collect::<Vec<_>>().join(", "),
        sunspec::source()
    ));
    Ok(out)
}
