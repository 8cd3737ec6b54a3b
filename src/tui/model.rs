//! What the terminal UI shows, built from analyzer events: a bounded list of rows (one per
//! transaction or noise burst), per-device statistics, the bus totals and the register image.
//! Pure: no terminal, no clock — the views render it, tests feed it events.

use std::collections::{BTreeMap, VecDeque};

use mbtap_analysis::analyzer::Event;
use mbtap_analysis::framer::LineSettings;
use mbtap_analysis::pairing::Outcome;
use mbtap_device::profile::Profiles;
use mbtap_device::profile::annotate::{Annotation, Lang};

use super::registers::Registers;
use super::stats::{BusStats, DeviceStats};

/// Transactions kept for scroll-back unless told otherwise (a default that holds a busy line's last minutes).
pub const DEFAULT_SCROLLBACK: usize = 100_000;

/// What a row is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    Transaction(Outcome),
    /// Bytes that belong to no frame.
    Noise,
}

/// Timing trouble seen on the frames of a row.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TimingFlags {
    /// A silence longer than t1.5 inside a frame (Serial Line v1.02 §2.5.1.1).
    pub gap_inside: bool,
    /// A frame that followed the previous one after less than t3.5.
    pub short_gap: bool,
    /// A frame whose bytes check at another length too (`Frame::alt_len`: a `00` that may be a
    /// turnaround glitch or its CRC's high byte).
    pub two_lengths: bool,
}

/// One row of the traffic view.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Number of the row since the start (never reused; survives the scroll-back dropping rows).
    pub seq: u64,
    pub t_ns: u64,
    /// Time since the previous row.
    pub delta_ns: Option<u64>,
    pub kind: RowKind,
    pub unit: Option<u8>,
    pub function: Option<u8>,
    /// The frames as on the wire.
    pub request: Option<Box<[u8]>>,
    pub response: Option<Box<[u8]>>,
    pub latency_ns: Option<u64>,
    /// The annotated values (or the request's addresses) in one line.
    pub summary: String,
    pub timing: TimingFlags,
}

impl Row {
    /// Exceptions, timeouts, failed checks, noise, orphans, wrong units and timing trouble.
    #[must_use]
    pub fn is_error(&self) -> bool {
        self.timing != TimingFlags::default()
            || !matches!(self.kind, RowKind::Transaction(Outcome::Ok | Outcome::Broadcast))
    }

    /// Status for a narrow column: `ok`, `exc 0x02`, `timeout`, `bad crc`, `noise`, ….
    #[must_use]
    pub fn label(&self) -> String {
        match self.kind {
            RowKind::Transaction(Outcome::Ok) => "ok".into(),
            RowKind::Transaction(Outcome::Exception(code)) => format!("exc 0x{code:02X}"),
            RowKind::Transaction(Outcome::NoResponse) => "timeout".into(),
            RowKind::Transaction(Outcome::Broadcast) => "broadcast".into(),
            // A failed CRC (RTU) or LRC (ASCII).
            RowKind::Transaction(Outcome::BadResponse) => "bad check".into(),
            RowKind::Transaction(Outcome::Orphan) => "orphan".into(),
            RowKind::Transaction(Outcome::WrongUnit(u)) => format!("from {u}"),
            RowKind::Noise => "noise".into(),
        }
    }

    /// Status as a word: the outcome's name, or `noise`.
    #[must_use]
    pub fn status(&self) -> &'static str {
        match self.kind {
            RowKind::Transaction(o) => o.name(),
            RowKind::Noise => "noise",
        }
    }
}

/// Everything the views show.
#[derive(Debug)]
pub struct Model {
    pub rows: VecDeque<Row>,
    pub capacity: usize,
    /// Rows dropped from the front to stay within `capacity`.
    pub dropped: u64,
    next_seq: u64,
    last_t: Option<u64>,
    pub devices: BTreeMap<u8, DeviceStats>,
    pub bus: BusStats,
    pub registers: Registers,
    pub profiles: Profiles,
    pub lang: Lang,
    pub line: LineSettings,
    pending: TimingFlags,
    /// Set by the producer when its input ended (a replay done); the UI stays for browsing.
    pub finished: Option<String>,
    /// The producer's latest message (a port lost and reopened, a warning about the input).
    pub notice: Option<String>,
    /// The bus health findings, live (the devices view shows them).
    pub health: mbtap_analysis::health::Health,
}

impl Model {
    #[must_use]
    pub fn new(profiles: Profiles, lang: Lang, line: LineSettings, capacity: usize) -> Self {
        let profiles_for_health = profiles.clone();
        Self {
            rows: VecDeque::with_capacity(capacity.min(4096)),
            capacity: capacity.max(1),
            dropped: 0,
            next_seq: 0,
            last_t: None,
            devices: BTreeMap::new(),
            bus: BusStats::default(),
            registers: Registers::default(),
            profiles,
            lang,
            line,
            pending: TimingFlags::default(),
            finished: None,
            notice: None,
            health: mbtap_analysis::health::Health::new(profiles_for_health),
        }
    }

    /// The device name of `unit` (its profile's), if known.
    #[must_use]
    pub fn device_name(&self, unit: u8) -> Option<&str> {
        self.profiles.get(&unit).map(|p| p.meta.name.as_str())
    }

