//! The TCP side of the bridge: Modbus TCP (MBAP, Messaging on TCP/IP v1.0b §3.1) or raw RTU
//! frames over TCP, many clients at once. Each connection is on its own: a malformed header,
//! a flood or a disconnect affects only that connection. Requests go to the line of their unit
//! ([`Route`]); answers come back in the order the client asked, with its transaction id and
//! unit id unchanged.

use std::sync::Arc;
use std::time::Duration;

use tokio::net::TcpListener;
use tokio::time::Instant;

use super::connection::connection;
pub use super::request::{Route, Routes, ServerOptions};
use mbtap_gateway::admit::{Role, canonical, ip_allowed};
use mbtap_gateway::queue::ClientId;
use mbtap_gateway::seats::{self, Seat};

/// One open connection: its seat (address, when it opened, when it last sent a whole request:
/// what the gateway core's [`seats`] decision reads) and how to end it.
#[derive(Debug)]
pub struct Conn {
    seat: Seat,
    /// When its socket last brought bytes in ([`super::watched`]).
    last_byte: super::watched::LastByte,
    abort: tokio::task::AbortHandle,
}

/// The open connections of every listener (plain, RTU over TCP, TLS) — the connection limit is
/// theirs together, so a full table evicts a socket that never asked (a TLS handshake in
/// progress counts as one), or its idlest member, whichever listener holds it, instead of
/// refusing everyone new (64 idle RTU sockets must not lock out every Modbus TCP client).
pub type Connections = std::sync::Mutex<std::collections::HashMap<ClientId, Conn>>;

/// Ends a connection's bookkeeping however it ends — closed, failed or evicted (an aborted
/// task runs its destructors, not its remaining code).
struct Cleanup {
    client: ClientId,
    routes: Arc<Routes>,
    table: Arc<Connections>,
}

impl Drop for Cleanup {
    fn drop(&mut self) {
        for r in self.routes.iter() {
            r.line.forget(self.client);
        }
        self.routes.server.connection_closed();
        self.table.lock().unwrap_or_else(std::sync::PoisonError::into_inner).remove(&self.client);
    }
}

/// Ends the connection the gateway core's [`seats`] decision names: for `ip`'s bound of silent
/// sockets, or (None) to make room in a full table. False when none may go.
fn evict(table: &Connections, ip: Option<std::net::IpAddr>) -> bool {
    let table = table.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // The seats as they are now: each with when its socket last brought bytes in.
    let now_seats: Vec<(ClientId, Seat)> = table
        .iter()
        .map(|(k, c)| (*k, Seat { last_byte: super::watched::last_byte(&c.last_byte), ..c.seat }))
        .collect();
    let all = now_seats.iter().map(|(k, s)| (*k, s));
    let victim = match ip {
        Some(ip) => seats::for_address(all, ip, now()),
        None => seats::for_room(all, now()),
    };
    victim.and_then(|k| table.get(&k)).map(|c| c.abort.abort()).is_some()
}

/// The listeners' clock for the seat decisions: time since the first call.
fn now() -> Duration {
    static ORIGIN: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    ORIGIN.get_or_init(Instant::now).elapsed()
}

/// How long a TLS client has to complete its handshake: a handshake is a few round trips.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(3);

/// Accepts connections forever.
/// With `tls`, each connection first completes a TLS handshake with a client certificate
/// (within [`HANDSHAKE_TIMEOUT`]); its role decides what it may do.
pub async fn serve(
    listener: TcpListener,
    routes: Arc<Routes>,
    opts: Arc<ServerOptions>,
    tls: Option<super::tls::Tls>,
    table: Arc<Connections>,
) {
    loop {
        let Ok((stream, peer)) = listener.accept().await else {
            // Out of file descriptors or similar: back off a little, keep serving.
            tokio::time::sleep(Duration::from_millis(50)).await;
            continue;
        };
        let metrics = &routes.server;
        if !ip_allowed(&opts.allow_ips, peer.ip()) {
            metrics.refused("ip_not_allowed");
            continue;
        }
        let ip = canonical(peer.ip());
        if evict(&table, Some(ip)) {
            metrics.refused("evicted_silent");
            tokio::task::yield_now().await;
        }
        if metrics.open_connections() >= i64::try_from(opts.max_connections).unwrap_or(i64::MAX) {
            // Full: a silent socket, else the idlest connection makes room (idle sockets must
            // not lock everyone out); when all are busy, the newcomer is refused.
            if evict(&table, None) {
                metrics.refused("evicted_idle");
                // Its slot frees when its task has run its cleanup.
                tokio::task::yield_now().await;
            } else {
                metrics.refused("max_connections");
                continue;
            }
        }
        metrics.connection_opened();
        let client = mbtap_gateway::clients::connection();
        let (routes, opts, table_for_task, tls) =
            (Arc::clone(&routes), Arc::clone(&opts), Arc::clone(&table), tls.clone());
        let last_byte = super::watched::LastByte::default();
        let _ = stream.set_nodelay(true);
        let stream = super::watched::Watched { inner: stream, last: Arc::clone(&last_byte), clock: now };
        // Registered before the task runs, so its cleanup always finds (and removes) it.
        let mut entries = table.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let handle = tokio::spawn(async move {
            let cleanup = Cleanup { client, routes: Arc::clone(&routes), table: Arc::clone(&table_for_task) };
            let seen = |c| {
                if let Some(e) = table_for_task.lock().unwrap_or_else(std::sync::PoisonError::into_inner).get_mut(&c) {
                    e.seat.last_request = Some(now());
                }
            };
            match &tls {
                None => connection(stream, peer, client, &routes, &opts, &seen, Role::Plain, None).await,
                Some(tls) => {
                    let metrics = &routes.server;
                    let Some(acceptor) = tls.current() else { return };
                    match tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(stream)).await {
                        Ok(Ok(tls_stream)) => {
                            let cert =
                                tls_stream.get_ref().1.peer_certificates().and_then(|c| c.first()).map(|c| c.to_vec());
                            let role = cert.as_deref().and_then(super::tls::role_of);
                            let policy = role.as_ref().and_then(|r| tls.roles.get(r));
                            // A session whose certificate a reloaded CRL revokes ends at once,
                            // not at its next connection.
                            let revoked = tls.revocation(cert.as_deref().unwrap_or_default());
                            tokio::select! {
                                () = connection(tls_stream, peer, client, &routes, &opts, &seen, Role::Tls(policy), role.clone()) => {}
                                () = revoked => {
                                    metrics.refused("revoked");
                                    eprintln!("mbtap: TLS client {peer}: its certificate is revoked by the reloaded CRL; session closed");
                                }
                            }
                        }
                        // No certificate, an expired one, one from another CA, a slow or
                        // broken handshake: the connection ends here, counted.
                        Ok(Err(_)) => {
                            metrics.refused("tls_handshake");
                        }
                        Err(_) => {
                            metrics.refused("tls_handshake_timeout");
                        }
                    }
                }
            }
            drop(cleanup);
        });
        let seat = Seat { ip, opened: now(), last_request: None, last_byte: None };
        entries.insert(client, Conn { seat, last_byte, abort: handle.abort_handle() });
        drop(entries);
    }
}
