//! What a listener does with each request it reads, whatever the transport (TCP, TLS, UDP,
//! RTU over TCP, the serial front, the broker, mbtap's own master): the gateway core's admission
//! policy, then the line's cache, then the line's queue ([`admit`]); a listener's answer comes
//! back as a [`Pending`] in the order the client asked.

use std::net::SocketAddr;
use std::ops::RangeInclusive;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::oneshot;
use tokio::time::Instant;

use super::shared::{Job, LineShared};
use mbtap_gateway::admit::{Asked, IpNet, Policy, RateLimit, Refusal, Role};
use mbtap_gateway::queue::{ClientId, Full};
use mbtap_gateway::rules::{GATEWAY_TARGET_FAILED, exception_pdu};
use mbtap_gateway::transaction::Reply;

/// Units served by one serial line.
#[derive(Debug, Clone)]
pub struct Route {
    pub units: RangeInclusive<u8>,
    pub line: Arc<LineShared>,
}

/// The lines a bridge serves, in the order given, and the counters of the server in front of
/// them: connections and refusals belong to no line, so they are kept and exported once,
/// without a line label.
#[derive(Debug, Default)]
pub struct Routes {
    pub lines: Vec<Route>,
    pub server: super::metrics::Metrics,
    /// `--audit`: where every request that may change a device is recorded, with its ending.
    pub audit: Option<Arc<crate::output::audit::Audit>>,
    /// `--web`: who asks, with their requests and refusals (kept only when the view is on).
    pub clients: Option<Arc<super::client_book::ClientBook>>,
}

impl std::ops::Deref for Routes {
    type Target = [Route];
    fn deref(&self) -> &[Route] {
        &self.lines
    }
}

/// What the TCP side allows and how it frames.
#[derive(Debug, Clone)]
pub struct ServerOptions {
    /// Raw RTU frames (address, PDU, CRC) over TCP instead of MBAP.
    pub rtu_over_tcp: bool,
    /// What a request may do and where it goes (the gateway core's admission policy).
    pub policy: Policy,
    /// Only these client addresses may connect (empty: all).
    pub allow_ips: Vec<IpNet>,
    pub max_connections: usize,
    /// A connection silent this long is closed.
    pub idle_timeout: Duration,
    /// Requests per second per connection (None: no limit); above it: exception 06.
    pub rate_limit: Option<f64>,
}

/// An answer on its way back to the client, in request order.
pub(super) struct Pending {
    pub(super) transaction_id: u16,
    pub(super) unit: u8,
    pub(super) function: u8,
    pub(super) answer: Delivery,
}

impl Pending {
    /// The answer's PDU once it is there (a gateway exception as its exception PDU); `None`
    /// for a broadcast, which nobody answers.
    pub(super) async fn answer_pdu(self) -> Option<Vec<u8>> {
        let reply = match self.answer {
            Delivery::Now(r) => r,
            // The line dropped the job (it never will, but a closed channel must not hang).
            Delivery::Later(r) => r.await.unwrap_or(Reply::Gateway(GATEWAY_TARGET_FAILED)),
        };
        match reply {
            Reply::Pdu(pdu) => Some(pdu),
            Reply::Gateway(code) => Some(exception_pdu(self.function, code)),
            Reply::Silence => None,
        }
    }
}

/// How an answer reaches the listener: at once (refused, or from the cache), or from the line.
pub(super) enum Delivery {
    Now(Reply),
    Later(oneshot::Receiver<Reply>),
}

/// One client as the listeners know it: its queue id, its role, whether all its requests are
/// in the priority class, and its rate limiter.
#[derive(Debug)]
pub struct Client<'a> {
    pub(super) id: ClientId,
    pub(super) role: Role<'a>,
    pub(super) peer_high: bool,
    pub(super) bucket: Option<RateLimit>,
    /// Who it is, as the audit records it.
    pub(super) who: crate::output::audit::Who,
}

impl<'a> Client<'a> {
    pub(super) fn new(id: ClientId, role: Role<'a>, peer: SocketAddr, routes: &[Route], opts: &ServerOptions) -> Self {
        let transport = if opts.rtu_over_tcp { "rtu-over-tcp" } else { "tcp" };
        Self {
            peer_high: opts.policy.peer_high(peer.ip()),
            who: crate::output::audit::Who { transport, address: Some(peer), role: None },
            ..Self::local(id, role, routes, opts)
        }
    }

