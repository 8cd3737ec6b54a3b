//! Pairing on a half-duplex bus: each request with the response that answers it.
//!
//! The bus carries one transaction at a time (Modbus over Serial Line v1.02 §2.1: the master
//! "initiates only one MODBUS transaction at the same time"), so a frame is a response when it
//! answers the pending request — same unit, same function or its exception, and a response
//! structure — and a request otherwise. What does not fit is reported as what it is: an
//! orphan response, a response from another unit, a request that got no answer.
//!
//! One exception to "one at a time": a request that arrives while another still waits for its
//! answer does not end the waiting one at once. The earlier request is kept, *overtaken*, until
//! the newer one is answered, another request comes, or its time runs out — so a second master
//! on the line, or an answer that comes after its master gave up, still pairs with the request
//! it answers (the health report tells the two apart, [`crate::health`]).

use crate::chunk::{PortId, Timestamp};
use crate::framer::Frame;
use mbtap_proto::{DirectionHint, EXCEPTION_FLAG, parse_request, parse_response};

mod transaction;
pub use transaction::{Outcome, ShownLatency, Transaction};

/// Longest frame on the wire (an ASCII frame: 513 characters, Modbus over Serial Line v1.02
/// §2.5.2.1); request copies are kept in a fixed buffer of this size.
const MAX: usize = 513;
/// The longest PDU: 253 bytes (MAP v1.1b3 §4.1).
const MAX_PDU: usize = 253;

/// Pairing settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PairingConfig {
    /// How long after a request its response may start. The serial-line spec leaves the
    /// response timeout to the implementation (Modbus over Serial Line v1.02 §2.4.1); 1 s is
    /// the common master default.
    pub timeout_ns: u64,
    /// Port that carries only requests (a 4-wire or two-port tap), if any.
    pub request_port: Option<PortId>,
    /// Port that carries only responses, if any.
    pub response_port: Option<PortId>,
}

impl Default for PairingConfig {
    fn default() -> Self {
        Self { timeout_ns: 1_000_000_000, request_port: None, response_port: None }
    }
}

#[derive(Debug, Clone)]
struct Pending {
    bytes: [u8; MAX],
    len: usize,
    pdu: [u8; MAX_PDU],
    pdu_len: usize,
    unit: u8,
    function: u8,
    t_start: Timestamp,
    t_end: Timestamp,
}

/// The pairing state machine.
#[derive(Debug, Clone, Default)]
pub struct Pairing {
    config: PairingConfig,
    pending: Option<Box<Pending>>,
    /// A request that another request followed before it was answered.
    overtaken: Option<Box<Pending>>,
    spare: Option<Box<Pending>>,
}

enum Decision {
    Unknown,
    Request,
    Answers(Outcome),
    /// Answers the overtaken request.
    AnswersOvertaken(Outcome),
    Orphan,
}

impl Pending {
    const EMPTY: Self = Self {
        bytes: [0; MAX],
        len: 0,
        pdu: [0; MAX_PDU],
        pdu_len: 0,
        unit: 0,
        function: 0,
        t_start: Timestamp(0),
        t_end: Timestamp(0),
    };
}

/// What pairing decided about one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Request,
    Response,
    /// A failed check or bytes that fit neither reading.
    Unknown,
}

impl Pairing {
    #[must_use]
    pub fn new(config: PairingConfig) -> Self {
        Self { config, pending: None, overtaken: None, spare: None }
    }

    fn role_hint(&self, port: PortId) -> DirectionHint {
        if self.config.request_port == Some(port) {
            DirectionHint::Request
        } else if self.config.response_port == Some(port) {
            DirectionHint::Response
        } else {
            DirectionHint::Unknown
        }
    }

    /// What a frame is, given the pending request. Pure: `frame` acts on it.
    fn decide(&self, f: &Frame<'_>, unit: u8, pdu: &[u8]) -> Decision {
        let hint = self.role_hint(f.port);
        let Some(&fc) = pdu.first() else { return Decision::Unknown };
        if !f.check_ok {
            // A damaged frame right after a request is most likely its response.
            return if hint != DirectionHint::Request && self.pending.is_some() {
                Decision::Answers(Outcome::BadResponse)
            } else {
                Decision::Unknown
            };
        }
        let base = fc & !EXCEPTION_FLAG;
        let answers = |p: &Option<Box<Pending>>| {
            p.as_ref().is_some_and(|p| p.unit == unit && p.function == base && hint != DirectionHint::Request)
                && clean(pdu, DirectionHint::Response)
        };
        let outcome = || {
            if fc & EXCEPTION_FLAG != 0 { Outcome::Exception(pdu.get(1).copied().unwrap_or(0)) } else { Outcome::Ok }
        };
        if answers(&self.pending) {
            return Decision::Answers(outcome());
        }
        if answers(&self.overtaken) {
            return Decision::AnswersOvertaken(outcome());
        }
        if hint != DirectionHint::Response && fc & EXCEPTION_FLAG == 0 && clean(pdu, DirectionHint::Request) {
            return Decision::Request;
        }
        match &self.pending {
            Some(p) if p.unit != unit && p.function == base => Decision::Answers(Outcome::WrongUnit(unit)),
            _ => Decision::Orphan,
        }
    }

