//! Writes from the broker (`watch --mqtt-writes`), carried out by the master between its rounds
//! exactly as `mbtap write` would: the item resolved by the profile, the value scaled and
//! range-checked, refused when the register is read-only — then sent, and read back.

use mbtap_device::profile::Profile;
use mbtap_device::query::encode::encode_write;
use mbtap_device::query::plan::{Plan, Read};
use mbtap_device::query::resolve;
use mbtap_publish::remote::{Ask, WriteResult};

use super::exec;
use super::link::Link;

/// Carries out `ask` on `unit` (the watched unit; another is refused).
pub async fn apply(link: &mut Link, unit: u8, ask: &Ask, profile: Option<&Profile>) -> WriteResult {
    if ask.unit != unit {
        return Err(format!("{}: this watch reads and writes unit {unit} only, not unit {}", ask.item.text, ask.unit));
    }
    if unit == 0 {
        return Err(format!("{}: unit 0 is a broadcast; the broker cannot ask for one", ask.item.text));
    }
    let target = resolve::resolve(&ask.item, profile).map_err(|e| e.to_string())?;
    let w = encode_write(&target, profile, false).map_err(|e| e.to_string())?;
    let (answer, _) = exec::send(link, unit, exec::Op::Write(&w)).await;
    if let Some(problem) = answer.problem() {
        return Err(format!("{}: the device refused or did not answer: {problem}", ask.item.text));
    }
    let quantity = u16::try_from(w.words.len()).unwrap_or(1);
    let plan = Plan {
        reads: vec![Read { target: 0, table: w.table, address: w.address, quantity }],
        skipped: vec![],
        unmapped: vec![],
    };
    let (back, _) = exec::read_all(link, unit, std::slice::from_ref(&target), &plan, profile).await;
    Ok(back.into_iter().next())
}
