//! Requests made from the profiles' reads and writes, sent over the [`Link`] (the bridge's
//! line and the gateway core: one admission, answer check, retry rule and late-answer rule),
//! and their answers read: values, a write done, an exception (decoded), or a typed
//! [`Failure`]. An exception is an answer and is never retried.

use std::time::{Duration, Instant};

use mbtap_device::profile::Table;
use mbtap_device::query::encode::Write;
use mbtap_device::query::is_bits;
use mbtap_device::query::plan::Read;
use mbtap_proto::function::ExceptionCode;

use super::link::Link;

/// How a request ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Answer {
    /// Registers, or bits as 0/1.
    Values(Vec<u16>),
    /// A write acknowledged.
    Done,
    /// An exception answer (MAP v1.1b3 §7).
    Exception(u8),
    /// No usable answer: why, typed.
    Failed(Failure),
}

pub use super::link::{CLOSED, Failure};

impl Answer {
    /// The failure as one phrase, `None` for a good answer.
    #[must_use]
    pub fn problem(&self) -> Option<String> {
        match self {
            Self::Values(_) | Self::Done => None,
            Self::Exception(c) => Some(format!("exception {}", ExceptionCode::from(*c))),
            Self::Failed(why) => Some(why.to_string()),
        }
    }
}

/// What to send.
#[derive(Debug, Clone, Copy)]
pub enum Op<'a> {
    Read(Read),
    Write(&'a Write),
}

/// The request `op` makes (MAP v1.1b3 §6.1–6.4: function, address, quantity; writes as the
/// profile's encoder built them).
fn request_pdu(op: Op<'_>) -> Vec<u8> {
    match op {
        Op::Read(r) => {
            let function = match r.table {
                Table::Coils => 0x01,
                Table::DiscreteInputs => 0x02,
                Table::HoldingRegisters => 0x03,
                Table::InputRegisters => 0x04,
            };
            let [ah, al] = r.address.to_be_bytes();
            let [qh, ql] = r.quantity.to_be_bytes();
            vec![function, ah, al, qh, ql]
        }
        Op::Write(w) => w.pdu(),
    }
}

/// What an answer the line's answer check let through says: an exception (MAP v1.1b3 §7), a
/// read's values — registers high byte first, bits least significant first and padded to whole
/// bytes (§6.1–6.4) — or a write done (its echo was checked by the line).
fn answer_of(op: Op<'_>, pdu: &[u8]) -> Answer {
    match (op, pdu) {
        (_, [f, code, ..]) if f & mbtap_proto::EXCEPTION_FLAG != 0 => Answer::Exception(*code),
        (Op::Read(r), [_, _, data @ ..]) if is_bits(r.table) => {
            Answer::Values(data.iter().flat_map(|byte| (0..8).map(move |i| u16::from(byte >> i & 1))).collect())
        }
        (Op::Read(_), [_, _, data @ ..]) => Answer::Values(
            data.chunks_exact(2).map(|w| if let [h, l] = w { u16::from_be_bytes([*h, *l]) } else { 0 }).collect(),
        ),
        // A write's echo, or nothing: a broadcast, which nobody answers.
        _ => Answer::Done,
    }
}

/// Sends `op` to `unit` over `link` (its timeout and retries are the link's). Returns the
/// answer and how long it took.
pub async fn send(link: &mut Link, unit: u8, op: Op<'_>) -> (Answer, Duration) {
    let started = Instant::now();
    let answer = match link.ask(unit, request_pdu(op)).await {
        Ok(pdu) => answer_of(op, &pdu),
        Err(why) => Answer::Failed(why),
    };
    (answer, started.elapsed())
}

/// Sends every read of `plan` to `unit` and names the answers with `profile`.
pub async fn read_all(
    link: &mut Link,
    unit: u8,
    targets: &[mbtap_device::query::resolve::Target],
    plan: &mbtap_device::query::plan::Plan,
    profile: Option<&mbtap_device::profile::Profile>,
) -> (Vec<mbtap_device::query::rows::Row>, Vec<super::show::Failure>) {
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for &read in &plan.reads {
        let item = targets.get(read.target).map(|t| t.item.text.clone()).unwrap_or_default();
        match send(link, unit, Op::Read(read)).await.0 {
            Answer::Values(mut v) => {
                // Bits come back padded to whole bytes (MAP v1.1b3 §6.1); keep those asked for.
                v.truncate(usize::from(read.quantity));
                rows.extend(mbtap_device::query::rows::rows(unit, read.table, read.address, &v, profile));
            }
            other => failures.push(super::show::Failure {
                unit,
                item,
                read: Some(read),
                problem: other.problem().unwrap_or_default(),
            }),
        }
    }
    (rows, failures)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Answer PDUs as a device sends them: function, byte count, data (MAP v1.1b3 §6.3, §6.1).
    const HOLDING_2: [u8; 6] = [0x03, 0x04, 0x12, 0x34, 0xFF, 0xFE];
    /// Ten coils, 1 0 1 1 0 0 0 0 | 1 0: two bytes, least significant bit first.
    const COILS_10: [u8; 4] = [0x01, 0x02, 0b0000_1101, 0b0000_0001];
    const EXCEPTION_02: [u8; 2] = [0x83, 0x02];

    #[test]
    fn reads_are_asked_and_their_answers_read_as_the_spec_lays_them_out() {
        let regs = Read { target: 0, table: Table::HoldingRegisters, address: 160, quantity: 2 };
        assert_eq!(request_pdu(Op::Read(regs)), [0x03, 0x00, 0xA0, 0x00, 0x02]);
        assert_eq!(answer_of(Op::Read(regs), &HOLDING_2), Answer::Values(vec![0x1234, 0xFFFE]));
        assert_eq!(answer_of(Op::Read(regs), &EXCEPTION_02), Answer::Exception(2));
        let coils = Read { target: 0, table: Table::Coils, address: 0, quantity: 10 };
        assert_eq!(request_pdu(Op::Read(coils)), [0x01, 0, 0, 0, 10]);
        let Answer::Values(bits) = answer_of(Op::Read(coils), &COILS_10) else { panic!("values") };
        assert_eq!(bits.get(..10), Some(&[1, 0, 1, 1, 0, 0, 0, 0, 1, 0][..]));
        assert_eq!(answer_of(Op::Read(coils), &[]), Answer::Done, "a broadcast is not answered");
    }
}
