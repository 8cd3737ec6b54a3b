//! Requests sent and answers classified: values, an exception (decoded), or a failure (no
//! answer in time, a broken link, a CRC or framing error as tokio-modbus reports it).
//! A request that timed out is sent again `retries` times on a reopened link; an exception is
//! an answer and is never retried.

use std::time::{Duration, Instant};

use mbtap_device::profile::Table;
use mbtap_device::query::encode::Write;
use mbtap_device::query::is_bits;
use mbtap_device::query::plan::Read;
use mbtap_proto::function::ExceptionCode;
use tokio_modbus::prelude::{Reader as _, Writer as _};

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

/// Why a request got no usable answer. Classified from the error's type (the I/O error's kind,
/// tokio-modbus's transport or protocol error), never from its words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Failure {
    /// Nothing (usable) came within the timeout.
    #[error("no answer from unit {unit} within {ms} ms")]
    Timeout { unit: u8, ms: u128 },
    /// An answer that does not fit the request: another request's (a late one) or a damaged one.
    #[error(
        "unit {unit} answered {got} {what} to a request for {asked} (a late answer to another request, or a damaged one)"
    )]
    Misfit { unit: u8, got: usize, what: &'static str, asked: u16 },
    /// The device (or the converter in front of it) closed the connection.
    #[error("unit {unit}: {CLOSED} ({detail}); the next request opens a new one")]
    Closed { unit: u8, detail: String },
    /// The answer broke the protocol (tokio-modbus's check: a header or function that does not
    /// match).
    #[error("unit {unit}: {detail}")]
    Protocol { unit: u8, detail: String },
    /// The link could not be opened or failed otherwise: the I/O error's kind and words.
    #[error("{detail}")]
    Io { kind: std::io::ErrorKind, detail: String },
}

impl Failure {
    /// Whether the device closed the connection.
    #[must_use]
    pub const fn closed(&self) -> bool {
        matches!(self, Self::Closed { .. })
    }
}

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

fn bits(v: Vec<bool>) -> Vec<u16> {
    v.into_iter().map(u16::from).collect()
}

async fn once(link: &mut Link, unit: u8, op: Op<'_>) -> anyhow::Result<Result<Option<Vec<u16>>, u8>> {
    let ctx = link.context(unit).await?;
    let r = match op {
        Op::Read(r) => match r.table {
            Table::Coils => ctx.read_coils(r.address, r.quantity).await.map(|a| a.map(|v| Some(bits(v)))),
            Table::DiscreteInputs => {
                ctx.read_discrete_inputs(r.address, r.quantity).await.map(|a| a.map(|v| Some(bits(v))))
            }
            Table::HoldingRegisters => ctx.read_holding_registers(r.address, r.quantity).await.map(|a| a.map(Some)),
            Table::InputRegisters => ctx.read_input_registers(r.address, r.quantity).await.map(|a| a.map(Some)),
        },
        Op::Write(w) => match w.function {
            0x05 => ctx.write_single_coil(w.address, w.words.first().is_some_and(|&v| v != 0)).await,
            0x06 => ctx.write_single_register(w.address, w.words.first().copied().unwrap_or(0)).await,
            _ => ctx.write_multiple_registers(w.address, &w.words).await,
        }
        .map(|a| a.map(|()| None)),
    };
    Ok(r?.map_err(u8::from))
}

/// A failed request's error, typed: a connection the device closed (reset, broken pipe, end of
/// stream, not connected, or the `EINPROGRESS` a write on a socket closed underneath gives) is
/// [`Failure::Closed`] — the raw OS text named neither what happened nor what comes next.
fn link_error(unit: u8, e: &anyhow::Error) -> Failure {
    use std::io::ErrorKind;
    /// `EINPROGRESS` on Linux.
    const EINPROGRESS: i32 = 115;
    let detail = format!("{e:#}");
    // tokio-modbus's error is transparent over the I/O error: looked for as itself, and the I/O
    // error of a link that did not open as itself.
    let modbus = e.chain().find_map(|c| c.downcast_ref::<tokio_modbus::Error>());
    if let Some(tokio_modbus::Error::Protocol(p)) = modbus {
        return Failure::Protocol { unit, detail: p.to_string() };
    }
    let io = match modbus {
        Some(tokio_modbus::Error::Transport(io)) => Some(io),
        _ => e.chain().find_map(|c| c.downcast_ref::<std::io::Error>()),
    };
    let Some(io) = io else { return Failure::Io { kind: ErrorKind::Other, detail } };
    if io.raw_os_error() == Some(EINPROGRESS) {
        // Its text ("Operation now in progress") says nothing true of what happened.
        return Failure::Closed { unit, detail: "the socket was closed under the request".to_owned() };
    }
    match io.kind() {
        ErrorKind::ConnectionReset | ErrorKind::BrokenPipe | ErrorKind::UnexpectedEof | ErrorKind::NotConnected => {
            Failure::Closed { unit, detail }
        }
        kind => Failure::Io { kind, detail },
    }
}

/// How a closed connection is said.
pub const CLOSED: &str = "the device closed the connection";

