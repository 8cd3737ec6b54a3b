//! A device that says it is SunSpec is typed by SunSpec's own model definitions, not by its
//! samples: the marker `SunS` at one of the standard bases (40000, 0, 50000; SunSpec Information
//! Model Reference §"Device Modbus Map") and a chain of model headers (ID, length) heard on the
//! line name every point's type and size — a scale factor's sign, a 32-bit accumulator, a
//! 16-register serial number padded with NULs — where one or two samples could not.
//!
//! Only what was heard is typed: a point none of whose registers the master read is left out,
//! and a model this build has no definition of is stepped over by its length (its registers are
//! judged by their samples, as any other device's). 64-bit points are left to the samples too
//! (the draft has no 64-bit kind).

use mbtap_device::sunspec::{BASES, END_ID, MARKER, PointDef, model, next_header};

use super::kind::{Guess, Kind};

/// How sure a point typed by the device's own model definition is: the definition decides, the
/// samples only place it.
const BY_DEFINITION: f64 = 0.95;

/// The guesses for every heard point of every model the chain names; empty when no base holds
/// the marker. `last(a)`: the last value heard at register `a`.
#[must_use]
pub fn guesses(last: &dyn Fn(u16) -> Option<u16>) -> Vec<Guess> {
    let Some(base) =
        BASES.into_iter().find(|&b| last(b) == Some(MARKER[0]) && b.checked_add(1).and_then(last) == Some(MARKER[1]))
    else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut at = base.checked_add(2);
    let mut found = 0usize;
    while let Some(header) = at {
        let (Some(id), Some(len)) = (last(header), header.checked_add(1).and_then(last)) else { break };
        if id == END_ID {
            break;
        }
        if let Some(def) = model(id) {
            // The points (ID and L first), then the repeating group as often as the length holds.
            let end = u32::from(header) + 2 + u32::from(len);
            let mut a = u32::from(header);
            for p in &def.points {
                a = point(&mut out, def.id, &def.name, p, a, end, last);
            }
            if let Some(group) = &def.repeat {
                let size: u32 = group.points.iter().map(|p| u32::from(p.size)).sum();
                let mut instance = 0u32;
                while size > 0 && a + size <= end && instance < 256 {
                    for p in &group.points {
                        a = point(&mut out, def.id, &def.name, p, a, end, last);
                    }
                    instance += 1;
                }
            }
        }
        found += 1;
        at = next_header(header, id, len, found);
    }
    out
}

/// The guess for point `p` at `a` when it was heard and lies inside the model (`end`), and the
/// address after it.
fn point(
    out: &mut Vec<Guess>,
    id: u16,
    model_name: &str,
    p: &PointDef,
    a: u32,
    end: u32,
    last: &dyn Fn(u16) -> Option<u16>,
) -> u32 {
    let next = a + u32::from(p.size);
    let Ok(address) = u16::try_from(a) else { return next };
    if next > end || p.size == 0 {
        return next;
    }
    let words: Vec<Option<u16>> = (0..p.size).map(|k| address.checked_add(k).and_then(last)).collect();
    if words.iter().any(Option::is_none) {
        return next;
    }
    let kind = match p.kind.as_str() {
        "int16" | "sunssf" => Kind::I16,
        "uint16" | "enum16" | "bitfield16" | "count" | "acc16" | "pad" => Kind::U16,
        "uint32" | "enum32" | "bitfield32" | "ipaddr" => Kind::U32 { high_first: true, counter: false },
        "acc32" => Kind::U32 { high_first: true, counter: true },
        "int32" => Kind::I32 { high_first: true },
        "float32" => Kind::F32 { high_first: true },
        "string" => Kind::Text {
            registers: p.size,
            text: words.iter().flatten().flat_map(|w| w.to_be_bytes()).filter(|&b| b != 0).map(char::from).collect(),
        },
        // 64-bit and other wide points: no kind of the draft's holds them; the samples judge.
        _ => return next,
    };
    out.push(Guess {
        address,
        kind,
        confidence: BY_DEFINITION,
        evidence: format!(
            "SunSpec model {id} ({model_name}), point {} ({}): the device's SunSpec marker and model header, heard on \
             the line, type it",
            p.name, p.kind
        ),
    });
    next
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    /// Named constant: a SunSpec device's first registers at 40000 — the marker, the common
    /// model's header (ID 1, length 66) and its first point, Mn, "Fronius" padded with NULs.
    const HEAD: [u16; 6] = [
        0x5375, 0x6E53, // 40000 "SunS"
        0x0001, 0x0042, // 40002 ID 1 (common), L 66
        0x4672, 0x6F6E, // 40004 Mn: "Fr" "on" …
    ];

    #[test]
    fn a_device_that_says_it_is_sunspec_is_typed_by_its_models() {
        let mut regs: BTreeMap<u16, u16> = (40000..).zip(HEAD).collect();
        // The rest of Mn ("ius" and NULs), then nothing heard of the other points.
        regs.insert(40006, 0x6975);
        regs.insert(40007, 0x7300);
        for a in 40008..40020 {
            regs.insert(a, 0);
        }
        let g = guesses(&|a| regs.get(&a).copied());
        let mn = g.iter().find(|g| g.address == 40004).unwrap();
        assert_eq!(mn.kind, Kind::Text { registers: 16, text: "Fronius".into() });
        assert!(mn.confidence >= 0.9 && mn.evidence.contains("model 1"), "{mn:?}");
        // Only heard points: Md (40020…) was not read.
        assert!(g.iter().all(|g| g.address < 40020), "{g:?}");
        // No marker, no guesses.
        regs.insert(40000, 0);
        assert!(guesses(&|a| regs.get(&a).copied()).is_empty());
    }
}
