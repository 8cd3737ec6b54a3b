//! The TCP side of the bridge: Modbus TCP (MBAP, Messaging on TCP/IP v1.0b §3.1) or raw RTU
//! frames over TCP, many clients at once. Each connection is on its own: a malformed header,
//! a flood or a disconnect affects only that connection. Requests go to the line of their unit
//! ([`Route`]); answers come back in the order the client asked, with its transaction id and
//! unit id unchanged.

use std::net::SocketAddr;
use std::ops::RangeInclusive;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot};
use tokio::time::Instant;

use super::shared::{Job, LineShared};
use mbtap_core::proto::tcp::{Streaming, parse_tcp_frame};
use mbtap_core::proto::{encode_rtu, encode_tcp};
use mbtap_gateway::admit::{Asked, IpNet, Policy, RateLimit, Refusal, Role, ip_allowed};
use mbtap_gateway::queue::ClientId;
use mbtap_gateway::rules::{GATEWAY_TARGET_FAILED, exception_pdu};
use mbtap_gateway::transaction::Reply;

/// A pause that ends an RTU-over-TCP frame of unknown length.
const RTU_OVER_TCP_SILENCE: Duration = Duration::from_millis(50);
/// A request must arrive whole this soon after its first byte (at most 260 bytes: one TCP
/// segment on any network a Modbus client uses): a client dribbling bytes holds no slot longer.
const REQUEST_DEADLINE: Duration = Duration::from_secs(2);
/// When every slot is taken, a connection that has sent no request for this long gives its slot
/// to the newcomer; one busier than that is never evicted.
const EVICT_AFTER_IDLE: Duration = Duration::from_secs(1);
/// A connection that has never sent a whole request is evicted first, once it has had this
/// long to send one (a client connects and asks at once; an idle socket never asks).
const FIRST_REQUEST_GRACE: Duration = Duration::from_millis(200);

/// One open connection: when it opened, when it last sent a whole request, how to end it.
#[derive(Debug)]
pub struct Conn {
    opened: Instant,
    last_request: Option<Instant>,
    abort: tokio::task::AbortHandle,
}

/// The open connections of every listener (plain, RTU over TCP, TLS) — the connection limit is
/// theirs together, so a full table evicts a socket that never asked (a TLS handshake in
/// progress counts as one), or its idlest member, whichever listener holds it, instead of
/// refusing everyone new (issue 24: 64 idle RTU sockets locked out every Modbus TCP client).
pub type Table = std::sync::Mutex<std::collections::HashMap<ClientId, Conn>>;

/// Ends a connection's bookkeeping however it ends — closed, failed or evicted (an aborted
/// task runs its destructors, not its remaining code).
struct Cleanup {
    client: ClientId,
    routes: Arc<Vec<Route>>,
    table: Arc<Table>,
}

impl Drop for Cleanup {
    fn drop(&mut self) {
        for r in self.routes.iter() {
            r.line.forget(self.client);
        }
        if let Some(r) = self.routes.first() {
            r.line.metrics.connection_closed();
        }
        self.table.lock().unwrap_or_else(std::sync::PoisonError::into_inner).remove(&self.client);
    }
}

/// Ends one connection to make room: the oldest that never sent a whole request in
/// [`FIRST_REQUEST_GRACE`], else the idlest quiet at least [`EVICT_AFTER_IDLE`]. False when
/// every connection is busy (then the newcomer is refused).
fn evict_idlest(table: &Table) -> bool {
    let table = table.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let silent = table
        .values()
        .filter(|c| c.last_request.is_none() && c.opened.elapsed() >= FIRST_REQUEST_GRACE)
        .min_by_key(|c| c.opened);
    let idlest = || {
        table
            .values()
            .filter_map(|c| c.last_request.map(|l| (l, c)))
            .filter(|(l, _)| l.elapsed() >= EVICT_AFTER_IDLE)
            .min_by_key(|(l, _)| *l)
            .map(|(_, c)| c)
    };
    match silent.or_else(idlest) {
        Some(c) => {
            c.abort.abort();
            true
        }
        None => false,
    }
}

/// Bytes an RTU-over-TCP client may send without a request among them before it is cut off:
/// sixteen of the longest frames.
const RTU_GARBAGE_LIMIT: u64 = 16 * 256;

