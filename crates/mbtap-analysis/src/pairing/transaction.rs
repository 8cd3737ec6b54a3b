//! What pairing hands on: a transaction (a request with its answer, or why it has none), how
//! it ended, and the latency it may show.

use crate::chunk::Timestamp;

/// How a transaction ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// A normal response.
    Ok,
    /// An exception response with this code.
    Exception(u8),
    /// No response before the timeout or before the next request.
    NoResponse,
    /// A broadcast (unit 0): no response is expected.
    Broadcast,
    /// The response failed its CRC check.
    BadResponse,
    /// A response with nothing pending that it answers.
    Orphan,
    /// A response from a unit other than the one asked.
    WrongUnit(u8),
}

impl Outcome {
    /// A stable snake_case name.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Exception(_) => "exception",
            Self::NoResponse => "no_response",
            Self::Broadcast => "broadcast",
            Self::BadResponse => "bad_response",
            Self::Orphan => "orphan_response",
            Self::WrongUnit(_) => "wrong_unit",
        }
    }
}

/// A completed (or abandoned) transaction, borrowing its frames (RTU, as on the wire) for the
/// duration of the callback: pairing allocates nothing per transaction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transaction<'a> {
    pub outcome: Outcome,
    pub unit: u8,
    /// The function code of the request (or of the orphan response).
    pub function: u8,
    pub request: Option<&'a [u8]>,
    pub response: Option<&'a [u8]>,
    /// The request's PDU, as the framer decoded it (no one splits the wire bytes again).
    pub request_pdu: Option<&'a [u8]>,
    /// The response's PDU when its check passed (a damaged answer's bytes carry no values).
    pub response_pdu: Option<&'a [u8]>,
    /// Start of the first frame.
    pub t_start: Timestamp,
    /// End of the request to start of the response; `None` without one, or when the reads'
    /// timing cannot resolve it (request and answer delivered in one read).
    pub latency_ns: Option<u64>,
    /// What the reads of the answer resolve (its frame's `resolution_ns`; 0: exact): a
    /// latency below it is no measurement ([`Transaction::shown_latency`]).
    pub latency_resolution_ns: u64,
    /// The input ended (end of file, the sniffer stopped) while this request still waited:
    /// "no response" only as far as anyone heard — the answer may have come.
    pub input_ended: bool,
}

/// A transaction's latency as every output shows it — text, JSON lines and the terminal UI
/// decide by this one rule ("latency 0.000 ms" beside rows saying "not measurable").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShownLatency {
    /// Measured: at least what the reads resolve, and above zero.
    Measured(u64),
    /// Shorter than what the reads resolve (ns): only "under" that can be said.
    Under(u64),
    /// The answer came in one read with the request: its start is not known.
    OneRead,
    /// The reads place the answer's start right at the request's end: a latency of 0 is no
    /// device's, it is where the reads' timing ran out.
    NotMeasurable,
    /// No answer to measure.
    None,
}

impl Transaction<'_> {
    /// The latency as it may be shown.
    #[must_use]
    pub fn shown_latency(&self) -> ShownLatency {
        let answered = self.response.is_some() && matches!(self.outcome, Outcome::Ok | Outcome::Exception(_));
        match self.latency_ns {
            Some(l) if l > 0 && l >= self.latency_resolution_ns => ShownLatency::Measured(l),
            Some(_) if self.latency_resolution_ns > 0 => ShownLatency::Under(self.latency_resolution_ns),
            Some(_) if answered => ShownLatency::NotMeasurable,
            None if answered => ShownLatency::OneRead,
            _ => ShownLatency::None,
        }
    }
}