    /// The role pairing will give a frame, without changing state (to show the frame before
    /// the transaction it completes).
    #[must_use]
    pub fn role_of(&self, f: &Frame<'_>, unit: u8, pdu: &[u8]) -> Role {
        match self.decide(f, unit, pdu) {
            Decision::Unknown => Role::Unknown,
            Decision::Request => Role::Request,
            Decision::Answers(_) | Decision::AnswersOvertaken(_) | Decision::Orphan => Role::Response,
        }
    }

    /// Feeds one frame with its unit and PDU (`None` when too short to have them); emits
    /// finished transactions; returns the role given to the frame.
    pub fn frame<F: FnMut(Transaction<'_>)>(
        &mut self,
        f: &Frame<'_>,
        decoded: Option<(u8, &[u8])>,
        emit: &mut F,
    ) -> Role {
        self.frame_then(f, decoded, |_| {}, emit)
    }

    /// As [`Self::frame`], calling `on_role` with the frame's role before any transaction the
    /// frame completes is emitted (so a frame can be shown before its transaction), and after
    /// transactions that time ran out on.
    pub fn frame_then<F: FnMut(Transaction<'_>)>(
        &mut self,
        f: &Frame<'_>,
        decoded: Option<(u8, &[u8])>,
        on_role: impl FnOnce(Role),
        emit: &mut F,
    ) -> Role {
        self.tick(f.t_start, emit);
        let Some((unit, pdu)) = decoded else {
            on_role(Role::Unknown);
            return Role::Unknown;
        };
        let decision = self.decide(f, unit, pdu);
        on_role(match decision {
            Decision::Unknown => Role::Unknown,
            Decision::Request => Role::Request,
            Decision::Answers(_) | Decision::AnswersOvertaken(_) | Decision::Orphan => Role::Response,
        });
        match decision {
            Decision::Unknown => Role::Unknown,
            Decision::Answers(outcome) => {
                // The newer request is answered: the overtaken one will not be.
                self.give_up_overtaken(emit);
                if let Some(p) = self.pending.take() {
                    emit(Self::finish(&p, outcome, Some((f, pdu))));
                    self.spare = Some(p);
                }
                Role::Response
            }
            Decision::AnswersOvertaken(outcome) => {
                if let Some(p) = self.overtaken.take() {
                    emit(Self::finish(&p, outcome, Some((f, pdu))));
                    self.spare = Some(p);
                }
                Role::Response
            }
            Decision::Request => {
                self.give_up_overtaken(emit);
                self.overtaken = self.pending.take();
                let fc = pdu.first().copied().unwrap_or(0);
                if unit == 0 {
                    emit(Transaction {
                        outcome: Outcome::Broadcast,
                        unit: 0,
                        function: fc,
                        request: Some(f.bytes),
                        response: None,
                        request_pdu: Some(pdu),
                        response_pdu: None,
                        t_start: f.t_start,
                        latency_ns: None,
                        latency_resolution_ns: 0,
                        input_ended: false,
                    });
                } else {
                    // Reuse the pending box's allocation from one request to the next.
                    let mut p = self.spare.take().unwrap_or_else(|| Box::new(Pending::EMPTY));
                    let len = f.bytes.len().min(MAX);
                    p.bytes[..len].copy_from_slice(&f.bytes[..len]);
                    p.len = len;
                    let pdu_len = pdu.len().min(MAX_PDU);
                    p.pdu[..pdu_len].copy_from_slice(&pdu[..pdu_len]);
                    p.pdu_len = pdu_len;
                    p.unit = unit;
                    p.function = fc;
                    p.t_start = f.t_start;
                    p.t_end = f.t_end;
                    self.pending = Some(p);
                }
                Role::Request
            }
            Decision::Orphan => {
                let fc = pdu.first().copied().unwrap_or(0);
                emit(Transaction {
                    outcome: Outcome::Orphan,
                    unit,
                    function: fc & !EXCEPTION_FLAG,
                    request: None,
                    response: Some(f.bytes),
                    request_pdu: None,
                    response_pdu: f.check_ok.then_some(pdu),
                    t_start: f.t_start,
                    latency_ns: None,
                    latency_resolution_ns: 0,
                    input_ended: false,
                });
                Role::Response
            }
        }
    }

