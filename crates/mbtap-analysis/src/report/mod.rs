//! Rendering decoded frames and transactions for people (text) and programs (JSON lines).
//! Both renderers read the same [`FrameView`] and the same field list ([`fields`]).
//!
//! Modules: `fields` (the field list both renderers read), `format` (times and hex dumps every
//! output shares), `events` (analyzer events as text and JSON lines), `jsonl` (JSON lines with
//! stable keys), `annotations` (profile annotations as JSON).

pub mod annotations;
pub mod events;
pub mod fields;
pub mod format;
pub mod jsonl;
pub mod text;

use mbtap_proto::{Adu, DecodedPdu, Finding, Pdu, PduDecode, Request};

/// Everything known about one frame, borrowed from where it lives.
#[derive(Debug, Clone, Copy)]
pub struct FrameView<'a> {
    /// The bytes as on the wire (ASCII: its characters).
    pub wire: &'a [u8],
    pub adu: &'a Adu,
    pub decode: &'a PduDecode<'a>,
    /// The request this frame answers, when it was paired.
    pub request: Option<&'a Request<'a>>,
}

impl FrameView<'_> {
    /// The reading to show: the only one, or the request reading of an echo-shaped frame.
    #[must_use]
    pub fn primary(&self) -> Option<&DecodedPdu<'_>> {
        match self.decode {
            PduDecode::One(d) => Some(d),
            PduDecode::Either { request, .. } => Some(request),
            PduDecode::Malformed { .. } => None,
        }
    }

    /// "request", "response", "request_or_response" or "unknown".
    #[must_use]
    pub fn direction(&self) -> &'static str {
        match self.decode {
            PduDecode::One(DecodedPdu { pdu: Pdu::Request(_), .. }) => "request",
            PduDecode::One(DecodedPdu { pdu: Pdu::Response(_), .. }) => "response",
            PduDecode::Either { .. } => "request_or_response",
            PduDecode::Malformed { .. } => "unknown",
        }
    }

    /// Every finding: framing, unit address, PDU.
    #[must_use]
    pub fn findings(&self) -> Vec<Finding> {
        let mut all = self.adu.findings.clone();
        if self.adu.mode != mbtap_proto::Mode::Tcp {
            mbtap_proto::findings::check_unit(self.adu.unit, self.direction() == "response", &mut all);
        }
        if let Some(d) = self.primary() {
            all.extend_from_slice(&d.findings);
        }
        all
    }

    /// The function byte as on the wire.
    #[must_use]
    pub fn function_byte(&self) -> Option<u8> {
        self.adu.pdu.first().copied()
    }
}
