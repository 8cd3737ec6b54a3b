//! The built-in profiles against the documents they were made from: every address a
//! document's register tables list must be in the profile (defined or reserved). The
//! addresses are read from the document itself (`docs/sources/`), so removing a register
//! from a profile — or the document gaining one — fails this test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_device::profile::{Table, builtin};

/// Addresses listed in the tables of a document section: table rows start with a 3-digit
/// address (`101\t…`) or a range (`019-049`, `244 · · · 255`, `279 – 285`).
fn listed_addresses(section: &str) -> Vec<u16> {
    let mut out = Vec::new();
    for line in section.lines() {
        let digits: String = line.chars().take_while(char::is_ascii_digit).collect();
        if digits.len() != 3 {
            continue;
        }
        let Ok(first) = digits.parse::<u16>() else { continue };
        let rest = &line[3..];
        // A range: separators then a second 3-digit address right after.
        let after: String = rest.chars().skip_while(|c| [' ', '-', '–', '·'].contains(c)).collect();
        let second: String = after.chars().take_while(char::is_ascii_digit).collect();
        let is_range = second.len() == 3 && rest.trim_start().starts_with(['-', '–', '·']);
        if is_range {
            let last: u16 = second.parse().unwrap();
            out.extend(first..=last);
        } else {
            out.push(first);
        }
    }
    out
}

fn section<'a>(doc: &'a str, from: &str, to: &str) -> &'a str {
    let a = doc.find(from).unwrap_or_else(|| panic!("{from:?} not in the document"));
    let b = doc[a..].find(to).map_or(doc.len(), |b| a + b);
    &doc[a..b]
}

#[test]
fn mk4_profile_has_every_address_of_the_document() {
    let doc = include_str!("../../docs/sources/mk4-protocol-v2.00.txt");
    let p = builtin::get("mk4").unwrap().unwrap();
    let sections = [
        (Table::Coils, section(doc, "#### 3.1 Чтение состояния дискретных выходов", "Чтение состояния 8 выходов")),
        (
            Table::DiscreteInputs,
            section(doc, "### 3.2 Чтение состояния дискретных входов", "Чтение 3 входов с адреса 053"),
        ),
        (
            Table::HoldingRegisters,
            section(doc, "### 3.3 Регистры задания параметров", "Чтение 3 регистров с адреса 101"),
        ),
        (
            Table::InputRegisters,
            section(doc, "### 3.4 Регистры чтения данных объекта", "Чтение 3 регистров с адреса 400"),
        ),
    ];
    let mut checked = 0;
    for (table, text) in sections {
        let listed = listed_addresses(text);
        assert!(!listed.is_empty(), "no addresses found for {}", table.name());
        for a in listed {
            assert!(
                p.slot(table, a).is_some() || p.is_reserved(table, a),
                "{} {a} is in the document but not in the mk4 profile",
                table.name()
            );
            checked += 1;
        }
    }
    // Coils 000–049, inputs 050–099, holding 100–399, input 400–499 + log 500–839 + 900–903.
    assert!(checked >= 50 + 50 + 300 + 100 + 340 + 4, "only {checked} addresses read from the document");
}

#[test]
fn mk4_profile_defines_exactly_the_documented_ranges() {
    let p = builtin::get("mk4").unwrap().unwrap();
    let count = |t| p.addresses(t).count();
    assert_eq!(count(Table::Coils), 19, "coils 000–018");
    assert_eq!(count(Table::DiscreteInputs), 35, "inputs 050–088 less the 4 reserved");
    assert_eq!(count(Table::HoldingRegisters), 213, "holding 100–312");
    assert_eq!(count(Table::InputRegisters), 77 + 340 + 4, "input 400–476, log 500–839, firmware 900–903");
}