    /// The overtaken request got no response.
    fn give_up_overtaken<F: FnMut(Transaction<'_>)>(&mut self, emit: &mut F) {
        if let Some(p) = self.overtaken.take() {
            emit(Self::finish(&p, Outcome::NoResponse, None));
            self.spare = Some(p);
        }
    }

    /// The time is `now`: a request pending longer than the timeout got no response.
    pub fn tick<F: FnMut(Transaction<'_>)>(&mut self, now: Timestamp, emit: &mut F) {
        if self.overtaken.as_ref().is_some_and(|p| now.since(p.t_end) > self.config.timeout_ns) {
            self.give_up_overtaken(emit);
        }
        if let Some(p) = &self.pending
            && now.since(p.t_end) > self.config.timeout_ns
            && let Some(p) = self.pending.take()
        {
            emit(Self::finish(&p, Outcome::NoResponse, None));
            self.spare = Some(p);
        }
    }

    /// End of input: a waiting request got no response as far as anyone heard.
    pub fn finish_all<F: FnMut(Transaction<'_>)>(&mut self, emit: &mut F) {
        for p in [self.overtaken.take(), self.pending.take()].into_iter().flatten() {
            emit(Transaction { input_ended: true, ..Self::finish(&p, Outcome::NoResponse, None) });
        }
    }

    #[inline]
    fn finish<'a>(p: &'a Pending, outcome: Outcome, response: Option<(&Frame<'a>, &'a [u8])>) -> Transaction<'a> {
        let response_pdu = response.filter(|(f, _)| f.check_ok).map(|(_, pdu)| pdu);
        let response = response.map(|(f, _)| f);
        Transaction {
            outcome,
            unit: p.unit,
            function: p.function,
            request: Some(&p.bytes[..p.len]),
            response: response.map(|f| f.bytes),
            request_pdu: Some(&p.pdu[..p.pdu_len]),
            response_pdu,
            t_start: p.t_start,
            // Not measurable when the answer began inside a read: its start time is a guess.
            latency_ns: response.filter(|f| f.gap_before_known).map(|f| f.t_start.since(p.t_end)),
            latency_resolution_ns: response.map_or(0, |f| f.resolution_ns),
            input_ended: false,
        }
    }
}

/// Does the PDU read cleanly (no trailing bytes) in this direction?
fn clean(pdu: &[u8], hint: DirectionHint) -> bool {
    match hint {
        DirectionHint::Request => matches!(parse_request(pdu), Ok(([], _))),
        DirectionHint::Response => matches!(parse_response(pdu), Ok(([], _))),
        DirectionHint::Unknown => clean(pdu, DirectionHint::Request) || clean(pdu, DirectionHint::Response),
    }
}

#[cfg(test)]
mod tests {

    /// A latency is shown only where it is above zero and at least what the reads resolve, else its
    /// bound or "not measurable" — never "latency 0.000 ms" beside "not measurable"; one rule for
    /// text, JSON and the terminal UI.
    #[test]
    fn a_latency_is_shown_only_where_the_reads_resolve_it() {
        const RESPONSE: &[u8] = &[0x01, 0x03, 0x02, 0x00, 0x07];
        let t = |latency_ns, latency_resolution_ns| Transaction {
            outcome: Outcome::Ok,
            unit: 1,
            function: 3,
            request: None,
            response: Some(RESPONSE),
            request_pdu: None,
            response_pdu: None,
            t_start: Timestamp(0),
            latency_ns,
            latency_resolution_ns,
            input_ended: false,
        };
        assert_eq!(t(Some(5_000_000), 0).shown_latency(), ShownLatency::Measured(5_000_000));
        assert_eq!(t(Some(5_000_000), 1_400_000).shown_latency(), ShownLatency::Measured(5_000_000));
        assert_eq!(t(Some(8_000_000), 17_000_000).shown_latency(), ShownLatency::Under(17_000_000));
        assert_eq!(t(Some(0), 0).shown_latency(), ShownLatency::NotMeasurable);
        assert_eq!(t(None, 0).shown_latency(), ShownLatency::OneRead);
        assert_eq!(Transaction { response: None, ..t(None, 0) }.shown_latency(), ShownLatency::None);
    }
    use super::*;

