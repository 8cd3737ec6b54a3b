//! The register image: the latest known value of every (unit, table, address) seen on the
//! bus — read in a response or written in a request — with when it was seen and which
//! transaction it came from. Written by `replay --image out.csv|json`.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::format::Table;
use mbtap_proto::{Request, Response};

/// One known value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Known {
    pub raw: u16,
    pub t_ns: u64,
    /// 1-based number of the transaction (in the order they completed) that carried it.
    pub transaction: u64,
}

/// Addresses the image holds at most (about 60 MiB): a line whose frames name ever new units
/// and addresses — a hostile or broken one, every address of 247 units and four tables is 65 M —
/// must not take the memory of the process that listens (spy mode, MQTT, `--image`).
pub const MAX_VALUES: usize = 1 << 20;

/// The image.
#[derive(Debug, Clone)]
pub struct RegisterImage {
    pub values: BTreeMap<(u8, Table, u16), Known>,
    transactions: u64,
    /// The addresses the last [`Self::update`] set, in the order it set them.
    touched: Vec<(u8, Table, u16)>,
    limit: usize,
    /// Values of new addresses not kept because the image was full (known ones still update).
    pub overflowed: u64,
}

impl Default for RegisterImage {
    fn default() -> Self {
        Self::with_limit(MAX_VALUES)
    }
}

impl RegisterImage {
    /// An image that keeps at most `limit` addresses.
    #[must_use]
    pub fn with_limit(limit: usize) -> Self {
        Self { values: BTreeMap::new(), transactions: 0, touched: Vec::new(), limit, overflowed: 0 }
    }

    fn set(&mut self, unit: u8, table: Table, start: u16, values: impl IntoIterator<Item = u16>, t_ns: u64) {
        for (i, raw) in values.into_iter().enumerate() {
            let Some(a) = u16::try_from(i).ok().and_then(|i| start.checked_add(i)) else { break };
            let known = Known { raw, t_ns, transaction: self.transactions };
            let full = self.values.len() >= self.limit;
            match self.values.entry((unit, table, a)) {
                std::collections::btree_map::Entry::Occupied(mut e) => {
                    e.insert(known);
                }
                std::collections::btree_map::Entry::Vacant(_) if full => {
                    self.overflowed += 1;
                    continue;
                }
                std::collections::btree_map::Entry::Vacant(e) => {
                    e.insert(known);
                }
            }
            self.touched.push((unit, table, a));
        }
    }

    /// Takes in a completed transaction: its request's PDU, and its response's when it checked
    /// (`Transaction::request_pdu`, `response_pdu`: the framer's, never split from the wire again).
    pub fn update(&mut self, unit: u8, t_ns: u64, request_pdu: &[u8], response_pdu: Option<&[u8]>) {
        self.transactions += 1;
        self.touched.clear();
        let Ok(([], req)) = mbtap_proto::parse_request(request_pdu) else { return };
        let resp = match response_pdu.map(mbtap_proto::parse_response) {
            Some(Ok(([], r))) => Some(r),
            _ => None,
        };
        let bits = |b: mbtap_proto::Bits<'_>, n: u16| b.iter(usize::from(n)).map(u16::from).collect::<Vec<_>>();
        match (req, resp) {
            (Request::ReadCoils { address, quantity }, Some(Response::ReadCoils { status })) => {
                self.set(unit, Table::Coils, address, bits(status, quantity), t_ns);
            }
            (Request::ReadDiscreteInputs { address, quantity }, Some(Response::ReadDiscreteInputs { status })) => {
                self.set(unit, Table::DiscreteInputs, address, bits(status, quantity), t_ns);
            }
            (Request::ReadHoldingRegisters { address, .. }, Some(Response::ReadHoldingRegisters { values }))
            | (
                Request::WriteMultipleRegisters { address, values, .. },
                Some(Response::WriteMultipleRegisters { .. }),
            ) => {
                self.set(unit, Table::HoldingRegisters, address, values.iter(), t_ns);
            }
            (Request::ReadInputRegisters { address, .. }, Some(Response::ReadInputRegisters { values })) => {
                self.set(unit, Table::InputRegisters, address, values.iter(), t_ns);
            }
            (Request::WriteSingleCoil { address, value }, Some(Response::WriteSingleCoil { .. })) => {
                self.set(unit, Table::Coils, address, [u16::from(value == 0xFF00)], t_ns);
            }
            (Request::WriteSingleRegister { address, value }, Some(Response::WriteSingleRegister { .. })) => {
                self.set(unit, Table::HoldingRegisters, address, [value], t_ns);
            }
            (Request::WriteMultipleCoils { address, quantity, values }, Some(Response::WriteMultipleCoils { .. })) => {
                self.set(unit, Table::Coils, address, bits(values, quantity), t_ns);
            }

            (
                Request::ReadWriteMultipleRegisters { read_address, write_address, values, .. },
                Some(Response::ReadWriteMultipleRegisters { values: read }),
            ) => {
                self.set(unit, Table::HoldingRegisters, write_address, values.iter(), t_ns);
                self.set(unit, Table::HoldingRegisters, read_address, read.iter(), t_ns);
            }
            _ => {}
        }
    }

