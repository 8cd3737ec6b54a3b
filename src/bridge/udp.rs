//! Modbus UDP clients (`--listen-udp`): one MBAP ADU per datagram (Messaging on TCP/IP v1.0b
//! §4.1 framing, carried in UDP as Modbus UDP gateways do), checked and queued exactly as a TCP
//! client's requests are — the allow-lists, read-only rules, rate limit, routes, queue and cache
//! of the TCP listener — and each answer sent back to the datagram's sender. A datagram that is
//! not exactly one well-formed ADU is dropped and counted; a sender is a client of its own for
//! the fair queue (its address, up to [`MAX_PEERS`] remembered).

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use tokio::time::Instant;

use mbtap_proto::tcp::{Streaming, encode_tcp, parse_tcp_frame};
use tokio::net::UdpSocket;

use super::request::{Client, Pending, Routes, ServerOptions, request};
use mbtap_gateway::admit::{Role, canonical, ip_allowed};

/// Senders remembered (their client id and rate-limit bucket); the oldest is forgotten beyond.
const MAX_PEERS: usize = 1024;
/// The largest datagram read: an MBAP ADU is at most 260 bytes (MAP v1.1b3 §4.1 + 7).
const DATAGRAM: usize = 2048;

struct Peer {
    client: Client<'static>,
    last: Instant,
}

/// Serves Modbus UDP on `socket` until the process ends.
pub async fn serve_udp(socket: UdpSocket, routes: Arc<Routes>, opts: Arc<ServerOptions>) {
    let socket = Arc::new(socket);
    let mut peers: HashMap<IpAddr, Peer> = HashMap::new();
    let mut buf = vec![0u8; DATAGRAM];
    loop {
        let Ok((n, peer)) = socket.recv_from(&mut buf).await else { continue };
        let metrics = &routes.server;
        if !ip_allowed(&opts.allow_ips, peer.ip()) {
            metrics.refused("ip_not_allowed");
            continue;
        }
        let datagram = buf.get(..n).unwrap_or_default();
        let (transaction_id, unit, pdu) = match parse_tcp_frame(datagram) {
            Ok(Streaming::Complete(f, used)) if used == n => (f.header.transaction_id, f.header.unit, f.pdu.to_vec()),
            // Short, long, two ADUs in one datagram, protocol id ≠ 0: dropped, counted.
            _ => {
                metrics.refused("malformed_mbap");
                continue;
            }
        };
        // An IPv4-mapped IPv6 source is that IPv4 address: one client either way.
        let source = canonical(peer.ip());
        if !peers.contains_key(&source)
            && peers.len() >= MAX_PEERS
            && let Some(oldest) = peers.iter().min_by_key(|(_, p)| p.last).map(|(a, _)| *a)
            && let Some(gone) = peers.remove(&oldest)
        {
            // Forgotten: its waiting requests go with it, they spend no line time.
            for r in routes.iter() {
                r.line.forget(gone.client.id);
            }
            metrics.refused("udp_peer_evicted");
        }
        let p = peers.entry(source).or_insert_with(|| Peer {
            client: Client::new(mbtap_gateway::clients::udp_peer(), Role::Plain, peer, &routes, &opts)
                .known_as("udp", None),
            last: Instant::now(),
        });
        p.last = Instant::now();
        let pending = request(&mut p.client, transaction_id, unit, pdu, &routes, &opts);
        let socket = Arc::clone(&socket);
        // The answer goes back when it comes; the next datagram is read meanwhile.
        tokio::spawn(async move { answer(&socket, peer, pending).await });
    }
}

/// Sends the answer to `pending` to `peer` (nothing for a broadcast).
async fn answer(socket: &UdpSocket, peer: SocketAddr, p: Pending) {
    let (transaction_id, unit) = (p.transaction_id, p.unit);
    let Some(pdu) = p.answer_pdu().await else { return };
    let mut out = Vec::with_capacity(pdu.len() + 7);
    encode_tcp(transaction_id, unit, &pdu, &mut out);
    // A sender that is gone is not an error of the bridge's.
    let _ = socket.send_to(&out, peer).await;
}
