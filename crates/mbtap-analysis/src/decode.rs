//! Frames given as hex or ASCII text, explained (the work of `mbtap decode`). A request followed by the
//! response that answers it is shown as one transaction.
//!
//! An RTU line that is not exactly one frame — frames pasted glued together from a sniffer log,
//! a frame with the turnaround glitch byte a logic analyser caught after it — is split the way
//! `replay` splits the same bytes: by the RTU framer, which knows each function's structure and
//! the CRC's look-alikes. A failed frame right after a request from the same unit is read as that
//! request's (damaged or truncated) answer.
//!
//! Its `pairs` module reads a pasted request and the response after it as one transaction.

use std::io::{self, Write};

use serde_json::json;

use crate::report::format::printable;
use crate::report::{FrameView, jsonl, text};
use mbtap_proto::hexinput::{Tagged, parse_log_line};
use mbtap_proto::{Adu, DecodedPdu, DirectionHint, Mode, Pdu, PduDecode, decode_pdu, parse_adu};

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Text,
    Jsonl,
}

/// How the run went, for the exit status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum RunStatus {
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
    /// The direction a log's tag gave (`Tx:`/`Rx:`), else unknown.
    hint: DirectionHint,
    /// What the log line held besides the frame: its timestamp and direction tag.
    timestamp: Option<String>,
    tag: Option<String>,
}

/// What an input line holds, piece by piece.
#[derive(Debug)]
enum Entry {
    Frame(Input),
    /// Not a frame at all: the input number, the line as given, and why.
    Unreadable(usize, String, String),
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
    // Units 0 and 248–255 are cut like any other: a pasted line is one device's
    // traffic, often at the "whoever is connected" address 254 or 255.
    let mut framer = RtuFramer::new(PortId(0), FramerConfig { pasted: true, ..FramerConfig::default() });
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
) -> io::Result<RunStatus> {
    run_with_profiles(lines, mode, format, &Profiles::new(), mbtap_device::profile::annotate::Lang::En, out, err)
}

pub use mbtap_device::profile::Profiles;

mod pairs;
use pairs::{answers, request_reading, transaction, truncated_response};

/// As [`run`], annotating the values of transactions of units that have a profile.
///
/// # Errors
/// Only I/O errors writing the output.
pub fn run_with_profiles(
    lines: &[String],
    mode: Option<Mode>,
    format: Format,
    profiles: &Profiles,
    lang: mbtap_device::profile::annotate::Lang,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> io::Result<RunStatus> {
    let mut d = Decoder::new(mode, format, profiles, lang);
    for line in lines {
        d.line(line, out, err)?;
    }
    d.finish(out, err)
}

/// Decodes a stream of lines as they come: one line in, its result out — held back only while
/// a request may still be answered by the next line, so memory stays constant and
/// `tail -f log | mbtap decode` shows each frame at once.
#[derive(Debug)]
pub struct Decoder<'p> {
    mode: Option<Mode>,
    format: Format,
    profiles: &'p Profiles,
    lang: mbtap_device::profile::annotate::Lang,
    status: RunStatus,
    /// Lines read so far (the next one's number is this plus one).
    read: usize,
    /// Pieces not shown yet: at most a request waiting for its answer and what came with it.
    pending: std::collections::VecDeque<Entry>,
}

impl<'p> Decoder<'p> {
    #[must_use]
    pub fn new(
        mode: Option<Mode>,
        format: Format,
        profiles: &'p Profiles,
        lang: mbtap_device::profile::annotate::Lang,
    ) -> Self {
        Self {
            mode,
            format,
            profiles,
            lang,
            status: RunStatus::Clean,
            read: 0,
            pending: std::collections::VecDeque::new(),
        }
    }

    /// Takes one input line and writes what it can decide.
    ///
    /// # Errors
    /// Only I/O errors writing the output.
    pub fn line(&mut self, line: &str, out: &mut dyn Write, err: &mut dyn Write) -> io::Result<()> {
        self.read += 1;
        let number = self.read;
        let shown = line.trim().to_owned();
        match parse_log_line(line) {
            Err(e) => self.pending.push_back(Entry::Unreadable(number, shown, e.to_string())),
            Ok(log) => {
                let hint = match log.tag.as_ref().map(|t| t.1) {
                    Some(Tagged::Request) => DirectionHint::Request,
                    Some(Tagged::Response) => DirectionHint::Response,
                    None => DirectionHint::Unknown,
                };
                let (timestamp, tag) = (log.timestamp, log.tag.map(|t| t.0));
                let wire = log.bytes;
                let adu = parse_adu(&wire, self.mode);
                let rtu = self.mode == Some(Mode::Rtu)
                    || (self.mode.is_none() && adu.as_ref().is_ok_and(|a| a.mode == Mode::Rtu));
                if let Some(pieces) = rtu.then(|| split_rtu(&wire)).flatten() {
                    for piece in pieces {
                        self.pending.push_back(match piece {
                            Piece::Frame(bytes) => match parse_adu(&bytes, Some(Mode::Rtu)) {
                                Ok(adu) => Entry::Frame(Input {
                                    number,
                                    wire: bytes,
                                    adu,
                                    hint,
                                    timestamp: timestamp.clone(),
                                    tag: tag.clone(),
                                }),
                                Err(e) => Entry::Unreadable(number, shown.clone(), e.to_string()),
                            },
                            Piece::Glitch(bytes) => Entry::Glitch(number, bytes),
                            Piece::Noise(bytes) => Entry::Noise(number, bytes),
                        });
                    }
                } else {
                    self.pending.push_back(match adu {
                        Ok(adu) => Entry::Frame(Input { number, wire, adu, hint, timestamp, tag }),
                        Err(e) => Entry::Unreadable(number, shown, e.to_string()),
                    });
                }
            }
        }
        self.drain(false, out, err)
    }

