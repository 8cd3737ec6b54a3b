//! The TCP side of the bridge: Modbus TCP (MBAP, Messaging on TCP/IP v1.0b §3.1) or raw RTU
//! frames over TCP, many clients at once. Each connection is on its own: a malformed header,
//! a flood or a disconnect affects only that connection. Requests go to the line of their unit
//! ([`Route`]); answers come back in the order the client asked, with its transaction id and
//! unit id unchanged.

use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};
use std::ops::RangeInclusive;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot};
use tokio::time::Instant;

use super::line::{GATEWAY_PATH_UNAVAILABLE, GATEWAY_TARGET_FAILED, Job, LineShared, Reply, SERVER_DEVICE_BUSY};
use super::queue::ClientId;
pub use super::rules::{ILLEGAL_DATA_VALUE, ILLEGAL_FUNCTION, read_only_safe};
use mbtap_core::proto::tcp::{Streaming, parse_tcp_frame};
use mbtap_core::proto::{encode_rtu, encode_tcp, request_len_problem};

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
    /// Only requests that cannot change a device pass ([`read_only_safe`]); everything else is
    /// answered with exception 01 and never reaches the line.
    pub read_only: bool,
    /// Without `read_only`: only these function codes pass (None: all). With it: these pass
    /// too, on top of the read-only set — how a vendor read such as 0x46 is let through.
    pub allow_functions: Option<Vec<u8>>,
    /// Only these client addresses may connect (empty: all).
    pub allow_ips: Vec<IpNet>,
    pub max_connections: usize,
    /// A connection silent this long is closed.
    pub idle_timeout: Duration,
    /// Requests per second per connection (None: no limit); above it: exception 06.
    pub rate_limit: Option<f64>,
    /// TCP unit id → serial address.
    pub unit_map: BTreeMap<u8, u8>,
    /// `--priority high=…`: requests that go before the round-robin.
    pub priority: Vec<Priority>,
}

/// One `--priority high=…` rule: a client network, units or function codes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Priority {
    Net(IpNet),
    Units(std::collections::BTreeSet<u8>),
    Functions(std::collections::BTreeSet<u8>),
}

/// `high=ip:10.0.0.0/24`, `high=unit:1-5`, `high=fc:5,6,15,16`.
///
/// # Errors
/// What is wrong with the value.
pub fn parse_priority(spec: &str) -> Result<Priority, String> {
    let bad =
        |why: String| format!("--priority {spec:?}: {why}; expected high=ip:NET, high=unit:UNITS or high=fc:CODES");
    let rule = spec.strip_prefix("high=").ok_or_else(|| bad("only the class \"high\" exists".into()))?;
    match rule.split_once(':') {
        Some(("ip", net)) => net.parse().map(Priority::Net).map_err(bad),
        Some(("unit", units)) => {
            super::parse::parse_units(units).map(Priority::Units).map_err(|e| bad(format!("{e:#}")))
        }
        Some(("fc", codes)) => super::parse::parse_function_codes(codes)
            .map(Priority::Functions)
            .ok_or_else(|| bad(format!("{codes:?} is not a list of function codes"))),
        _ => Err(bad(format!("{rule:?}"))),
    }
}

/// An address or a network (`192.168.1.0/24`, `::1`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IpNet {
    pub addr: IpAddr,
    pub prefix: u8,
}

impl std::str::FromStr for IpNet {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("{s:?} is not an IP address or network like 192.168.1.0/24");
        let (a, p) = s.split_once('/').map_or((s, None), |(a, p)| (a, Some(p)));
        let addr: IpAddr = a.trim().parse().map_err(|_| bad())?;
        let max = if addr.is_ipv4() { 32 } else { 128 };
        let prefix = match p {
            Some(p) => p.trim().parse::<u8>().ok().filter(|&p| p <= max).ok_or_else(bad)?,
            None => max,
        };
        // An IPv4-mapped IPv6 address (::ffff:10.0.0.5) is that IPv4 address: peers are compared
        // in their IPv4 form, so the net must be too, or it would match no one.
        if let IpAddr::V6(v6) = addr
            && let Some(v4) = v6.to_ipv4_mapped()
            && prefix >= 96
        {
            return Ok(Self { addr: IpAddr::V4(v4), prefix: prefix - 96 });
        }
        Ok(Self { addr, prefix })
    }
}