    /// An asker inside this process (the broker's writes, mbtap's own master): no address, the
    /// same rate limit as a connection.
    pub fn local(id: ClientId, role: Role<'a>, routes: &[Route], opts: &ServerOptions) -> Self {
        let now = routes.first().map_or(Duration::ZERO, |r| r.line.now());
        Self {
            id,
            role,
            peer_high: false,
            bucket: opts.rate_limit.map(|rate| RateLimit::new(rate, now)),
            who: crate::output::audit::Who { transport: "local", address: None, role: None },
        }
    }

    /// The same client, recorded by the audit as coming over `transport` under `role`.
    #[must_use]
    pub fn known_as(mut self, transport: &'static str, role: Option<String>) -> Self {
        self.who.transport = transport;
        self.who.role = role;
        self
    }
}

/// What admission made of a request: refused (nothing of it reached a line), answered from
/// the cache, or queued on its line with the answer to come.
#[derive(Debug)]
pub enum Admission {
    Refused(Refusal),
    Now(Reply),
    Later(oneshot::Receiver<Reply>),
}

/// Puts one request through the gateway core's admission policy, then the cache, then queues it
/// on its line: the one path every asker's request takes (connections, UDP peers, the serial
/// front, the broker's writes, mbtap's own master). A refusal is counted here.
pub fn admit(client: &mut Client<'_>, unit: u8, pdu: Vec<u8>, routes: &Routes, opts: &ServerOptions) -> Admission {
    // What the audit records of it, if anything: a request that may change a device.
    let audited = routes.audit.as_ref().and_then(|a| Some((Arc::clone(a), mbtap_gateway::audit::change(&pdu)?)));
    if let Some(book) = &routes.clients {
        book.request(client.id, &client.who);
    }
    let refuse = |why: Refusal| {
        routes.server.refused(why.reason());
        if let Some(book) = &routes.clients {
            book.refused(client.id, &client.who, why.reason());
        }
        if let Some((audit, change)) = &audited {
            audit.record(&client.who, unit, change, &format!("refused: {}", why.reason()));
        }
        Admission::Refused(why)
    };
    let now = routes.first().map_or(Duration::ZERO, |r| r.line.now());
    let asked = Asked { unit, pdu: &pdu, role: client.role, peer_high: client.peer_high };
    let admitted = match opts.policy.admit(asked, client.bucket.as_mut(), now) {
        Ok(a) => a,
        Err(why) => return refuse(why),
    };
    let Some(route) = routes.get(admitted.route) else { return refuse(Refusal::NoRoute) };
    let target = admitted.target;
    if let Some(answer) = route.line.cached(target, &pdu) {
        return Admission::Now(Reply::Pdu(answer));
    }
    let (tx, rx) = oneshot::channel();
    let write = route.line.write_pending(target, &pdu);
    let audit = audited.as_ref().map(|(audit, change)| super::shared::Ticket {
        audit: Arc::clone(audit),
        who: client.who.clone(),
        change: change.clone(),
    });
    let job = Job { unit: target, pdu, reply: tx, queued: Instant::now(), high: admitted.high, write, audit };
    match route.line.submit(client.id, job) {
        Ok(()) => Admission::Later(rx),
        Err(Full::Client) => refuse(Refusal::QueueFull),
        Err(Full::Line) => refuse(Refusal::LineFull),
    }
}

/// One request read by a listener, through [`admit`]; what to answer, in the client's order.
pub(super) fn request(
    client: &mut Client<'_>,
    transaction_id: u16,
    unit: u8,
    pdu: Vec<u8>,
    routes: &Routes,
    opts: &ServerOptions,
) -> Pending {
    let function = pdu.first().copied().unwrap_or(0);
    let answer = match admit(client, unit, pdu, routes, opts) {
        Admission::Refused(why) => Delivery::Now(Reply::Gateway(why.exception())),
        Admission::Now(reply) => Delivery::Now(reply),
        Admission::Later(rx) => Delivery::Later(rx),
    };
    Pending { transaction_id, unit, function, answer }
}