    /// Read holding register 100 (function 03, address 0x0064, quantity 1), RTU with CRC.
    fn ask(unit: u8) -> Vec<u8> {
        let mut out = Vec::new();
        mbtap_proto::encode_rtu(unit, &[0x03, 0x00, 0x64, 0x00, 0x01], &mut out);
        out
    }

    /// Its answer: byte count 2, value 7.
    fn answer(unit: u8) -> Vec<u8> {
        let mut out = Vec::new();
        mbtap_proto::encode_rtu(unit, &[0x03, 0x02, 0x00, 0x07], &mut out);
        out
    }

    /// A frame of `bytes` starting at `ms`, one millisecond long, its check as given.
    fn frame_at(bytes: &[u8], ms: u64, check_ok: bool) -> Frame<'_> {
        Frame {
            port: PortId(0),
            bytes,
            t_start: Timestamp(ms * 1_000_000),
            t_end: Timestamp((ms + 1) * 1_000_000),
            check_ok,
            gap_violation_ns: None,
            short_gap_before_ns: None,
            gap_tolerance_ns: None,
            short_gap_tolerance_ns: None,
            resolution_ns: 0,
            gap_before_known: true,
            bad_chars: false,
            alt_len: None,
        }
    }

    /// Feeds `(start ms, bytes)` frames; the transactions as (unit, outcome, latency ms).
    fn pair(frames: &[(u64, Vec<u8>)], end_ms: u64) -> Vec<(u8, Outcome, Option<u64>)> {
        let mut p = Pairing::new(PairingConfig::default());
        let mut out = Vec::new();
        let mut emit = |t: Transaction<'_>| out.push((t.unit, t.outcome, t.latency_ns.map(|l| l / 1_000_000)));
        for (ms, bytes) in frames {
            let f = frame_at(bytes, *ms, true);
            let len = bytes.len().saturating_sub(2);
            p.frame(&f, Some((bytes[0], &bytes[1..len])), &mut emit);
        }
        p.tick(Timestamp(end_ms * 1_000_000), &mut emit);
        out
    }

    #[test]
    fn a_second_masters_request_does_not_cost_the_first_its_answer() {
        // Unit 1 asked; another master asks unit 5; unit 1 answers, then unit 5.
        let tx = pair(&[(0, ask(1)), (3, ask(5)), (10, answer(1)), (15, answer(5))], 20);
        assert_eq!(tx, [(1, Outcome::Ok, Some(9)), (5, Outcome::Ok, Some(11))]);
    }

    #[test]
    fn an_overtaken_request_gives_up_when_the_newer_one_is_answered() {
        let tx = pair(&[(0, ask(9)), (100, ask(1)), (105, answer(1))], 110);
        assert_eq!(tx, [(9, Outcome::NoResponse, None), (1, Outcome::Ok, Some(4))]);
    }

    #[test]
    fn overtaken_and_pending_both_time_out_oldest_first() {
        let tx = pair(&[(0, ask(9)), (100, ask(8))], 5_000);
        assert_eq!(tx, [(9, Outcome::NoResponse, None), (8, Outcome::NoResponse, None)]);
    }

    #[test]
    fn a_third_request_gives_up_the_overtaken_one() {
        let tx = pair(&[(0, ask(9)), (100, ask(8)), (200, ask(1)), (205, answer(1))], 210);
        assert_eq!(tx, [(9, Outcome::NoResponse, None), (8, Outcome::NoResponse, None), (1, Outcome::Ok, Some(4))]);
    }

    /// A transaction carries its frames' PDUs as the framer decoded them, so no
    /// consumer splits the wire bytes again; a damaged answer's PDU is not handed on as values.
    #[test]
    fn transactions_carry_their_pdus_and_a_damaged_answer_none() {
        let (req, resp) = (ask(1), answer(1));
        for check_ok in [true, false] {
            let mut p = Pairing::new(PairingConfig::default());
            let mut got = Vec::new();
            let mut emit = |t: Transaction<'_>| {
                got.push((t.request_pdu.map(<[u8]>::to_vec), t.response_pdu.map(<[u8]>::to_vec), t.outcome));
            };
            p.frame(&frame_at(&req, 0, true), Some((1, &req[1..req.len() - 2])), &mut emit);
            p.frame(&frame_at(&resp, 10, check_ok), Some((1, &resp[1..resp.len() - 2])), &mut emit);
            let want_resp = check_ok.then(|| vec![0x03, 0x02, 0x00, 0x07]);
            let outcome = if check_ok { Outcome::Ok } else { Outcome::BadResponse };
            assert_eq!(got, [(Some(vec![0x03, 0x00, 0x64, 0x00, 0x01]), want_resp, outcome)]);
        }
    }
}
