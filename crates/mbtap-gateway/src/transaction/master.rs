//! The serial master's memory between requests — the learnt timeouts, whether the adapter
//! echoes, the units whose last request timed out — and the transaction it starts.

use super::{EchoMode, MasterConfig, Phase, Step, Transaction};
use crate::timeouts::Timeouts;
use mbtap_proto::serial_line::SerialMode;
use mbtap_proto::{encode_ascii, encode_rtu};
use std::collections::BTreeSet;
use std::time::Duration;

/// The serial master's memory between requests: learnt timeouts, whether the adapter echoes,
/// units whose last request timed out.
#[derive(Debug, Clone)]
pub struct SerialMaster {
    pub config: MasterConfig,
    pub timeouts: Timeouts,
    pub(super) echo_found: Option<bool>,
    pub(super) suspect: BTreeSet<u8>,
}

impl SerialMaster {
    #[must_use]
    pub fn new(config: MasterConfig, timeouts: Timeouts) -> Self {
        Self { config, timeouts, echo_found: None, suspect: BTreeSet::new() }
    }

    /// Starts one request to `unit`; the first step is [`Step::Send`] with its ADU.
    pub fn transaction<'m>(&'m mut self, unit: u8, pdu: &'m [u8]) -> (Transaction<'m>, Step) {
        let mut adu = Vec::with_capacity(pdu.len() * 2 + 5);
        match self.config.mode {
            SerialMode::Rtu => encode_rtu(unit, pdu, &mut adu),
            SerialMode::Ascii => encode_ascii(unit, pdu, &mut adu),
        }
        let was_suspect = self.suspect.remove(&unit);
        let mut t = Transaction {
            master: self,
            unit,
            pdu,
            function: pdu.first().copied().unwrap_or(0),
            adu,
            attempt: 0,
            sent: Duration::ZERO,
            timeout: Duration::ZERO,
            phase: Phase::Sending,
            notes: Vec::new(),
            was_suspect,
            flush: None,
            outcome: None,
        };
        let step = t.attempt();
        (t, step)
    }

    /// Whether to read the frame back before the answer: `Some(true)` when the adapter is known
    /// to echo, `Some(false)` to find out (`auto`, first telling request), `None` not to.
    pub(super) fn echo_expected(&self, function: u8) -> Option<bool> {
        match (self.config.echo, self.echo_found) {
            (EchoMode::Off, _) | (EchoMode::Auto, Some(false)) => None,
            (EchoMode::On, _) | (EchoMode::Auto, Some(true)) => Some(true),
            // 05, 06 and 08 answer with the request itself: an echo and an answer look alike.
            (EchoMode::Auto, None) if matches!(function, 0x05 | 0x06 | 0x08) => None,
            (EchoMode::Auto, None) => Some(false),
        }
    }
}