    /// Takes in one analyzer event.
    pub fn event(&mut self, e: &Event<'_>) {
        if !matches!(e, Event::Transaction(_)) {
            self.health.event(e);
        }
        match *e {
            Event::Frame { frame, .. } => {
                self.bus.frame(frame.bytes.len(), frame.check_ok, frame.t_end.0, self.line);
                self.pending.gap_inside |= frame.gap_violation_ns.is_some();
                self.pending.short_gap |= frame.short_gap_before_ns.is_some();
                self.pending.two_lengths |= frame.alt_len.is_some();
            }
            // A turnaround glitch is not traffic: the devices view shows it as a finding
            // (the health collector above counted it), the traffic view shows no row.
            Event::Glitch(_) => {}
            Event::Noise(n) => {
                self.bus.noise(n.bytes.len(), n.t_end.0, self.line);
                let summary = format!("{} byte(s) of noise", n.bytes.len());
                self.push(Row {
                    seq: 0,
                    t_ns: n.t_start.0,
                    delta_ns: None,
                    kind: RowKind::Noise,
                    unit: None,
                    function: None,
                    request: None,
                    response: Some(n.bytes.into()),
                    latency_ns: None,
                    summary,
                    timing: TimingFlags::default(),
                });
            }
            Event::Transaction(t) => {
                let annotations = match (t.outcome, t.request_pdu, self.profiles.get(&t.unit)) {
                    (Outcome::Ok, Some(req), Some(p)) => {
                        mbtap_device::profile::transaction::annotate_pdus(p, req, t.response_pdu)
                    }
                    _ => Vec::new(),
                };
                self.health.event_annotated(e, Some(&annotations));
                if t.outcome == Outcome::Ok
                    && let Some(req) = t.request_pdu
                {
                    self.registers.update(t.unit, t.t_start.0, req, t.response_pdu, &annotations, self.lang);
                }
                self.devices.entry(t.unit).or_default().transaction(t);
                self.bus.transaction(t.outcome);
                let summary =
                    mbtap_analysis::report::format::printable(&summary(t, &annotations, self.lang)).into_owned();
                let timing = std::mem::take(&mut self.pending);
                self.push(Row {
                    seq: 0,
                    t_ns: t.t_start.0,
                    delta_ns: None,
                    kind: RowKind::Transaction(t.outcome),
                    unit: Some(t.unit),
                    function: Some(t.function),
                    request: t.request.map(Into::into),
                    response: t.response.map(Into::into),
                    // The one rule every output shows latency by: a 0 or a figure under what the
                    // reads resolve is not shown as a latency.
                    latency_ns: match t.shown_latency() {
                        mbtap_analysis::pairing::ShownLatency::Measured(l) => Some(l),
                        _ => None,
                    },
                    summary,
                    timing,
                });
            }
        }
    }

    fn push(&mut self, mut row: Row) {
        row.seq = self.next_seq;
        self.next_seq += 1;
        row.delta_ns = self.last_t.map(|last| row.t_ns.saturating_sub(last));
        self.last_t = Some(row.t_ns);
        if self.rows.len() >= self.capacity {
            self.rows.pop_front();
            self.dropped += 1;
        }
        self.rows.push_back(row);
    }

    /// Rows seen since the start, dropped ones included.
    #[must_use]
    pub const fn total_rows(&self) -> u64 {
        self.next_seq
    }

    /// The row with sequence number `seq`, if still kept.
    #[must_use]
    pub fn row(&self, seq: u64) -> Option<&Row> {
        let first = self.rows.front()?.seq;
        self.rows.get(usize::try_from(seq.checked_sub(first)?).ok()?)
    }
}

/// One line for a transaction: the annotated values, else what was asked and answered.
fn summary(t: &mbtap_analysis::pairing::Transaction<'_>, annotations: &[Annotation], lang: Lang) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    match t.outcome {
        Outcome::Exception(code) => {
            let _ = write!(s, "exception {}", mbtap_proto::ExceptionCode::from(code));
        }
        Outcome::NoResponse => s.push_str("no response"),
        Outcome::BadResponse => s.push_str("response failed its check"),
        Outcome::Orphan => s.push_str("response with no request"),
        Outcome::WrongUnit(u) => {
            let _ = write!(s, "answered by unit {u}");
        }
        Outcome::Ok | Outcome::Broadcast => {}
    }
    if !annotations.is_empty() {
        for a in annotations {
            if !s.is_empty() {
                s.push_str(" · ");
            }
            let _ = write!(s, "{} {}", a.name_in(lang).unwrap_or("?"), a.value_text());
            if s.len() > 400 {
                break;
            }
        }
        return s;
    }
    let brief = t.request_pdu.and_then(request_brief).unwrap_or_default();
    if !brief.is_empty() {
        if !s.is_empty() {
            s.push_str(" · ");
        }
        s.push_str(&brief);
    }
    s
}

/// What a request asks, briefly: `430 ×4`, `100 := 7`.
fn request_brief(pdu: &[u8]) -> Option<String> {
    use mbtap_proto::Request as R;
    let (_, req) = mbtap_proto::parse_request(pdu).ok()?;
    Some(match req {
        R::ReadCoils { address, quantity }
        | R::ReadDiscreteInputs { address, quantity }
        | R::ReadHoldingRegisters { address, quantity }
        | R::ReadInputRegisters { address, quantity } => format!("{address} ×{quantity}"),
        R::WriteSingleCoil { address, value } => format!("{address} := {}", if value == 0xFF00 { "on" } else { "off" }),
        R::WriteSingleRegister { address, value } => format!("{address} := {value}"),
        R::WriteMultipleCoils { address, quantity, .. } => format!("{address} := {quantity} coils"),
        R::WriteMultipleRegisters { address, values, .. } => {
            let v: Vec<String> = values.iter().take(8).map(|v| v.to_string()).collect();
            format!("{address} := [{}]", v.join(", "))
        }
        _ => return None,
    })
}
