//! Human-readable rendering: a header line per frame, then its fields indented.

use std::fmt::Write as _;

use super::FrameView;
use super::fields::{Field, Value};
use crate::report::format::hex_spaced;
use mbtap_proto::{Check, Finding, FunctionCode, PduDecode};

fn check_text(check: Check) -> String {
    match check {
        Check::Crc { received, computed } if received == computed => format!("CRC ok (0x{received:04X})"),
        Check::Crc { received, computed } => {
            format!("CRC FAILED: received 0x{received:04X}, computed 0x{computed:04X}")
        }
        Check::Lrc { received, computed } if received == computed => format!("LRC ok (0x{received:02X})"),
        Check::Lrc { received, computed } => {
            format!("LRC FAILED: received 0x{received:02X}, computed 0x{computed:02X}")
        }
        Check::Mbap => "MBAP length ok".to_owned(),
    }
}

fn function_text(fc: u8) -> String {
    if fc & 0x80 != 0 {
        let base = FunctionCode::from(fc & 0x7F);
        format!("0x{fc:02X} Exception to {}", base.label())
    } else {
        FunctionCode::from(fc).to_string()
    }
}

/// Renders one frame; `indent` prefixes every line.
#[must_use]
pub fn frame(view: &FrameView<'_>, indent: &str) -> String {
    let mut out = String::new();
    let adu = view.adu;
    let direction = match view.direction() {
        "request_or_response" => "request or response (echo shape)",
        d => d,
    };
    let fc = view.function_byte().map_or_else(|| "no function".to_owned(), function_text);
    let tid = adu.transaction_id.map(|t| format!(" tid {t}")).unwrap_or_default();
    let _ = writeln!(
        out,
        "{indent}{}{tid} unit {} · {fc} · {direction} · {}",
        adu.mode.name(),
        adu.unit,
        check_text(adu.check)
    );
    let shown = if adu.mode == mbtap_proto::Mode::Ascii {
        String::from_utf8_lossy(view.wire).trim_end().to_owned()
    } else {
        hex_spaced(view.wire)
    };
    let _ = writeln!(out, "{indent}  {shown}");
    match (view.decode, view.primary()) {
        (PduDecode::Malformed { error, .. }, _) => {
            let _ = writeln!(out, "{indent}  malformed: {error}");
        }
        (_, Some(d)) => {
            let fields = match &d.pdu {
                mbtap_proto::Pdu::Request(r) => super::fields::request_fields(r),
                mbtap_proto::Pdu::Response(r) => super::fields::response_fields(r, view.request),
            };
            for field in &fields {
                write_field(&mut out, &format!("{indent}  "), field);
            }
            if !d.trailing.is_empty() {
                let _ = writeln!(out, "{indent}  trailing: {}", hex_spaced(d.trailing));
            }
        }
        (_, None) => {}
    }
    for finding in view.findings() {
        write_finding(&mut out, indent, &finding);
    }
    out
}

fn write_finding(out: &mut String, indent: &str, finding: &Finding) {
    let tag = match finding.severity() {
        mbtap_proto::Severity::Info => "note",
        mbtap_proto::Severity::Warning => "warning",
    };
    let _ = writeln!(out, "{indent}  {tag}: {finding}");
}

/// Renders findings on a pairing (response against request).
#[must_use]
pub fn pair_findings(findings: &[Finding], indent: &str) -> String {
    let mut out = String::new();
    for f in findings {
        write_finding(&mut out, indent, f);
    }
    out
}

fn write_field(out: &mut String, indent: &str, field: &Field<'_>) {
    let key = field.key.replace('_', " ");
    match &field.value {
        Value::Num(n) => {
            let _ = writeln!(out, "{indent}{key}: {n}");
        }
        Value::Hex(h) => {
            let _ = writeln!(out, "{indent}{key}: 0x{h:04X}");
        }
        Value::Name(s) => {
            let _ = writeln!(out, "{indent}{key}: {s}");
        }
        Value::Text(s) => {
            let _ = writeln!(out, "{indent}{key}: {s:?}");
        }
        Value::Bytes([]) => {
            let _ = writeln!(out, "{indent}{key}: (none)");
        }
        Value::Bytes(b) => {
            let _ = writeln!(out, "{indent}{key}: {}", hex_spaced(b));
        }
        Value::Registers { start, values } => {
            let _ = writeln!(out, "{indent}{key}: {} register(s)", values.len());
            for (i, v) in values.iter().enumerate() {
                let label = match start {
                    Some(s) => format!("{}", usize::from(*s) + i),
                    None => format!("[{i}]"),
                };
                let _ = writeln!(out, "{indent}  {label} = {v} (0x{v:04X})");
            }
            if let Some(b) = values.odd_byte() {
                let _ = writeln!(out, "{indent}  odd byte 0x{b:02X}");
            }
        }
        Value::Bits { start, count, bits } => {
            let n = count.map_or(bits.capacity(), usize::from);
            let _ = write!(out, "{indent}{key}:");
            for (i, b) in bits.iter(n).enumerate() {
                let label = match start {
                    Some(s) => format!("{}", usize::from(*s) + i),
                    None => format!("[{i}]"),
                };
                let _ = write!(out, " {label}={}", u8::from(b));
            }
            out.push('\n');
        }
        Value::Records(records) => {
            let _ = writeln!(out, "{indent}{key}: {}", records.len());
            for (i, rec) in records.iter().enumerate() {
                let _ = writeln!(out, "{indent}  #{i}");
                for f in rec {
                    write_field(out, &format!("{indent}    "), f);
                }
            }
        }
    }
}