/// The example: `--device 1=mk4` shows L1, L2, L3 and their average in volts.
#[test]
fn mk4_phase_voltages() {
    let p = builtin::get("mk4").unwrap().unwrap();
    let a = mbtap_device::profile::annotate::annotate_registers(
        &p,
        Table::InputRegisters,
        430,
        &[2305, 2298, 2310, 2304],
        false,
    );
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

/// The alarm log's combined code: group digit (2 = motor M1) and code (5 = starts per hour).
#[test]
fn mk4_alarm_log_code_is_decoded() {
    let p = builtin::get("mk4").unwrap().unwrap();
    let a = mbtap_device::profile::annotate::annotate_registers(&p, Table::InputRegisters, 517, &[25], false);
    assert_eq!(a[0].to_string(), "517 Alarm log record 2: alarm code = motor M1: starts per hour exceeded (raw 25)");
}

#[test]
fn every_builtin_profile_loads() {
    for name in builtin::names() {
        builtin::get(name).unwrap().unwrap_or_else(|e| panic!("{e}"));
    }
}

/// The Display's table 4 rows are `N\tDDDD\t…` with the Modbus address in the second column.
#[test]
fn display_profile_has_every_address_of_the_document() {
    let doc = include_str!("../../docs/sources/mechatronics-display-protocol.txt");
    let p = builtin::get("display").unwrap().unwrap();
    let mut listed = Vec::new();
    for line in doc.lines() {
        let mut cols = line.split('\t');
        let (Some(n), Some(addr)) = (cols.next(), cols.next()) else { continue };
        if n.trim_end_matches('*').parse::<u32>().is_ok() && addr.len() == 4 && addr.chars().all(|c| c.is_ascii_digit())
        {
            listed.push(addr.parse::<u16>().unwrap());
        }
    }
    assert_eq!(listed.len(), 268, "table 4 lists input registers 0000–0267");
    for a in listed {
        assert!(
            p.slot(Table::InputRegisters, a).is_some(),
            "input register {a} is in the document but not in the display profile"
        );
    }
    assert_eq!(p.addresses(Table::InputRegisters).count(), 268);
}

/// A flow meter's status bits and a level sensor's 32-bit volume (high word first).
#[test]
fn display_values() {
    use mbtap_device::profile::annotate::annotate_registers;
    let p = builtin::get("display").unwrap().unwrap();
    let a = annotate_registers(&p, Table::InputRegisters, 65, &[0b10_0010], false);
    assert_eq!(a[0].to_string(), "65 Flow meter 1: status = mode: nominal, interference (raw 34)");
    let a = annotate_registers(&p, Table::InputRegisters, 4, &[0x0001, 0x86A0, 5025, 0xFFFB], false);
    let shown: Vec<String> = a.iter().map(ToString::to_string).collect();
    assert_eq!(
        shown,
        [
            "4 Level sensor 1: fuel volume = 1000.00 l (raw 100000)",
            "6 Level sensor 1: fuel volume, percent = 50.25 % (raw 5025)",
            "7 Level sensor 1: temperature = -5 °C (raw -5)",
        ]
    );
}

/// The MKZP's tables (an OCR'd scan) give addresses as five digits: `Current_Faza_A 00050 | …`.
#[test]
fn mkzp_profile_has_every_address_of_the_document() {
    let doc = include_str!("../../docs/sources/mkzp-0.4-protocol-ocr.txt");
    let p = builtin::get("mkzp").unwrap().unwrap();
    // Table rows: a parameter name, the five-digit address, then `|` and the description.
    let mut listed = Vec::new();
    for line in doc.lines() {
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i < chars.len() {
            if chars[i].is_ascii_digit() {
                let start = i;
                while i < chars.len() && chars[i].is_ascii_digit() {
                    i += 1;
                }
                let next = chars[i..].iter().find(|c| **c != ' ');
                if i - start == 5 && next == Some(&'|') {
                    listed.push(chars[start..i].iter().collect::<String>().parse::<u16>().unwrap());
                }
            } else {
                i += 1;
            }
        }
    }
    listed.sort_unstable();
    listed.dedup();
    let expected: Vec<u16> = (50..=122).chain(128..=195).collect();
    assert_eq!(listed, expected, "the document lists 50–122 and 128–195");
    for a in listed {
        assert!(
            p.slot(Table::HoldingRegisters, a).is_some(),
            "register {a} is in the document but not in the mkzp profile"
        );
    }
    assert!(p.meta.also_answers.contains(&247), "every MKZP also answers address 247");
}

#[test]
fn mkzp_status_bits_and_trip_records() {
    use mbtap_device::profile::annotate::annotate_registers;
    let p = builtin::get("mkzp").unwrap().unwrap();
    let a = annotate_registers(&p, Table::HoldingRegisters, 66, &[0b100_0000_1000], false);
    assert_eq!(a[0].to_string(), "66 System_Status: status register = overload, motor on (raw 1032)");
    // P3 starts at 128 + 2 × 17 = 162: month, day, hour, minute, second.
    let a = annotate_registers(&p, Table::HoldingRegisters, 162, &[7], false);
    assert_eq!(a[0].name.as_deref(), Some("Trip record P3: time"));
    assert_eq!(a[0].notes[0].kind(), "half_of_pair", "one register of a five-register time");
    let a = annotate_registers(&p, Table::HoldingRegisters, 162, &[7, 14, 9, 5, 30], false);
    assert_eq!(a[0].to_string(), "162 Trip record P3: time = 07-14 09:05:30");
}

// Record 1 from 500: code, then day, month, year, hour, minute at 501–505.
const OCCURRED: [u16; 5] =
    [/* day */ 22, /* month */ 11, /* year */ 2026, /* hour */ 14, /* minute */ 35];

/// Log timestamps are shown as one date, and an impossible part (minute 75) is flagged.
#[test]
fn mk4_alarm_log_time_is_one_date() {
    let p = builtin::get("mk4").unwrap().unwrap();
    let a = mbtap_device::profile::annotate::annotate_registers(&p, Table::InputRegisters, 501, &OCCURRED, false);
    assert_eq!(a.len(), 1, "five registers, one value: {a:?}");
    assert_eq!(a[0].to_string(), "501 Alarm log record 1: occurred = 2026-11-22 14:35");
    assert!(a[0].notes.is_empty());
    let a = mbtap_device::profile::annotate::annotate_registers(
        &p,
        Table::InputRegisters,
        501,
        &[22, 11, 2026, 14, 75],
        false,
    );
    assert_eq!(a[0].notes[0].kind(), "out_of_range", "minute 75");
}

/// Named constant: an ABB B23's answer to `03 5000 0008` (MAP v1.1b3 §6.3) after the byte count,
/// as registers — active import 0x0000_0000_0001_E240 (123 456 × 0.01 kWh), active export 0,
/// both 64-bit high word first (ABB 2CMC485003M0201, "Energy accumulators").
const B23_ENERGIES: [u16; 8] = [
    0x0000, 0x0000, 0x0001, 0xE240, // 5000h active import, u64
    0x0000, 0x0000, 0x0000, 0x0000, // 5004h active export, u64
];

/// 64-bit registers read whole: four registers, one value, the scale applied; the meter's "not
/// available" (all ones) said out of range, never shown as a reading.
#[test]
fn an_abb_meters_64_bit_energy_reads_as_one_value() {
    let p = builtin::get("b23").unwrap().unwrap();
    let a =
        mbtap_device::profile::annotate::annotate_registers(&p, Table::HoldingRegisters, 0x5000, &B23_ENERGIES, false);
    let shown: Vec<String> = a.iter().map(ToString::to_string).collect();
    assert_eq!(
        shown,
        ["20480 Active import energy = 1234.56 kWh (raw 123456)", "20484 Active export energy = 0.00 kWh (raw 0)"]
    );
    let a =
        mbtap_device::profile::annotate::annotate_registers(&p, Table::HoldingRegisters, 0x5000, &[0xFFFF; 4], false);
    assert!(a[0].to_string().contains("outside the documented range"), "{}", a[0]);
}
