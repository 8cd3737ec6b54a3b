//! Rendering analyzer events (frames, noise, transactions) as text lines and JSON lines, and
//! the statistics sink. JSON keys follow the contract in ARCHITECTURE.md: every frame event
//! has `event`, `hex`, `check_ok` and `t_ns` (estimated start, ns since the epoch).
//!
//! Its `stats` module counts what went by (the statistics sink and the summary).

use std::fmt::Write as _;

use serde_json::{Map, Value as J, json};

use super::fields::{Field, Value, request_fields, response_fields};
use crate::analyzer::Event;
use crate::pairing::{Outcome, Role, ShownLatency, Transaction};
use crate::report::format::{clock_us, hex_compact, hex_spaced};
use mbtap_proto::{DecodedPdu, DirectionHint, FunctionCode, Pdu, PduDecode, decode_pdu};

mod stats;
pub use stats::{Stats, observer_text};

/// Wire text: ASCII frames as their characters (CR LF escaped), RTU as hex.
fn wire(bytes: &[u8]) -> String {
    if bytes.first() == Some(&b':') {
        String::from_utf8_lossy(bytes).replace('\r', "\\r").replace('\n', "\\n")
    } else {
        hex_spaced(bytes)
    }
}

fn role_name(role: Role) -> &'static str {
    match role {
        Role::Request => "request",
        Role::Response => "response",
        Role::Unknown => "unknown",
    }
}

fn decode(pdu: &[u8], role: Role) -> Option<DecodedPdu<'_>> {
    let hint = match role {
        Role::Request => DirectionHint::Request,
        Role::Response => DirectionHint::Response,
        Role::Unknown => return None,
    };
    match decode_pdu(pdu, hint) {
        PduDecode::One(d) => Some(d),
        _ => None,
    }
}

/// The decoded fields and findings of a frame with a valid check, read in its role.
fn decoded_fields(frame_ok: bool, pdu: Option<&[u8]>, role: Role) -> Option<(Vec<Field<'_>>, DecodedPdu<'_>)> {
    let d = decode(pdu.filter(|_| frame_ok)?, role)?;
    let fields = match d.pdu {
        Pdu::Request(r) => request_fields(&r),
        Pdu::Response(r) => response_fields(&r, None),
    };
    Some((fields, d))
}