    /// End of input: writes what was held back; the run's status.
    ///
    /// # Errors
    /// Only I/O errors writing the output.
    pub fn finish(mut self, out: &mut dyn Write, err: &mut dyn Write) -> io::Result<RunStatus> {
        self.drain(true, out, err)?;
        Ok(self.status)
    }

    /// Writes every piece that can be decided now: all of them at the end, otherwise all but a
    /// last frame that reads as a request (its answer may be the next line).
    fn drain(&mut self, at_end: bool, out: &mut dyn Write, err: &mut dyn Write) -> io::Result<()> {
        while let Some(front) = self.pending.front() {
            if let Entry::Frame(this) = front
                && self.pending.len() == 1
                && !at_end
                && request_reading(&decode_pdu(&this.adu.pdu, this.hint)).is_some()
            {
                return Ok(());
            }
            let Some(entry) = self.pending.pop_front() else { return Ok(()) };
            self.show(entry, out, err)?;
        }
        Ok(())
    }

    /// Bytes of a line that belong to no frame: a turnaround glitch or noise.
    fn stray(&mut self, number: usize, bytes: &[u8], glitch: bool, out: &mut dyn Write) -> io::Result<()> {
        // Not part of any frame: the line held more than its frames.
        self.status = self.status.max(if glitch { RunStatus::Problems } else { RunStatus::Unreadable });
        let hex = crate::report::format::hex_spaced(bytes);
        match self.format {
            Format::Text if glitch => writeln!(
                out,
                "glitch: {hex} right after the frame — a transceiver's turnaround byte, not part of the frame (missing fail-safe biasing)"
            ),
            Format::Text => writeln!(out, "noise: {hex} ({} byte(s) that belong to no frame)", bytes.len()),
            Format::Jsonl => writeln!(
                out,
                "{}",
                json!({"event": if glitch { "glitch" } else { "noise" }, "input": number, "hex": crate::report::format::hex_compact(bytes), "len": bytes.len()})
            ),
        }
    }

    /// Writes one piece (a frame with the answer after it as one transaction).
    fn show(&mut self, entry: Entry, out: &mut dyn Write, err: &mut dyn Write) -> io::Result<()> {
        let format = self.format;
        let this = match entry {
            Entry::Frame(this) => this,
            Entry::Unreadable(number, shown, reason) => {
                self.status = RunStatus::Unreadable;
                return match format {
                    Format::Text => writeln!(err, "mbtap: input {number} ({shown:?}) is not a frame: {reason}"),
                    Format::Jsonl => writeln!(
                        out,
                        "{}",
                        json!({"event": "error", "input": number, "text": shown, "message": reason})
                    ),
                };
            }
            Entry::Glitch(number, bytes) => return self.stray(number, &bytes, true, out),
            Entry::Noise(number, bytes) => return self.stray(number, &bytes, false, out),
        };
        let decode = decode_pdu(&this.adu.pdu, this.hint);
        if !this.adu.check.ok() {
            self.status = self.status.max(RunStatus::Problems);
        }
        if let Some(Entry::Frame(next)) = self.pending.front()
            && let Some((req, req_decoded)) = request_reading(&decode)
            && answers(&this.adu, &req, &next.adu)
        {
            if !next.adu.check.ok() {
                self.status = self.status.max(RunStatus::Problems);
            }
            let resp = decode_pdu(&next.adu.pdu, DirectionHint::Response);
            let req_decode = PduDecode::One(req_decoded.clone());
            let annotations = match (self.profiles.get(&this.adu.unit), &resp) {
                (Some(p), PduDecode::One(DecodedPdu { pdu: Pdu::Response(r), .. })) => {
                    mbtap_device::profile::transaction::annotate_transaction(p, &req, Some(r))
                }
                _ => Vec::new(),
            };
            transaction(&this, &req_decode, &req, next, &resp, &annotations, self.lang, format, out)?;
            self.pending.pop_front();
            return Ok(());
        }
        if matches!(decode, PduDecode::Malformed { .. }) {
            self.status = self.status.max(RunStatus::Problems);
        }
        let view = FrameView { wire: &this.wire, adu: &this.adu, decode: &decode, request: None };
        let cut = truncated_response(&this, &decode);
        match format {
            Format::Text => {
                let frame = text::frame(&view, "");
                let shown = printable(&frame);
                let Some(c) = cut else { return writeln!(out, "{shown}") };
                writeln!(out, "{}", shown.trim_end_matches('\n'))?;
                writeln!(
                    out,
                    "  or: a truncated response — 0x{:02X} whose byte count ({}) makes the frame {} bytes with its CRC; {} received, {} missing\n",
                    c.function,
                    c.byte_count,
                    c.expected,
                    c.received,
                    c.expected - c.received
                )
            }
            Format::Jsonl => {
                let mut j = serde_json::Map::new();
                j.insert("event".into(), json!("frame"));
                j.insert("input".into(), json!(this.number));
                // What the log line held besides the frame, set aside and shown.
                if let Some(t) = &this.timestamp {
                    j.insert("timestamp".into(), json!(t));
                }
                if let Some(t) = &this.tag {
                    j.insert("tag".into(), json!(t));
                }
                if let serde_json::Value::Object(m) = jsonl::frame(&view) {
                    j.extend(m);
                }
                if let Some(c) = cut {
                    j.insert(
                        "or_truncated_response".into(),
                        json!({"function": c.function, "byte_count": c.byte_count, "expected_len": c.expected, "received_len": c.received}),
                    );
                }
                writeln!(out, "{}", serde_json::Value::Object(j))
            }
        }
    }
}