/// Units served by one serial line.
#[derive(Debug, Clone)]
pub struct Route {
    pub units: RangeInclusive<u8>,
    pub line: Arc<LineShared>,
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

/// How long a TLS client has to complete its handshake.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// Accepts connections forever.
/// With `tls`, each connection first completes a TLS handshake with a client certificate
/// (within [`HANDSHAKE_TIMEOUT`]); its role decides what it may do.
pub async fn serve(
    listener: TcpListener,
    routes: Arc<Vec<Route>>,
    opts: Arc<ServerOptions>,
    tls: Option<super::tls::Tls>,
    table: Arc<Table>,
) {
    static NEXT_CLIENT: AtomicU64 = AtomicU64::new(1);
    let metrics_line = routes.first().map(|r| Arc::clone(&r.line));
    loop {
        let Ok((stream, peer)) = listener.accept().await else {
            // Out of file descriptors or similar: back off a little, keep serving.
            tokio::time::sleep(Duration::from_millis(50)).await;
            continue;
        };
        let metrics = metrics_line.as_ref().map(|l| &l.metrics);
        if !ip_allowed(&opts.allow_ips, peer.ip()) {
            if let Some(m) = metrics {
                m.refused("ip_not_allowed");
            }
            continue;
        }
        if metrics.is_some_and(|m| m.open_connections() >= i64::try_from(opts.max_connections).unwrap_or(i64::MAX)) {
            // Full: the idlest connection makes room (idle sockets must not lock everyone
            // out); when all are busy, the newcomer is refused.
            if evict_idlest(&table) {
                if let Some(m) = metrics {
                    m.refused("evicted_idle");
                }
                // Its slot frees when its task has run its cleanup.
                tokio::task::yield_now().await;
            } else {
                if let Some(m) = metrics {
                    m.refused("max_connections");
                }
                continue;
            }
        }
        if let Some(m) = metrics {
            m.connection_opened();
        }
        let client = NEXT_CLIENT.fetch_add(1, Ordering::Relaxed);
        let (routes, opts, table_for_task, tls) =
            (Arc::clone(&routes), Arc::clone(&opts), Arc::clone(&table), tls.clone());
        // Registered before the task runs, so its cleanup always finds (and removes) it.
        let mut entries = table.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let handle = tokio::spawn(async move {
            let cleanup = Cleanup { client, routes: Arc::clone(&routes), table: Arc::clone(&table_for_task) };
            let _ = stream.set_nodelay(true);
            let seen = |c| {
                if let Some(e) = table_for_task.lock().unwrap_or_else(std::sync::PoisonError::into_inner).get_mut(&c) {
                    e.last_request = Some(Instant::now());
                }
            };
            match &tls {
                None => connection(stream, peer, client, &routes, &opts, &seen, Role::Plain).await,
                Some(tls) => {
                    let metrics = routes.first().map(|r| &r.line.metrics);
                    let Some(acceptor) = tls.current() else { return };
                    match tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(stream)).await {
                        Ok(Ok(tls_stream)) => {
                            let cert =
                                tls_stream.get_ref().1.peer_certificates().and_then(|c| c.first()).map(|c| c.to_vec());
                            let role = cert.as_deref().and_then(super::tls::role_of);
                            let policy = role.as_ref().and_then(|r| tls.roles.get(r));
                            // A session whose certificate a reloaded CRL revokes ends at once
                            // (issue 24: it was still answered after SIGHUP).
                            let revoked = tls.revocation(cert.as_deref().unwrap_or_default());
                            tokio::select! {
                                () = connection(tls_stream, peer, client, &routes, &opts, &seen, Role::Tls(policy)) => {}
                                () = revoked => {
                                    if let Some(m) = metrics {
                                        m.refused("revoked");
                                    }
                                    eprintln!("mbtap: TLS client {peer}: its certificate is revoked by the reloaded CRL; session closed");
                                }
                            }
                        }
                        // No certificate, an expired one, one from another CA, a slow or
                        // broken handshake: the connection ends here, counted.
                        Ok(Err(_)) => {
                            if let Some(m) = metrics {
                                m.refused("tls_handshake");
                            }
                        }
                        Err(_) => {
                            if let Some(m) = metrics {
                                m.refused("tls_handshake_timeout");
                            }
                        }
                    }
                }
            }
            drop(cleanup);
        });
        entries.insert(client, Conn { opened: Instant::now(), last_request: None, abort: handle.abort_handle() });
        drop(entries);
    }
}