    /// The addresses the last [`Self::update`] set (at most one transaction's worth: a
    /// publisher looks here for what may have changed).
    #[must_use]
    pub fn touched(&self) -> &[(u8, Table, u16)] {
        &self.touched
    }

    /// The image as CSV: `unit,table,address,name,raw,value,unit_of_measure,t_ns,transaction`,
    /// names and scaled values from the unit's profile when there is one; text cells a spreadsheet
    /// would run as a formula are neutralised ([`super::escape::csv_cell`]).
    #[must_use]
    pub fn to_csv(&self, profiles: &BTreeMap<u8, super::Profile>) -> String {
        let mut out = String::from("unit,table,address,name,raw,value,unit_of_measure,t_ns,transaction\n");
        for row in self.rows(profiles) {
            let quote = |s: &str| super::escape::csv_cell(s);
            let _ = writeln!(
                out,
                "{},{},{},{},{},{},{},{},{}",
                row.unit,
                row.table.name(),
                row.address,
                quote(&row.name),
                row.raw,
                quote(&row.value),
                quote(&row.unit_of_measure),
                row.t_ns,
                row.transaction
            );
        }
        out
    }

    /// The image as a JSON array of the same rows.
    #[must_use]
    pub fn to_json(&self, profiles: &BTreeMap<u8, super::Profile>) -> serde_json::Value {
        serde_json::Value::Array(
            self.rows(profiles)
                .into_iter()
                .map(|r| {
                    serde_json::json!({
                        "unit": r.unit, "table": r.table.name(), "address": r.address, "name": r.name,
                        "raw": r.raw, "value": r.value, "unit_of_measure": r.unit_of_measure,
                        "t_ns": r.t_ns, "transaction": r.transaction,
                    })
                })
                .collect(),
        )
    }

    fn rows(&self, profiles: &BTreeMap<u8, super::Profile>) -> Vec<Row> {
        self.values
            .iter()
            .map(|(&(unit, table, address), k)| {
                let mut row = Row {
                    unit,
                    table,
                    address,
                    name: String::new(),
                    raw: k.raw,
                    value: k.raw.to_string(),
                    unit_of_measure: String::new(),
                    t_ns: k.t_ns,
                    transaction: k.transaction,
                };
                // A 32-bit value is shown at its first address, from both registers when the
                // image has the second.
                let next = address.checked_add(1).and_then(|n| self.values.get(&(unit, table, n))).map(|n| n.raw);
                let regs: Vec<u16> = std::iter::once(k.raw).chain(next).collect();
                if let Some(p) = profiles.get(&unit)
                    && let Some(a) = (if matches!(table, Table::Coils | Table::DiscreteInputs) {
                        super::annotate::annotate_bits(p, table, address, &[k.raw != 0], false)
                    } else {
                        super::annotate::annotate_registers(p, table, address, &regs, false)
                    })
                    .into_iter()
                    .next()
                    .filter(|a| a.address == address)
                {
                    row.name = a.name.unwrap_or_default();
                    match &a.shown {
                        super::annotate::Shown::Number { value, unit, decimals } => {
                            row.value = match decimals {
                                Some(d) => format!("{value:.*}", usize::from(*d)),
                                None => format!("{value}"),
                            };
                            unit.as_deref().unwrap_or_default().clone_into(&mut row.unit_of_measure);
                        }
                        super::annotate::Shown::Label(l) | super::annotate::Shown::Bool { label: Some(l), .. } => {
                            l.clone_into(&mut row.value);
                        }
                        super::annotate::Shown::Bits(b) => row.value = b.join("; "),
                        super::annotate::Shown::Text(t) | super::annotate::Shown::Time(t) => {
                            t.clone_into(&mut row.value);
                        }
                        super::annotate::Shown::Bool { label: None, .. } | super::annotate::Shown::Raw => {}
                    }
                }
                row
            })
            .collect()
    }
}

