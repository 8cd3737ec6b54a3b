//! A pasted request and the response after it, as one transaction: whether the response answers
//! the request, a response cut short said with what its byte count needed, and the pair checked.

use super::{Format, Input};
use crate::report::format::printable;
use crate::report::{FrameView, jsonl, text};
use mbtap_proto::{Adu, DecodedPdu, DirectionHint, Mode, Pdu, PduDecode, Request, decode_pdu, pair_findings};
use serde_json::json;
use std::io::{self, Write};

/// A response cut short: what its own byte count says the frame needed, and what came.
#[derive(Debug, Clone, Copy)]
pub(super) struct Cut {
    pub(super) function: u8,
    pub(super) byte_count: u8,
    pub(super) expected: usize,
    pub(super) received: usize,
}

/// The other reading of an RTU frame whose CRC failed and that was read as a request: a
/// response whose byte count (MAP v1.1b3 §6.1–§6.4: the third byte) asks for more bytes than
/// came — what a read cut by the adapter or a lost tail looks like. `replay` calls such bytes a
/// bad response; `decode`, without the request before it, cannot choose, so it says both.
pub(super) fn truncated_response(input: &Input, decode: &PduDecode<'_>) -> Option<Cut> {
    let is_request = matches!(decode, PduDecode::One(DecodedPdu { pdu: Pdu::Request(_), .. }));
    if input.adu.mode != Mode::Rtu || input.adu.check.ok() || input.hint == DirectionHint::Request || !is_request {
        return None;
    }
    // The bytes after the unit, the supposed CRC included: a response prefix.
    let body = input.wire.get(1..)?;
    let (&function, &byte_count) = (body.first()?, body.get(1)?);
    if !matches!(function, 0x01..=0x04) {
        return None;
    }
    let mbtap_proto::PduLength::Exact(pdu) = mbtap_proto::response_len(body) else { return None };
    // Unit + PDU + CRC (Serial Line v1.02 §2.5.1).
    let expected = pdu.checked_add(3)?;
    (expected > input.wire.len()).then_some(Cut { function, byte_count, expected, received: input.wire.len() })
}

/// The request reading of a decode, when it has no trailing bytes.
pub(super) fn request_reading<'d, 'a>(d: &'d PduDecode<'a>) -> Option<(Request<'a>, &'d DecodedPdu<'a>)> {
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
/// the same function or its exception, and a response reading with nothing left over — or,
/// failing its check, the damaged or truncated answer a replay would call a bad response.
pub(super) fn answers(req_adu: &Adu, req: &Request<'_>, resp: &Adu) -> bool {
    let Some(&fc) = resp.pdu.first() else { return false };
    req_adu.mode == resp.mode
        && req_adu.unit == resp.unit
        && req_adu.transaction_id == resp.transaction_id
        && fc & 0x7F == req.function_byte()
        && req_adu.check.ok()
        && (!resp.check.ok()
            || matches!(
                decode_pdu(&resp.pdu, DirectionHint::Response),
                PduDecode::One(DecodedPdu { trailing: [], .. })
            ))
}

#[allow(clippy::too_many_arguments)]
pub(super) fn transaction(
    req_in: &Input,
    req_decode: &PduDecode<'_>,
    req: &Request<'_>,
    resp_in: &Input,
    resp_decode: &PduDecode<'_>,
    annotations: &[mbtap_device::profile::annotate::Annotation],
    lang: mbtap_device::profile::annotate::Lang,
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
            write!(out, "{}", printable(&text::frame(&req_view, "  ")))?;
            write!(out, "{}", printable(&text::frame(&resp_view, "  ")))?;
            write!(out, "{}", text::pair_findings(&pair, ""))?;
            if !annotations.is_empty() {
                writeln!(out, "  values:")?;
                for a in annotations {
                    writeln!(out, "    {}", printable(&a.line(lang)))?;
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