/// An answer on its way back to the client, in request order.
pub(super) struct Pending {
    pub(super) transaction_id: u16,
    pub(super) unit: u8,
    pub(super) function: u8,
    pub(super) answer: Answer,
}

impl Pending {
    /// The answer's PDU once it is there (a gateway exception as its exception PDU); `None`
    /// for a broadcast, which nobody answers.
    pub(super) async fn answer_pdu(self) -> Option<Vec<u8>> {
        let reply = match self.answer {
            Answer::Now(r) => r,
            // The line dropped the job (it never will, but a closed channel must not hang).
            Answer::Later(r) => r.await.unwrap_or(Reply::Gateway(GATEWAY_TARGET_FAILED)),
        };
        match reply {
            Reply::Pdu(pdu) => Some(pdu),
            Reply::Gateway(code) => Some(exception_pdu(self.function, code)),
            Reply::Silence => None,
        }
    }
}

pub(super) enum Answer {
    Now(Reply),
    Later(oneshot::Receiver<Reply>),
}

/// One client's connection until it closes, misbehaves or idles out; `seen` is told of every
/// whole request (for eviction).
async fn connection<S>(
    stream: S,
    peer: SocketAddr,
    client: ClientId,
    routes: &[Route],
    opts: &ServerOptions,
    seen: &(dyn Fn(ClientId) + Sync),
    role: Role<'_>,
) where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + 'static,
{
    // `--priority high=ip:…`: the whole connection's requests.
    let mut client = Client::new(client, role, peer, routes, opts);
    let (mut rd, mut wr) = tokio::io::split(stream);
    let (tx, mut rx) = mpsc::channel::<Pending>(64);
    let rtu = opts.rtu_over_tcp;
    let writer = tokio::spawn(async move {
        let mut out = Vec::with_capacity(300);
        while let Some(p) = rx.recv().await {
            let (transaction_id, unit) = (p.transaction_id, p.unit);
            let Some(pdu) = p.answer_pdu().await else { continue };
            out.clear();
            if rtu {
                encode_rtu(unit, &pdu, &mut out);
            } else {
                encode_tcp(transaction_id, unit, &pdu, &mut out);
            }
            if wr.write_all(&out).await.is_err() {
                break;
            }
        }
    });
    let mut buf = Vec::with_capacity(600);
    let mut chunk = [0u8; 1024];
    let mut rtu_frames = mbtap_core::sim::RequestAssembler::default();
    // The idle timer counts from the last whole request, not the last byte: bytes that never
    // make a request do not keep a connection alive. A request begun must end within
    // REQUEST_DEADLINE.
    let mut last_request = Instant::now();
    let mut partial_since: Option<Instant> = None;
    'read: loop {
        // RTU over TCP: a frame whose function does not fix its length ends when the client
        // pauses, as on a serial line.
        let rtu_waiting = rtu && rtu_frames.pending() > 0;
        let idle_left = opts.idle_timeout.saturating_sub(last_request.elapsed());
        let wait = match partial_since {
            _ if rtu_waiting => RTU_OVER_TCP_SILENCE,
            Some(t) => REQUEST_DEADLINE.saturating_sub(t.elapsed()).min(idle_left),
            None => idle_left,
        };
        let n = match tokio::time::timeout(wait, rd.read(&mut chunk)).await {
            Ok(Ok(n)) if n > 0 => n,
            Err(_) if rtu_waiting && partial_since.is_none_or(|t| t.elapsed() < REQUEST_DEADLINE) => {
                if let Some(f) = rtu_frames.silence() {
                    last_request = Instant::now();
                    seen(client.id);
                    let pending = request(&mut client, 0, f.unit, f.pdu, routes, opts);
                    if tx.send(pending).await.is_err() {
                        break;
                    }
                }
                partial_since = None;
                continue;
            }
            Err(_) if partial_since.is_some() => {
                // Slowloris: a request begun and never finished ends this connection only.
                if let Some(r) = routes.first() {
                    r.line.metrics.refused("slow_request");
                }
                break;
            }
            // EOF, an error, or idle too long: the connection ends.
            _ => break,
        };
        buf.extend_from_slice(chunk.get(..n).unwrap_or_default());
        loop {
            let (transaction_id, unit, pdu) = if rtu {
                rtu_frames.push(&buf);
                buf.clear();
                let Some(f) = rtu_frames.next_request() else {
                    // Kilobytes that hold no request are not a Modbus client: end this
                    // connection only.
                    if rtu_frames.discarded > RTU_GARBAGE_LIMIT {
                        if let Some(r) = routes.first() {
                            r.line.metrics.refused("garbage");
                        }
                        break 'read;
                    }
                    break;
                };
                rtu_frames.discarded = 0;
                (0, f.unit, f.pdu)
            } else {
                match parse_tcp_frame(&buf) {
                    Ok(Streaming::Incomplete(_)) => break,
                    Ok(Streaming::Complete(f, used)) => {
                        let r = (f.header.transaction_id, f.header.unit, f.pdu.to_vec());
                        buf.drain(..used);
                        r
                    }
                    Err(_) => {
                        // Protocol id ≠ 0, length 0, 1 or > 254: this connection only.
                        if let Some(r) = routes.first() {
                            r.line.metrics.refused("malformed_mbap");
                        }
                        break 'read;
                    }
                }
            };
            last_request = Instant::now();
            seen(client.id);
            let pending = request(&mut client, transaction_id, unit, pdu, routes, opts);
            if tx.send(pending).await.is_err() {
                break 'read;
            }
        }
        // Bytes of a request still to come: its deadline runs from its first byte.
        let partial = if rtu { rtu_frames.pending() > 0 } else { !buf.is_empty() };
        partial_since = if partial { partial_since.or(Some(Instant::now())) } else { None };
    }
    drop(tx);
    // Answers already on their way still go out (the client may only have half-closed);
    // requests not started were dropped by the caller's `forget`.
    let _ = writer.await;
}

