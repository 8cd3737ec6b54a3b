//! JSON lines: one object per frame or transaction. Keys kept stable for scripts: `event`,
//! `hex`, `check_ok`, `unit`, `function` (the byte as on the wire: 131 for an exception to 03),
//! `direction`, `fields`, `findings`.

use serde_json::{Map, Value as J, json};

use super::FrameView;
use super::fields::{Field, Value};
use crate::report::format::hex_compact;
use mbtap_proto::{Check, Finding, FunctionCode, Mode, Pdu};

fn field_value(v: &Value<'_>) -> J {
    match v {
        Value::Num(n) => json!(n),
        Value::Hex(h) => json!(h),
        Value::Name(s) => json!(s),
        Value::Text(s) => json!(s),
        Value::Bytes(b) => json!(hex_compact(b)),
        Value::Registers { values, .. } => J::Array(values.iter().map(|v| json!(v)).collect()),
        Value::Bits { count, bits, .. } => {
            let n = count.map_or(bits.capacity(), usize::from);
            J::Array(bits.iter(n).map(|b| json!(u8::from(b))).collect())
        }
        Value::Records(rs) => J::Array(rs.iter().map(|r| fields_object(r)).collect()),
    }
}

/// Fields as a JSON object (addresses of register and bit lists as `<key>_start_address`).
#[must_use]
pub fn fields_object(fields: &[Field<'_>]) -> J {
    let mut m = Map::new();
    for f in fields {
        m.insert(f.key.to_owned(), field_value(&f.value));
        if let Value::Registers { start: Some(s), .. } | Value::Bits { start: Some(s), .. } = f.value {
            m.insert(format!("{}_start_address", f.key), json!(s));
        }
    }
    J::Object(m)
}

/// Findings as `[{kind, severity, message}]`.
#[must_use]
pub fn findings(list: &[Finding]) -> J {
    J::Array(
        list.iter()
            .map(|f| {
                json!({
                    "kind": f.kind(),
                    "severity": match f.severity() {
                        mbtap_proto::Severity::Info => "info",
                        mbtap_proto::Severity::Warning => "warning",
                    },
                    "message": f.to_string(),
                })
            })
            .collect(),
    )
}

/// One frame as a JSON object (no `event` key: the caller adds it where it belongs).
#[must_use]
pub fn frame(view: &FrameView<'_>) -> J {
    let adu = view.adu;
    let mut m = Map::new();
    let wire =
        if adu.mode == Mode::Ascii { String::from_utf8_lossy(view.wire).into_owned() } else { hex_compact(view.wire) };
    m.insert("hex".into(), json!(wire));
    m.insert("mode".into(), json!(adu.mode.name().to_lowercase()));
    m.insert("check_ok".into(), json!(adu.check.ok()));
    match adu.check {
        Check::Crc { received, computed } => {
            m.insert("crc".into(), json!({"received": received, "computed": computed}));
        }
        Check::Lrc { received, computed } => {
            m.insert("lrc".into(), json!({"received": received, "computed": computed}));
        }
        Check::Mbap => {}
    }
    if let Some(t) = adu.transaction_id {
        m.insert("transaction_id".into(), json!(t));
    }
    m.insert("unit".into(), json!(adu.unit));
    if let Some(fc) = view.function_byte() {
        m.insert("function".into(), json!(fc));
        m.insert("function_name".into(), json!(FunctionCode::from(fc & 0x7F).label()));
        m.insert("exception".into(), json!(fc & 0x80 != 0));
    }
    m.insert("direction".into(), json!(view.direction()));
    match view.primary() {
        Some(d) => {
            let fields = match &d.pdu {
                Pdu::Request(r) => super::fields::request_fields(r),
                Pdu::Response(r) => super::fields::response_fields(r, view.request),
            };
            m.insert("fields".into(), fields_object(&fields));
            if !d.trailing.is_empty() {
                m.insert("trailing".into(), json!(hex_compact(d.trailing)));
            }
        }
        None => {
            if let mbtap_proto::PduDecode::Malformed { error, .. } = view.decode {
                m.insert("error".into(), json!(error.to_string()));
            }
        }
    }
    m.insert("findings".into(), findings(&view.findings()));
    J::Object(m)
}
