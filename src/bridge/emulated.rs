//! A line whose devices are emulated in this process (`mbtap simulate --listen`): the bridge's
//! fronts (Modbus TCP, RTU over TCP, UDP, TLS) and their one admission, queue, cache and
//! metrics, with the devices of [`mbtap_sim::device`] behind them instead of a port.
//! Every answer still passes the gateway core's one answer check: an emulated device that
//! answered what was not asked is a defect to count, never a reply to forward. The breaker,
//! the cache fill and the line-time class are the core's line's ([`mbtap_gateway::line`]), as
//! for a serial line or a Modbus TCP device.

use std::sync::Arc;
use std::time::Instant;

pub use crate::source::simulate::emulated::Emulated;
use mbtap_gateway::line::{Back, Line, Start, class};
use mbtap_gateway::rules::GATEWAY_TARGET_FAILED;
use mbtap_gateway::transaction::Reply;

use super::shared::LineShared;

/// Runs the emulated line forever, answering the clients' requests in the queue's order.
pub async fn run(emulated: Arc<Emulated>, shared: Arc<LineShared>) {
    let mut decide = Line::new(Back::Emulated);
    loop {
        let Some((client, job)) = shared.next() else {
            shared.wake.notified().await;
            continue;
        };
        if job.reply.is_closed() {
            shared.metrics.dropped();
            let mut job = job;
            job.audited("not sent: the client left before the device took it");
            continue;
        }
        if let Start::Answer(reply) = decide.start(job.unit, shared.now()) {
            shared.metrics.circuit_open(job.unit);
            super::line::answer(&shared, job, reply);
            continue;
        }
        let twins = shared.twins(client, &job);
        shared.cache().invalidate(job.unit, &job.pdu);
        shared.metrics.request(job.unit);
        let started = Instant::now();
        let reply = match emulated.answer(job.unit, &job.pdu) {
            Some((pdu, wait)) => {
                if !wait.is_zero() {
                    tokio::time::sleep(wait).await;
                }
                match mbtap_gateway::answer::check(job.unit, &job.pdu, job.unit, &pdu) {
                    Ok(()) => Reply::Pdu(pdu),
                    Err(why) => {
                        shared.metrics.misfit(job.unit, why);
                        Reply::Gateway(GATEWAY_TARGET_FAILED)
                    }
                }
            }
            None if job.unit == mbtap_sim::slave::BROADCAST => Reply::Silence,
            // No emulated device at that address: as a line where nobody answers (MAP v1.1b3 §7, 0B).
            None => Reply::Gateway(GATEWAY_TARGET_FAILED),
        };
        // An emulated answer is this request's by construction: the answer check above vouches.
        let finished = decide.finished(job.unit, &reply, true, shared.now());
        if let Reply::Pdu(pdu) = &reply {
            shared.metrics.response(job.unit, pdu);
            if finished.fill_cache {
                shared.cache().fill(job.unit, &job.pdu, pdu, shared.now());
            }
        }
        shared.metrics.line_time(class(client, job.high), started.elapsed());
        for twin in twins {
            let _ = twin.reply.send(reply.clone());
        }
        shared.metrics.latency(job.unit, job.queued.elapsed());
        super::line::answer(&shared, job, reply);
    }
}