fn summary(fields: &[Field<'_>]) -> String {
    let mut s = String::new();
    for f in fields {
        let v = match &f.value {
            Value::Num(n) => n.to_string(),
            Value::Hex(h) => format!("0x{h:04X}"),
            Value::Name(n) => (*n).to_owned(),
            Value::Text(t) => format!("{t:?}"),
            Value::Bytes(b) => hex_spaced(b),
            Value::Registers { values, .. } => {
                let v: Vec<String> = values.iter().take(16).map(|r| r.to_string()).collect();
                let more = if values.len() > 16 { ", …" } else { "" };
                format!("[{}{more}]", v.join(", "))
            }
            Value::Bits { count, bits, .. } => {
                let n = count.map_or(bits.capacity(), usize::from).min(32);
                bits.iter(n).map(|b| if b { '1' } else { '0' }).collect()
            }
            Value::Records(r) => format!("{} record(s)", r.len()),
        };
        let _ = write!(s, " {}={v}", f.key);
    }
    s
}

/// What a frame's other possible length means (`Frame::alt_len`), said in one phrase.
#[must_use]
pub fn alt_len_text(len: usize, alt: usize) -> String {
    if alt > len {
        format!("or {alt} bytes: the 00 after it checks as its CRC's high byte too, not a turnaround glitch")
    } else {
        format!("or {alt} bytes: its last 00 checks as a turnaround glitch too, not its CRC's high byte")
    }
}

/// One event as a line of text.
#[must_use]
pub fn text_line(e: &Event<'_>) -> String {
    match *e {
        Event::Frame { frame, role, unit, pdu } => {
            let mut line = format!("{} p{} ", clock_us(frame.t_start.0), frame.port.0);
            let check = if frame.check_ok { "ok " } else { "BAD" };
            let fc = pdu.and_then(|p| p.first().copied());
            match (unit, fc) {
                (Some(u), Some(fc)) => {
                    let name = if fc & 0x80 != 0 {
                        format!("exception to {}", FunctionCode::from(fc & 0x7F).label())
                    } else {
                        FunctionCode::from(fc).label().to_owned()
                    };
                    let _ = write!(line, "{check} unit {u:>3} {:<8} 0x{fc:02X} {name}", role_name(role));
                    if let Some((fields, _)) = decoded_fields(frame.check_ok, pdu, role) {
                        line.push_str(&summary(&fields));
                    }
                }
                _ => {
                    let _ = write!(line, "{check} frame too short to decode");
                }
            }
            if let Some(g) = frame.gap_violation_ns {
                let _ = write!(line, " [gap {} µs inside]", g / 1000);
            }
            if let Some(g) = frame.short_gap_before_ns {
                let _ = write!(line, " [only {} µs after previous frame]", g / 1000);
            }
            if let Some(n) = frame.alt_len {
                let _ = write!(line, " [{}]", alt_len_text(frame.bytes.len(), n));
            }
            let _ = write!(line, "  | {}", wire(frame.bytes));
            line
        }
        Event::Noise(n) => {
            format!("{} p{} NOISE {} byte(s) | {}", clock_us(n.t_start.0), n.port.0, n.bytes.len(), wire(n.bytes))
        }
        Event::Glitch(n) => {
            format!("{} p{} GLITCH at turnaround | {}", clock_us(n.t_start.0), n.port.0, wire(n.bytes))
        }
        Event::Transaction(t) => transaction_text(t),
    }
}

fn transaction_text(t: &Transaction<'_>) -> String {
    let mut line = format!(
        "{} --> unit {:>3} 0x{:02X} {} {}",
        clock_us(t.t_start.0),
        t.unit,
        t.function,
        FunctionCode::from(t.function).label(),
        t.outcome.name()
    );
    if let Outcome::Exception(c) = t.outcome {
        let _ = write!(line, " {}", mbtap_proto::ExceptionCode::from(c));
    }
    if let Outcome::WrongUnit(u) = t.outcome {
        let _ = write!(line, " (answered by unit {u})");
    }
    let ms = |l: u64| format!("{}.{:03} ms", l / 1_000_000, (l / 1000) % 1000);
    match t.shown_latency() {
        ShownLatency::Measured(l) => {
            let _ = write!(line, " latency {}", ms(l));
        }
        ShownLatency::Under(r) => {
            let _ = write!(line, " latency under {} (not measurable finer through these reads)", ms(r));
        }
        ShownLatency::OneRead => line.push_str(" latency not measurable (request and answer in one read)"),
        ShownLatency::NotMeasurable => {
            line.push_str(" latency not measurable (the reads place the answer at the request's end)");
        }
        ShownLatency::None => {}
    }
    if t.input_ended {
        line.push_str(" (input ended while waiting)");
    }
    line
}

/// One event as a JSON object.
#[must_use]
pub fn json(e: &Event<'_>) -> J {
    match *e {
        Event::Frame { frame, role, unit, pdu } => {
            let mut m = Map::new();
            m.insert("event".into(), json!("frame"));
            m.insert("t_ns".into(), json!(frame.t_start.0));
            m.insert("t_end_ns".into(), json!(frame.t_end.0));
            m.insert("port".into(), json!(frame.port.0));
            let shown = if frame.bytes.first() == Some(&b':') {
                String::from_utf8_lossy(frame.bytes).into_owned()
            } else {
                hex_compact(frame.bytes)
            };
            m.insert("hex".into(), json!(shown));
            m.insert("check_ok".into(), json!(frame.check_ok));
            m.insert("len".into(), json!(frame.bytes.len()));
            m.insert("direction".into(), json!(role_name(role)));
            if let Some(u) = unit {
                m.insert("unit".into(), json!(u));
            }
            if let Some(&fc) = pdu.and_then(|p| p.first()) {
                m.insert("function".into(), json!(fc));
                m.insert("function_name".into(), json!(FunctionCode::from(fc & 0x7F).label()));
            }
            if let Some((fields, d)) = decoded_fields(frame.check_ok, pdu, role) {
                m.insert("fields".into(), super::jsonl::fields_object(&fields));
                m.insert("findings".into(), super::jsonl::findings(&d.findings));
            }
            if let Some(g) = frame.gap_violation_ns {
                m.insert("gap_violation_ns".into(), json!(g));
            }
            if let Some(g) = frame.short_gap_before_ns {
                m.insert("short_gap_before_ns".into(), json!(g));
            }
            if frame.bad_chars {
                m.insert("bad_chars".into(), json!(true));
            }
            if let Some(n) = frame.alt_len {
                m.insert("or_len".into(), json!(n));
            }
            J::Object(m)
        }
        Event::Glitch(n) | Event::Noise(n) => json!({
            "event": if matches!(e, Event::Glitch(_)) { "glitch" } else { "noise" },
            "t_ns": n.t_start.0,
            "t_end_ns": n.t_end.0,
            "port": n.port.0,
            "hex": hex_compact(n.bytes),
            "check_ok": false,
            "len": n.bytes.len(),
        }),
        Event::Transaction(t) => {
            let mut m = Map::new();
            m.insert("event".into(), json!("transaction"));
            m.insert("t_ns".into(), json!(t.t_start.0));
            m.insert("unit".into(), json!(t.unit));
            m.insert("function".into(), json!(t.function));
            m.insert("function_name".into(), json!(FunctionCode::from(t.function).label()));
            m.insert("outcome".into(), json!(t.outcome.name()));
            if t.input_ended {
                m.insert("input_ended".into(), json!(true));
            }
            match t.outcome {
                Outcome::Exception(c) => {
                    m.insert("exception_code".into(), json!(c));
                }
                Outcome::WrongUnit(u) => {
                    m.insert("responder".into(), json!(u));
                }
                _ => {}
            }
            // Not measurable: no latency rather than an invented 0; under the resolution: the
            // bound, not the figure.
            match t.shown_latency() {
                ShownLatency::Measured(l) => {
                    m.insert("latency_ns".into(), json!(l));
                }
                ShownLatency::Under(r) => {
                    m.insert("latency_measurable".into(), json!(false));
                    m.insert("latency_under_ns".into(), json!(r));
                }
                ShownLatency::NotMeasurable | ShownLatency::OneRead => {
                    m.insert("latency_measurable".into(), json!(false));
                }
                ShownLatency::None => {}
            }
            if let Some(r) = t.request {
                m.insert("request_hex".into(), json!(hex_compact(r)));
            }
            if let Some(r) = t.response {
                m.insert("response_hex".into(), json!(hex_compact(r)));
            }
            J::Object(m)
        }
    }
}