/// One client as the listeners know it: its queue id, its role, whether all its requests are
/// in the priority class, and its rate limiter.
#[derive(Debug)]
pub(super) struct Client<'a> {
    pub(super) id: ClientId,
    pub(super) role: Role<'a>,
    pub(super) peer_high: bool,
    pub(super) bucket: Option<RateLimit>,
}

impl<'a> Client<'a> {
    pub(super) fn new(id: ClientId, role: Role<'a>, peer: SocketAddr, routes: &[Route], opts: &ServerOptions) -> Self {
        let now = routes.first().map_or(Duration::ZERO, |r| r.line.now());
        Self {
            id,
            role,
            peer_high: opts.policy.peer_high(peer.ip()),
            bucket: opts.rate_limit.map(|rate| RateLimit::new(rate, now)),
        }
    }
}

/// Puts one request through the gateway core's admission policy, then the cache, then queues it
/// on its line; what to answer.
pub(super) fn request(
    client: &mut Client<'_>,
    transaction_id: u16,
    unit: u8,
    pdu: Vec<u8>,
    routes: &[Route],
    opts: &ServerOptions,
) -> Pending {
    let function = pdu.first().copied().unwrap_or(0);
    let reply = |answer| Pending { transaction_id, unit, function, answer };
    let refuse = |why: Refusal| {
        // Server-wide refusals are counted with the first line's metrics (the one exported).
        if let Some(r) = routes.first() {
            r.line.metrics.refused(why.reason());
        }
        reply(Answer::Now(Reply::Gateway(why.exception())))
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
        return reply(Answer::Now(Reply::Pdu(answer)));
    }
    let (tx, rx) = oneshot::channel();
    let write = route.line.write_pending(target, &pdu);
    let job = Job { unit: target, pdu, reply: tx, queued: Instant::now(), high: admitted.high, write };
    match route.line.submit(client.id, job) {
        Ok(()) => reply(Answer::Later(rx)),
        Err(_) => refuse(Refusal::QueueFull),
    }
}
