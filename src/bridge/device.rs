//! The line task's exchange with a Modbus TCP device (`--serial tcp://HOST:PORT`): each
//! request under the bridge's own transaction id on the one connection, the answer matched
//! back by it ([`mbtap_gateway::tcp_device`]), answers to earlier requests that timed out
//! dropped and counted. For `--monitor`, request and answer are shown as the RTU frames they
//! would be on a line.

use std::io::{Error, ErrorKind};

use mbtap_gateway::rules::GATEWAY_TARGET_FAILED;
use mbtap_gateway::tcp_device::Heard;
use mbtap_gateway::transaction::{Outcome, Reply};

use super::port::Port;
use super::shared::Job;

impl Port<'_> {
    /// One request to the device and its answer, or exception 0x0B after the timeout; an
    /// error when the connection broke (the caller answers 0x0A and connects again).
    pub(super) async fn transact_tcp(&mut self, job: &Job) -> std::io::Result<Outcome> {
        let (shared, opts) = (self.shared, self.opts);
        let (id, adu) = self.device.request(job.unit, &job.pdu);
        let timeout = opts.unit_timeouts.get(&job.unit).copied().unwrap_or(opts.timeout);
        let result = async {
            let stream = self.stream.as_mut().ok_or_else(|| Error::new(ErrorKind::NotConnected, "no connection"))?;
            stream.clear_input();
            shared.metrics.request(job.unit);
            stream.send(&opts.rs485, &adu).await?;
            let deadline = tokio::time::Instant::now() + timeout;
            let mut chunk = [0u8; 512];
            loop {
                let n = match tokio::time::timeout_at(deadline, stream.read(&mut chunk)).await {
                    Ok(Ok(0)) => return Err(Error::new(ErrorKind::UnexpectedEof, "the device closed the connection")),
                    Ok(Ok(n)) => n,
                    Ok(Err(e)) => return Err(e),
                    Err(_) => {
                        shared.metrics.timeout(job.unit);
                        return Ok(Reply::Gateway(GATEWAY_TARGET_FAILED));
                    }
                };
                let (heard, late) = self.device.bytes(id, chunk.get(..n).unwrap_or_default());
                for _ in 0..late {
                    shared.metrics.late_answer(job.unit);
                }
                match heard {
                    Heard::More => {}
                    Heard::Answer { pdu, .. } => return Ok(Reply::Pdu(pdu)),
                    Heard::Broken => {
                        return Err(Error::new(ErrorKind::InvalidData, "the device's stream is not Modbus TCP"));
                    }
                }
            }
        }
        .await;
        if let Err(e) = &result {
            self.lost(e);
        }
        let reply = result?;
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
        let cacheable = matches!(reply, Reply::Pdu(_));
        Ok(Outcome { reply, last: shared.now(), cacheable, flush: None })
    }
}
