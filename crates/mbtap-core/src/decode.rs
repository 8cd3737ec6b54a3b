//! Frames given as hex or ASCII text, explained (the work of `mbtap decode`). A request followed by the
//! response that answers it is shown as one transaction.
//!
//! An RTU line that is not exactly one frame — frames pasted glued together from a sniffer log,
//! a frame with the turnaround glitch byte a logic analyser caught after it — is split the way
//! `replay` splits the same bytes: by the RTU framer, which knows each function's structure and
//! the CRC's look-alikes. A failed frame right after a request from the same unit is read as that
//! request's (damaged or truncated) answer.

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

/// What an input line holds, piece by piece.
#[derive(Debug)]
enum Entry {
    Frame(Input),
    /// Not a frame at all: the input number and why.
    Unreadable(usize, String),
    /// A turnaround glitch byte after a frame (input number, bytes).
    Glitch(usize, Vec<u8>),
    /// Bytes between frames that belong to none (input number, bytes).
    Noise(usize, Vec<u8>),
}

/// A piece of an RTU line as the framer cut it.
#[derive(Debug)]
enum Piece {
    /// A frame, valid or not (its check is shown when it is decoded).
    Frame(Vec<u8>),
    Glitch(Vec<u8>),
    Noise(Vec<u8>),
}

/// The pieces of one RTU line, as the framer cuts the same bytes in a replay: `None` when the
/// line is one frame, or holds no valid frame at all (then it is shown whole, as it always was).
fn split_rtu(wire: &[u8]) -> Option<Vec<Piece>> {
    use crate::chunk::{Chunk, PortId, Timestamp};
    use crate::framer::{FrameEvent, FramerConfig, RtuFramer};
    // Pasted text has no timing: one read, nothing known about silences.
    let mut framer = RtuFramer::new(PortId(0), FramerConfig::default());
    let mut pieces = Vec::new();
    let mut valid = 0usize;
    let mut emit = |e: FrameEvent<'_>| {
        pieces.push(match e {
            FrameEvent::Frame(f) => {
                valid += usize::from(f.check_ok);
                Piece::Frame(f.bytes.to_vec())
            }
            FrameEvent::Glitch(n) => Piece::Glitch(n.bytes.to_vec()),
            FrameEvent::Noise(n) => Piece::Noise(n.bytes.to_vec()),
        });
    };
    framer.push(&Chunk { port: PortId(0), t: Timestamp(0), bytes: wire }, &mut emit);
    framer.finish(&mut emit);
    (pieces.len() >= 2 && valid > 0).then_some(pieces)
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
    // Unreadable lines stay in the sequence so output keeps the input's order.
    let mut entries: Vec<Entry> = Vec::with_capacity(lines.len());
    for (i, line) in lines.iter().enumerate() {
        let number = i + 1;
        let wire = match parse_frame_text(line) {
            Ok(wire) => wire,
            Err(e) => {
                entries.push(Entry::Unreadable(number, e.to_string()));
                continue;
            }
        };
        let adu = parse_adu(&wire, mode);
        let rtu = mode == Some(Mode::Rtu) || (mode.is_none() && adu.as_ref().is_ok_and(|a| a.mode == Mode::Rtu));
        if let Some(pieces) = rtu.then(|| split_rtu(&wire)).flatten() {
            for piece in pieces {
                entries.push(match piece {
                    Piece::Frame(bytes) => match parse_adu(&bytes, Some(Mode::Rtu)) {
                        Ok(adu) => Entry::Frame(Input { number, wire: bytes, adu }),
                        Err(e) => Entry::Unreadable(number, e.to_string()),
                    },
                    Piece::Glitch(bytes) => Entry::Glitch(number, bytes),
                    Piece::Noise(bytes) => Entry::Noise(number, bytes),
                });
            }
            continue;
        }
        entries.push(match adu {
            Ok(adu) => Entry::Frame(Input { number, wire, adu }),
            Err(e) => Entry::Unreadable(number, e.to_string()),
        });
    }
    let decodes: Vec<Option<PduDecode<'_>>> = entries
        .iter()
        .map(|e| match e {
            Entry::Frame(i) => Some(decode_pdu(&i.adu.pdu, DirectionHint::Unknown)),
            _ => None,
        })
        .collect();
    let mut i = 0;
    while i < entries.len() {
        let (this, decode) = match (&entries[i], &decodes[i]) {
            (Entry::Frame(this), Some(decode)) => (this, decode),
            (Entry::Unreadable(number, reason), _) => {
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
            (Entry::Glitch(number, bytes) | Entry::Noise(number, bytes), _) => {
                let glitch = matches!(entries[i], Entry::Glitch(..));
                // Not part of any frame: the line held more than its frames.
                outcome = outcome.max(if glitch { Outcome::Problems } else { Outcome::Unreadable });
                let hex = crate::report::format::hex_spaced(bytes);
                match format {
                    Format::Text if glitch => writeln!(
                        out,
                        "glitch: {hex} right after the frame — a transceiver's turnaround byte, not part of the frame (missing fail-safe biasing)"
                    )?,
                    Format::Text => writeln!(out, "noise: {hex} ({} byte(s) that belong to no frame)", bytes.len())?,
                    Format::Jsonl => writeln!(
                        out,
                        "{}",
                        json!({"event": if glitch { "glitch" } else { "noise" }, "input": number, "hex": crate::report::format::hex_compact(bytes), "len": bytes.len()})
                    )?,
                }
                i += 1;
                continue;
            }
            // `decodes[i]` is `Some` exactly for frames; nothing to show otherwise.
            (Entry::Frame(_), None) => {
                i += 1;
                continue;
            }
        };
        if !this.adu.check.ok() {
            outcome = outcome.max(Outcome::Problems);
        }
        if let Some(Entry::Frame(next)) = entries.get(i + 1)
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
/// the same function or its exception, and a response reading with nothing left over — or,
/// failing its check, the damaged or truncated answer a replay would call a bad response.
fn answers(req_adu: &Adu, req: &Request<'_>, resp: &Adu) -> bool {
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