struct Row {
    unit: u8,
    table: Table,
    address: u16,
    name: String,
    raw: u16,
    value: String,
    unit_of_measure: String,
    t_ns: u64,
    transaction: u64,
}

/// MAP v1.1b3 §7: exception 01, illegal function.
pub const ILLEGAL_FUNCTION: u8 = 0x01;
/// MAP v1.1b3 §7: exception 02, illegal data address.
pub const ILLEGAL_DATA_ADDRESS: u8 = 0x02;
/// MAP v1.1b3 §7: exception 03, illegal data value (a quantity out of range, §6.1–§6.4).
pub const ILLEGAL_DATA_VALUE: u8 = 0x03;
/// MAP v1.1b3 §7: exception 0B, gateway target device failed to respond.
pub const GATEWAY_TARGET_FAILED: u8 = 0x0B;

impl RegisterImage {
    /// Whether anything was ever heard from `unit`.
    #[must_use]
    pub fn knows_unit(&self, unit: u8) -> bool {
        self.values.range((unit, Table::Coils, 0)..=(unit, Table::InputRegisters, u16::MAX)).next().is_some()
    }

    /// The answer a read-only server gives from the image: the values of `quantity` addresses
    /// of `table` from `address`, or the exception code — 03 for a quantity the spec does not
    /// allow (1–2000 bits, 1–125 registers: MAP v1.1b3 §6.1–§6.4), 0B for a unit never heard
    /// or any value older than `max_age_ns` at `now_ns` (a gateway whose target did not answer:
    /// stale data must not pass for fresh), 02 for an address never heard.
    pub fn serve_read(
        &self,
        unit: u8,
        table: Table,
        address: u16,
        quantity: u16,
        now_ns: u64,
        max_age_ns: Option<u64>,
    ) -> Result<Vec<u16>, u8> {
        let max = if matches!(table, Table::Coils | Table::DiscreteInputs) { 2000 } else { 125 };
        if quantity == 0 || quantity > max {
            return Err(ILLEGAL_DATA_VALUE);
        }
        if !self.knows_unit(unit) {
            return Err(GATEWAY_TARGET_FAILED);
        }
        let mut out = Vec::with_capacity(usize::from(quantity));
        let mut stale = false;
        for i in 0..quantity {
            let a = address.checked_add(i).ok_or(ILLEGAL_DATA_ADDRESS)?;
            let k = self.values.get(&(unit, table, a)).ok_or(ILLEGAL_DATA_ADDRESS)?;
            stale |= max_age_ns.is_some_and(|max| now_ns.saturating_sub(k.t_ns) > max);
            out.push(k.raw);
        }
        if stale { Err(GATEWAY_TARGET_FAILED) } else { Ok(out) }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod serve_tests {
    use super::*;

    /// Unit 1 reads holding 100–101 = 7, 8: request 01 03 0064 0002 + CRC, answer 01 03 04
    /// 0007 0008 + CRC.
    const REQUEST: [u8; 8] = [0x01, 0x03, 0x00, 0x64, 0x00, 0x02, 0x85, 0xD4];
    const RESPONSE: [u8; 9] = [0x01, 0x03, 0x04, 0x00, 0x07, 0x00, 0x08, 0x4A, 0x34];

    fn image() -> RegisterImage {
        // CRC-16/MODBUS, low byte first (Serial Line v1.02 §2.5.1.2).
        assert_eq!(mbtap_proto::crc16(&REQUEST[..6]).to_le_bytes(), [0x85, 0xD4]);
        assert_eq!(mbtap_proto::crc16(&RESPONSE[..7]).to_le_bytes(), [0x4A, 0x34]);
        let mut img = RegisterImage::default();
        img.update(1, 1_000, &REQUEST[1..6], Some(&RESPONSE[1..7]));
        img
    }

    #[test]
    fn answers_what_was_heard_and_refuses_the_rest() {
        let img = image();
        assert_eq!(img.serve_read(1, Table::HoldingRegisters, 100, 2, 1_000, None), Ok(vec![7, 8]));
        assert_eq!(img.serve_read(1, Table::HoldingRegisters, 100, 3, 1_000, None), Err(ILLEGAL_DATA_ADDRESS));
        assert_eq!(img.serve_read(1, Table::InputRegisters, 100, 1, 1_000, None), Err(ILLEGAL_DATA_ADDRESS));
        assert_eq!(img.serve_read(2, Table::HoldingRegisters, 100, 1, 1_000, None), Err(GATEWAY_TARGET_FAILED));
        assert_eq!(img.serve_read(1, Table::HoldingRegisters, 100, 126, 1_000, None), Err(ILLEGAL_DATA_VALUE));
        assert_eq!(img.serve_read(1, Table::HoldingRegisters, 100, 0, 1_000, None), Err(ILLEGAL_DATA_VALUE));
        assert_eq!(img.serve_read(1, Table::HoldingRegisters, u16::MAX, 2, 1_000, None), Err(ILLEGAL_DATA_ADDRESS));
    }

    #[test]
    fn a_full_image_keeps_updating_what_it_has_and_counts_the_rest() {
        let mut img = RegisterImage::with_limit(1);
        // The image takes PDUs (the frames' unit, CRC dropped).
        img.update(1, 1_000, &REQUEST[1..6], Some(&RESPONSE[1..7]));
        assert_eq!((img.values.len(), img.overflowed), (1, 1), "holding 100 kept, 101 counted");
        img.update(1, 2_000, &REQUEST[1..6], Some(&RESPONSE[1..7]));
        assert_eq!(img.values[&(1, Table::HoldingRegisters, 100)].t_ns, 2_000, "a known address still updates");
        assert_eq!(img.overflowed, 2);
    }

    #[test]
    fn stale_values_are_a_failed_target_not_data() {
        let img = image();
        assert_eq!(img.serve_read(1, Table::HoldingRegisters, 100, 2, 1_500, Some(500)), Ok(vec![7, 8]));
        assert_eq!(img.serve_read(1, Table::HoldingRegisters, 100, 2, 1_501, Some(500)), Err(GATEWAY_TARGET_FAILED));
    }

    /// A register named like a formula is written as text a spreadsheet shows, not runs
    /// (`=HYPERLINK(…)` never reaches a cell as a formula).
    #[test]
    fn formula_names_in_the_csv_image_are_neutralised() {
        let img = image();
        let profile = crate::profile::load(
            "f.toml",
            "[profile]\nname = \"f\"\ndevice = \"f\"\n[[holding_registers]]\naddress = 100\nname = \"=HYPERLINK(\\\"http://x\\\")\"\nunit = \"@SUM(A1)\"\n",
        )
        .expect("loads");
        let csv = img.to_csv(&BTreeMap::from([(1, profile)]));
        let row = csv.lines().find(|l| l.starts_with("1,holding_registers,100,")).expect("row");
        assert!(row.contains(",\"'=HYPERLINK(\"\"http://x\"\")\","), "{row}");
        assert!(row.contains(",\"'@SUM(A1)\","), "{row}");
    }
}
