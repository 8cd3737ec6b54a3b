//! Frames given as hex or ASCII text, explained (the work of `mbtap decode`). A request followed by the
//! response that answers it is shown as one transaction.

use std::io::{self, Write};

use serde_json::json;

use crate::proto::hexinput::parse_frame_text;
use crate::proto::{
    Adu, DecodedPdu, DirectionHint, Mode, Pdu, PduDecode, Request, decode_pdu, pair_findings, parse_adu,
};
use crate::report::{FrameView, jsonl, text};

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Text,
    Jsonl,
}

/// How the run went, for the exit status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Outcome {
    /// Every frame decoded and passed its check.
    Clean = 0,
    /// Every input was a frame, but a check failed or a PDU did not fit its function code.
    Problems = 1,
    /// Some input could not be read as a frame at all.
    Unreadable = 2,
}

/// One input that became a frame.
#[derive(Debug)]
struct Input {
    /// 1-based position among the inputs, for messages.
    number: usize,
    wire: Vec<u8>,
    adu: Adu,
}

/// Decodes `lines` (one frame each) and writes the result to `out`; unreadable lines are
/// reported on `err` (text) or as `"event":"error"` objects (JSON lines).
///
/// # Errors
/// Only I/O errors writing the output.
pub fn run(
    lines: &[String],
    mode: Option<Mode>,
    format: Format,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> io::Result<Outcome> {
    run_with_profiles(lines, mode, format, &Profiles::new(), crate::profile::annotate::Lang::En, out, err)
}

pub use crate::profile::Profiles;

/// As [`run`], annotating the values of transactions of units that have a profile.
///
/// # Errors
/// Only I/O errors writing the output.
pub fn run_with_profiles(
    lines: &[String],
    mode: Option<Mode>,
    format: Format,
    profiles: &Profiles,
    lang: crate::profile::annotate::Lang,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> io::Result<Outcome> {
    let mut outcome = Outcome::Clean;
    // Unreadable lines stay in the sequence (as `Err`) so output keeps the input's order.
    let mut entries: Vec<Result<Input, (usize, String)>> = Vec::with_capacity(lines.len());
    for (i, line) in lines.iter().enumerate() {
        let number = i + 1;
        let parsed = parse_frame_text(line)
            .map_err(|e| e.to_string())
            .and_then(|wire| parse_adu(&wire, mode).map(|adu| (wire, adu)).map_err(|e| e.to_string()));
        entries.push(parsed.map(|(wire, adu)| Input { number, wire, adu }).map_err(|reason| (number, reason)));
    }
    let decodes: Vec<Option<PduDecode<'_>>> =
        entries.iter().map(|e| e.as_ref().ok().map(|i| decode_pdu(&i.adu.pdu, DirectionHint::Unknown))).collect();
    let mut i = 0;
    while i < entries.len() {
        let (this, decode) = match (&entries[i], &decodes[i]) {
            (Ok(this), Some(decode)) => (this, decode),
            (Err((number, reason)), _) => {
                outcome = Outcome::Unreadable;
                let shown = lines[number - 1].trim();
                match format {
                    Format::Text => writeln!(err, "mbtap: input {number} ({shown:?}) is not a frame: {reason}")?,
                    Format::Jsonl => {
                        writeln!(
                            out,
                            "{}",
                            json!({"event": "error", "input": number, "text": shown, "message": reason})
                        )?;
                    }
                }
                i += 1;
                continue;
            }
            // `decodes[i]` is `Some` exactly when `entries[i]` is `Ok`; nothing to show otherwise.
            (Ok(_), None) => {
                i += 1;
                continue;
            }
        };
        if !this.adu.check.ok() {
            outcome = outcome.max(Outcome::Problems);
        }
        if let Some(Ok(next)) = entries.get(i + 1)
            && let Some((req, req_decoded)) = request_reading(decode)
            && answers(&this.adu, &req, &next.adu)
        {
            if !next.adu.check.ok() {
                outcome = outcome.max(Outcome::Problems);
            }
            let resp = decode_pdu(&next.adu.pdu, DirectionHint::Response);
            let req_decode = PduDecode::One(req_decoded.clone());
            let annotations = match (profiles.get(&this.adu.unit), &resp) {
                (Some(p), PduDecode::One(DecodedPdu { pdu: Pdu::Response(r), .. })) => {
                    crate::profile::transaction::annotate_transaction(p, &req, Some(r))
                }
                _ => Vec::new(),
            };
            transaction(this, &req_decode, &req, next, &resp, &annotations, lang, format, out)?;
            i += 2;
            continue;
        }
        if matches!(decode, PduDecode::Malformed { .. }) {
            outcome = outcome.max(Outcome::Problems);
        }
        let view = FrameView { wire: &this.wire, adu: &this.adu, decode, request: None };
        match format {
            Format::Text => writeln!(out, "{}", text::frame(&view, ""))?,
            Format::Jsonl => {
                let mut j = serde_json::Map::new();
                j.insert("event".into(), json!("frame"));
                j.insert("input".into(), json!(this.number));
                if let serde_json::Value::Object(m) = jsonl::frame(&view) {
                    j.extend(m);
                }
                writeln!(out, "{}", serde_json::Value::Object(j))?;
            }
        }
        i += 1;
    }
    Ok(outcome)
}

/// The request reading of a decode, when it has no trailing bytes.
fn request_reading<'d, 'a>(d: &'d PduDecode<'a>) -> Option<(Request<'a>, &'d DecodedPdu<'a>)> {
    let reading = match d {
        PduDecode::One(x) | PduDecode::Either { request: x, .. } => x,
        PduDecode::Malformed { .. } => return None,
    };
    match reading.pdu {
        Pdu::Request(r) if reading.trailing.is_empty() => Some((r, reading)),
        _ => None,
    }
}

/// Does `resp` read as the answer to `req`: same mode and unit (and transaction id on TCP),
/// the same function or its exception, and a response reading with nothing left over.
fn answers(req_adu: &Adu, req: &Request<'_>, resp: &Adu) -> bool {
    let Some(&fc) = resp.pdu.first() else { return false };
    req_adu.mode == resp.mode
        && req_adu.unit == resp.unit
        && req_adu.transaction_id == resp.transaction_id
        && fc & 0x7F == req.function_byte()
        && matches!(decode_pdu(&resp.pdu, DirectionHint::Response), PduDecode::One(DecodedPdu { trailing: [], .. }))
}

#[allow(clippy::too_many_arguments)]
fn transaction(
    req_in: &Input,
    req_decode: &PduDecode<'_>,
    req: &Request<'_>,
    resp_in: &Input,
    resp_decode: &PduDecode<'_>,
    annotations: &[crate::profile::annotate::Annotation],
    lang: crate::profile::annotate::Lang,
    format: Format,
    out: &mut dyn Write,
) -> io::Result<()> {
    let req_view = FrameView { wire: &req_in.wire, adu: &req_in.adu, decode: req_decode, request: None };
    let resp_view = FrameView { wire: &resp_in.wire, adu: &resp_in.adu, decode: resp_decode, request: Some(req) };
    let pair = match resp_decode {
        PduDecode::One(DecodedPdu { pdu: Pdu::Response(r), .. }) => pair_findings(req, r),
        _ => Vec::new(),
    };
    match format {
        Format::Text => {
            writeln!(out, "transaction: unit {} · {}", req_in.adu.unit, req.function())?;
            write!(out, "{}", text::frame(&req_view, "  "))?;
            write!(out, "{}", text::frame(&resp_view, "  "))?;
            write!(out, "{}", text::pair_findings(&pair, ""))?;
            if !annotations.is_empty() {
                writeln!(out, "  values:")?;
                for a in annotations {
                    writeln!(out, "    {}", a.line(lang))?;
                }
            }
            writeln!(out)?;
        }
        Format::Jsonl => {
            let j = json!({
                "event": "transaction",
                "inputs": [req_in.number, resp_in.number],
                "unit": req_in.adu.unit,
                "function": req.function_byte(),
                "request": jsonl::frame(&req_view),
                "response": jsonl::frame(&resp_view),
                "findings": jsonl::findings(&pair),
                "annotations": annotations.iter().map(crate::report::annotations::json).collect::<Vec<_>>(),
            });
            writeln!(out, "{j}")?;
        }
    }
    Ok(())
}