impl IpNet {
    #[must_use]
    pub fn contains(&self, ip: IpAddr) -> bool {
        let ip = match ip {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
            v4 @ IpAddr::V4(_) => v4,
        };
        match (self.addr, ip) {
            (IpAddr::V4(net), IpAddr::V4(ip)) => {
                let mask = u32::MAX.checked_shl(32 - u32::from(self.prefix)).unwrap_or(0);
                u32::from(net) & mask == u32::from(ip) & mask
            }
            (IpAddr::V6(net), IpAddr::V6(ip)) => {
                let mask = u128::MAX.checked_shl(128 - u32::from(self.prefix)).unwrap_or(0);
                u128::from(net) & mask == u128::from(ip) & mask
            }
            _ => false,
        }
    }
}

/// Function codes a broadcast may carry (Serial Line v1.02 §2.1: broadcasts are writes only,
/// MAP v1.1b3 §6.5, 6.6, 6.11, 6.12, 6.15, 6.16).
fn broadcastable(fc: u8) -> bool {
    matches!(fc, 0x05 | 0x06 | 0x0F | 0x10 | 0x15 | 0x16)
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
        if !opts.allow_ips.is_empty() && !opts.allow_ips.iter().any(|n| n.contains(peer.ip())) {
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
            Reply::Gateway(code) => Some(vec![self.function | 0x80, code]),
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
    let peer_high = opts.priority.iter().any(|p| matches!(p, Priority::Net(n) if n.contains(peer.ip())));
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
    let mut bucket = opts.rate_limit.map(|r| (r.max(1.0), Instant::now()));
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
                    seen(client);
                    let pending = request(client, 0, f.unit, f.pdu, routes, opts, &mut bucket, role, peer_high);
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
            seen(client);
            let pending = request(client, transaction_id, unit, pdu, routes, opts, &mut bucket, role, peer_high);
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

/// Who the client is, for authorisation: anyone on a plain listener; on the TLS listener the
/// policy of its certificate's role, or none (no role, or one no rule names: nothing allowed).
#[derive(Debug, Clone, Copy)]
pub(super) enum Role<'a> {
    Plain,
    Tls(Option<&'a super::tls::Policy>),
}

/// Checks one request and queues it on its line; what to answer.
#[allow(clippy::too_many_arguments)] // the request's fields and the connection's context
pub(super) fn request(
    client: ClientId,
    transaction_id: u16,
    unit: u8,
    pdu: Vec<u8>,
    routes: &[Route],
    opts: &ServerOptions,
    bucket: &mut Option<(f64, Instant)>,
    role: Role<'_>,
    peer_high: bool,
) -> Pending {
    let function = pdu.first().copied().unwrap_or(0);
    let reply = |answer| Pending { transaction_id, unit, function, answer };
    let metrics = routes.first().map(|r| &r.line.metrics);
    let refuse = |reason, code| {
        if let Some(m) = metrics {
            m.refused(reason);
        }
        reply(Answer::Now(Reply::Gateway(code)))
    };
    // A PDU longer (or shorter) than its function allows is never forwarded: on the line its
    // extra bytes would follow the request as a frame of their own (issue 24: a write smuggled
    // behind a read, past --read-only). Nothing is sent; the client gets 03.
    if request_len_problem(&pdu).is_some() {
        return refuse("malformed_request", ILLEGAL_DATA_VALUE);
    }
    // The serial address the request will reach: roles and routes judge that, not the TCP
    // unit id (a role limited to units 2–20 must not reach unit 1 through --map-unit 10=1).
    let target = opts.unit_map.get(&unit).copied().unwrap_or(unit);
    // MODBUS/TCP Security: a request the client's role does not authorise is answered 01.
    match role {
        Role::Tls(None) => return refuse("no_role", ILLEGAL_FUNCTION),
        Role::Tls(Some(p)) if !p.allows(target, &pdu) => return refuse("role", ILLEGAL_FUNCTION),
        Role::Plain | Role::Tls(Some(_)) => {}
    }
    let listed = opts.allow_functions.as_ref().map(|a| a.contains(&function));
    if opts.read_only {
        // An allow-list: what is not known to be harmless is refused, unless explicitly allowed.
        if !read_only_safe(&pdu) && listed != Some(true) {
            return refuse("read_only", ILLEGAL_FUNCTION);
        }
    } else if listed == Some(false) {
        return refuse("function_not_allowed", ILLEGAL_FUNCTION);
    }
    if let (Some(rate), Some((tokens, at))) = (opts.rate_limit, bucket.as_mut()) {
        // Token bucket: `rate` per second, bursts up to one second's worth.
        let now = Instant::now();
        *tokens = (*tokens + now.duration_since(*at).as_secs_f64() * rate).min(rate.max(1.0));
        *at = now;
        if *tokens < 1.0 {
            return refuse("rate_limit", SERVER_DEVICE_BUSY);
        }
        *tokens -= 1.0;
    }
    if target == 0 && !broadcastable(function) {
        // A broadcast read would make every device on the line answer at once (or none): the
        // serial-line spec allows broadcast for writes only. Nothing goes on the line.
        return refuse("broadcast_not_write", ILLEGAL_FUNCTION);
    }
    let Some(route) = routes.iter().find(|r| r.units.contains(&target) || target == 0) else {
        return refuse("no_route", GATEWAY_PATH_UNAVAILABLE);
    };
    if let Some(answer) = route.line.cached(target, &pdu) {
        return reply(Answer::Now(Reply::Pdu(answer)));
    }
    let high = peer_high
        || opts.priority.iter().any(|p| match p {
            Priority::Units(u) => u.contains(&target),
            Priority::Functions(f) => f.contains(&function),
            Priority::Net(_) => false,
        });
    let (tx, rx) = oneshot::channel();
    let write = route.line.write_pending(target, &pdu);
    let job = Job { unit: target, pdu, reply: tx, queued: Instant::now(), high, write };
    match route.line.submit(client, job) {
        Ok(()) => reply(Answer::Later(rx)),
        Err(_) => refuse("queue_full", SERVER_DEVICE_BUSY),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ip_networks_match_their_addresses() {
        let net: IpNet = "192.168.1.0/24".parse().unwrap();
        assert!(net.contains("192.168.1.77".parse().unwrap()));
        assert!(!net.contains("192.168.2.1".parse().unwrap()));
        assert!(net.contains("::ffff:192.168.1.5".parse().unwrap()), "IPv4-mapped IPv6 peers");
        let one: IpNet = "127.0.0.1".parse().unwrap();
        assert!(one.contains("127.0.0.1".parse().unwrap()));
        assert!(!one.contains("127.0.0.2".parse().unwrap()));
        let all: IpNet = "0.0.0.0/0".parse().unwrap();
        assert!(all.contains("10.1.2.3".parse().unwrap()));
        assert!("10.0.0.0/33".parse::<IpNet>().is_err());
        // Issue 15: a mapped address on the allow-list matched no client.
        let mapped: IpNet = "::ffff:127.0.0.1".parse().unwrap();
        assert!(mapped.contains("127.0.0.1".parse().unwrap()));
        assert!(mapped.contains("::ffff:127.0.0.1".parse().unwrap()));
        let mapped_net: IpNet = "::ffff:10.0.0.0/120".parse().unwrap();
        assert!(mapped_net.contains("10.0.0.77".parse().unwrap()));
        assert!(!mapped_net.contains("10.0.1.1".parse().unwrap()));
        assert!("nonsense".parse::<IpNet>().is_err());
    }

    #[test]
    fn read_only_is_an_allow_list_of_what_cannot_change_a_device() {
        // Reads and reports pass.
        for pdu in [
            &[0x01, 0, 0, 0, 8][..],
            &[0x03, 0, 0, 0, 1],
            &[0x04, 0, 0, 0, 1],
            &[0x07],
            &[0x0B],
            &[0x0C],
            &[0x11],
            &[0x14, 7, 6, 0, 4, 0, 1, 0, 2],
            &[0x18, 0, 4],
            &[0x2B, 0x0E, 1, 0],
            &[0x08, 0x00, 0x00, 0xA5, 0x37], // Return Query Data: an echo
        ] {
            assert!(read_only_safe(pdu), "{pdu:02X?} should pass");
        }
        // Everything else is refused: writes, the diagnostics that restart or silence a device,
        // CANopen (2B/0D), vendor and unknown codes, 0x00, 0x7F and exception-shaped codes.
        for pdu in [
            &[0x05, 0, 1, 0xFF, 0][..],
            &[0x06, 0, 1, 0, 3],
            &[0x0F, 0, 1, 0, 1, 1, 1],
            &[0x10, 0, 1, 0, 1, 2, 0, 1],
            &[0x15, 6, 6, 0, 4, 0, 1, 0, 1, 0, 0],
            &[0x16, 0, 4, 0, 0xF2, 0, 0x25],
            &[0x17, 0, 0, 0, 1, 0, 0, 0, 1, 2, 0, 1],
            &[0x08, 0x00, 0x01, 0x00, 0x00], // restart communications
            &[0x08, 0x00, 0x04, 0x00, 0x00], // force listen-only mode
            &[0x08, 0x00, 0x0A, 0x00, 0x00], // clear counters
            &[0x2B, 0x0D, 0, 0],
            &[0x41, 1, 2],
            &[0x46, 0, 0],
            &[0x64],
            &[0x00],
            &[0x7F],
            &[0x80],
            &[0x83, 0x02],
            &[],
        ] {
            assert!(!read_only_safe(pdu), "{pdu:02X?} should be refused");
        }
    }
}
