//! The line task's exchange with a Modbus TCP device (`--serial tcp://HOST:PORT`): each
//! request under the bridge's own transaction id on the one connection, the answer matched
//! back by it and checked against the request ([`mbtap_gateway::tcp_device`]), answers to
//! earlier requests that timed out and answers that do not fit dropped and counted; the core's
//! timeouts (fixed, `--timeout auto`, `--unit-timeout`) and `--retries` as on a serial line. For `--monitor`, request and answer are shown as the RTU frames they
//! would be on a line.

use std::io::{Error, ErrorKind};
use std::time::Duration;

use mbtap_gateway::rules::GATEWAY_TARGET_FAILED;
use mbtap_gateway::tcp_device::Heard;
use mbtap_gateway::transaction::{Ending, Reply, SerialMaster};

use super::port::Port;
use super::shared::Job;

impl Port<'_> {
    /// One request to the device and its answer, or exception 0x0B once the core's timeout for
    /// the unit (fixed, learnt or its own) has passed on every attempt (`--retries`); an error
    /// when the connection broke (the caller answers 0x0A and connects again). Every answer
    /// goes through the core's one answer check ([`mbtap_gateway::answer::check`], inside
    /// [`mbtap_gateway::tcp_device::TcpDevice::bytes`]).
    pub(super) async fn transact_tcp(&mut self, master: &mut SerialMaster, job: &Job) -> std::io::Result<Ending> {
        let shared = self.shared;
        let mut reply = Reply::Gateway(GATEWAY_TARGET_FAILED);
        for _attempt in 0..=master.config.retries {
            let adu = self.device.request(job.unit, &job.pdu);
            let timeout = master.timeouts.get(job.unit);
            shared.metrics.unit_timeout(job.unit, timeout);
            let started = shared.now();
            let result = self.exchange(job.unit, &adu, timeout).await;
            if let Err(e) = &result {
                self.lost(e);
            }
            if let Some(pdu) = result? {
                master.timeouts.answered(job.unit, shared.now().saturating_sub(started));
                reply = Reply::Pdu(pdu);
                break;
            }
            master.timeouts.timed_out(job.unit);
            shared.metrics.timeout(job.unit);
            shared.metrics.waited_in_vain(job.unit, timeout);
        }
        if self.monitor.is_some() {
            let mut frame = Vec::new();
            mbtap_proto::rtu::encode_rtu(job.unit, &job.pdu, &mut frame);
            self.observe_sent(&frame);
            if let Reply::Pdu(pdu) = &reply {
                frame.clear();
                mbtap_proto::rtu::encode_rtu(job.unit, pdu, &mut frame);
                self.observe(1, &frame);
            }
        }
        // Answers are matched by the bridge's own transaction id and checked: a late one cannot
        // be taken for this request's, so every answer may fill the cache.
        let cacheable = matches!(reply, Reply::Pdu(_));
        Ok(Ending { reply, last: shared.now(), cacheable, flush: None })
    }

    /// Sends `adu` and reads until its answer (None: none within `timeout`).
    async fn exchange(&mut self, unit: u8, adu: &[u8], timeout: Duration) -> std::io::Result<Option<Vec<u8>>> {
        let shared = self.shared;
        let stream = self.stream.as_mut().ok_or_else(|| Error::new(ErrorKind::NotConnected, "no connection"))?;
        let dropped = stream.clear_input();
        shared.metrics.garbage(dropped);
        shared.metrics.request(unit);
        stream.send(&self.opts.rs485, adu).await?;
        let deadline = tokio::time::Instant::now() + timeout;
        let mut chunk = [0u8; 512];
        loop {
            let n = match tokio::time::timeout_at(deadline, stream.read(&mut chunk)).await {
                Ok(Ok(0)) => return Err(Error::new(ErrorKind::UnexpectedEof, "the device closed the connection")),
                Ok(Ok(n)) => n,
                Ok(Err(e)) => return Err(e),
                Err(_) => return Ok(None),
            };
            let (heard, dropped) = self.device.bytes(chunk.get(..n).unwrap_or_default());
            shared.metrics.answers_dropped(unit, &dropped);
            match heard {
                Heard::More => {}
                Heard::Answer { pdu, .. } => return Ok(Some(pdu)),
                Heard::Broken => {
                    return Err(Error::new(ErrorKind::InvalidData, "the device's stream is not Modbus TCP"));
                }
            }
        }
    }
}

/// A value nobody outside the process can predict (std's hasher keys come from the OS's random
/// source).
pub(super) fn random_seed() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u64(0x006D_6274_6170);
    h.finish()
}