/// Whether `got` values can answer `read`: registers exactly, bits padded to whole bytes
/// (MAP v1.1b3 §6.1–6.4).
fn fits(read: Read, got: usize) -> bool {
    let q = usize::from(read.quantity);
    if is_bits(read.table) { got == q.div_ceil(8) * 8 || got == q } else { got == q }
}

/// Sends `op` to `unit`, waiting `timeout` for each try. Returns the answer and how long the
/// last try took.
pub async fn send(link: &mut Link, unit: u8, op: Op<'_>, timeout: Duration, retries: u32) -> (Answer, Duration) {
    let mut tries = 0;
    loop {
        // The link is opened, and a late answer to a request given up heard out, before this
        // request's own time starts: listening for the late answer is no part of its timeout.
        if let Err(e) = link.context(unit).await {
            let answer = Answer::Failed(link_error(unit, &e));
            if tries < retries {
                tries += 1;
                continue;
            }
            return (answer, Duration::ZERO);
        }
        let started = Instant::now();
        let answer = match tokio::time::timeout(timeout, once(link, unit, op)).await {
            Ok(Ok(Ok(Some(v)))) => match op {
                Op::Read(r) if !fits(r, v.len()) => {
                    // Another request's answer (a late one), or a damaged one: never values
                    // (issue 24: a 4-register answer to a 2-register read gave rc=0).
                    link.reset();
                    Answer::Failed(Failure::Misfit {
                        unit,
                        got: v.len(),
                        what: if is_bits(r.table) { "bits" } else { "registers" },
                        asked: r.quantity,
                    })
                }
                _ => Answer::Values(v),
            },
            Ok(Ok(Ok(None))) => Answer::Done,
            Ok(Ok(Err(code))) => Answer::Exception(code),
            Ok(Err(e)) => {
                link.reset();
                Answer::Failed(link_error(unit, &e))
            }
            Err(_) => {
                // A late answer must not be taken for the next request's: start afresh.
                link.reset();
                Answer::Failed(Failure::Timeout { unit, ms: timeout.as_millis() })
            }
        };
        let took = started.elapsed();
        if matches!(answer, Answer::Failed(_)) && tries < retries {
            tries += 1;
            continue;
        }
        return (answer, took);
    }
}

/// Sends every read of `plan` to `unit` and names the answers with `profile`.
pub async fn read_all(
    link: &mut Link,
    unit: u8,
    targets: &[mbtap_device::query::resolve::Target],
    plan: &mbtap_device::query::plan::Plan,
    profile: Option<&mbtap_device::profile::Profile>,
    timeout: Duration,
    retries: u32,
) -> (Vec<mbtap_device::query::rows::Row>, Vec<super::show::Failure>) {
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for &read in &plan.reads {
        let item = targets.get(read.target).map(|t| t.item.text.clone()).unwrap_or_default();
        match send(link, unit, Op::Read(read), timeout, retries).await.0 {
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

    /// Issue 24: `read` took a 4-register (late) answer to a 2-register request, and 3 of 4.
    #[test]
    fn answers_of_the_wrong_length_are_not_values() {
        let regs = Read { target: 0, table: Table::HoldingRegisters, address: 160, quantity: 2 };
        assert!(fits(regs, 2));
        assert!(!fits(regs, 4) && !fits(regs, 1) && !fits(regs, 3));
        let bits = Read { target: 0, table: Table::Coils, address: 0, quantity: 10 };
        assert!(fits(bits, 16) && fits(bits, 10));
        assert!(!fits(bits, 8) && !fits(bits, 24));
    }
}

#[cfg(test)]
mod link_error_tests {
    use super::*;

    /// A device closing its connection after each request was said as "Operation now in
    /// progress (os error 115)" alone.
    #[test]
    fn a_closed_connection_is_said_as_such() {
        let e = anyhow::Error::from(std::io::Error::from_raw_os_error(115));
        let f = link_error(1, &e);
        let said = f.to_string();
        assert!(f.closed() && !said.contains("os error") && !said.contains("in progress"), "{said}");
        let e = anyhow::anyhow!("no route");
        assert_eq!(link_error(1, &e), Failure::Io { kind: std::io::ErrorKind::Other, detail: "no route".into() });
    }

    /// Classified by type, not by words: a reset inside tokio-modbus's transport error is a
    /// closed connection whatever its text; a text that merely says "Broken pipe" is not.
    #[test]
    fn a_failure_is_classified_by_its_type_not_its_words() {
        let reset = tokio_modbus::Error::Transport(std::io::Error::new(std::io::ErrorKind::ConnectionReset, "x"));
        assert!(link_error(1, &anyhow::Error::from(reset)).closed());
        let words = anyhow::anyhow!("Broken pipe");
        assert!(!link_error(1, &words).closed());
        let timed_out = std::io::Error::new(std::io::ErrorKind::TimedOut, "t");
        assert!(matches!(
            link_error(1, &anyhow::Error::from(timed_out)),
            Failure::Io { kind: std::io::ErrorKind::TimedOut, .. }
        ));
    }
}
