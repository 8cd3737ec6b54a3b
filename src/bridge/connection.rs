//! One client's TCP connection (plain or TLS; MBAP or raw RTU frames): its requests read and
//! handed to [`super::request`], its answers written back in order. Each connection is on its
//! own: a malformed header, a flood, a dribbling or idle client ends only that connection.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use super::request::{Client, Pending, Routes, ServerOptions, request};
use mbtap_gateway::admit::Role;
use mbtap_gateway::lifetime::{Fate, Ids, Lifetime};
use mbtap_gateway::queue::ClientId;
use mbtap_proto::tcp::{Streaming, parse_tcp_frame};
use mbtap_proto::{encode_rtu, encode_tcp};

/// A pause that ends an RTU-over-TCP frame of unknown length.
const RTU_OVER_TCP_SILENCE: Duration = Duration::from_millis(50);
/// A request must arrive whole this soon after its first byte (at most 260 bytes: one TCP
/// segment on any network a Modbus client uses): a client dribbling bytes holds no slot longer.
const REQUEST_DEADLINE: Duration = Duration::from_secs(2);
/// Bytes an RTU-over-TCP client may send without a request among them before it is cut off:
/// sixteen of the longest frames.
const RTU_GARBAGE_LIMIT: u64 = 16 * 256;

/// One client's connection until it closes, misbehaves or idles out; `seen` is told of every
/// whole request (for eviction); `role_name`: its TLS certificate's role, for the audit.
#[allow(clippy::too_many_arguments)] // the connection's parts, each passed once by the server
pub(super) async fn connection<S>(
    stream: S,
    peer: SocketAddr,
    client: ClientId,
    routes: &Arc<Routes>,
    opts: &ServerOptions,
    seen: &(dyn Fn(ClientId) + Sync),
    role: Role<'_>,
    role_name: Option<String>,
) where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + 'static,
{
    // `--priority high=ip:…`: the whole connection's requests.
    let tls = matches!(role, Role::Tls(_));
    let mut client = Client::new(client, role, peer, routes, opts);
    if tls {
        client = client.known_as("tls", role_name);
    }
    let (mut rd, mut wr) = tokio::io::split(stream);
    let (tx, mut rx) = mpsc::channel::<(u64, Pending)>(64);
    // Requests numbered as they come; whether the client still waits for each, and what its
    // answer becomes, is the gateway core's one rule (`mbtap_gateway::lifetime`): MBAP clients
    // have ids, RTU-over-TCP clients do not. The reader tells the writer which requests the
    // client gave up on.
    let rtu = opts.rtu_over_tcp;
    let lifetime = Arc::new(Mutex::new(Lifetime::new(if rtu { Ids::None } else { Ids::Has })));
    let (give_up, mut given_up) = watch::channel(0u64);
    let born = Instant::now();
    let writer = {
        let (lifetime, counts) = (Arc::clone(&lifetime), Arc::clone(routes));
        tokio::spawn(async move {
            let mut out = Vec::with_capacity(300);
            while let Some((seq, p)) = rx.recv().await {
                let (transaction_id, unit) = (p.transaction_id, p.unit);
                let abandoned = |below: &u64| *below > seq;
                let pdu = if abandoned(&given_up.borrow()) {
                    // Dropping it closes its reply: the line skips it if it has not started.
                    None
                } else {
                    tokio::select! {
                        biased;
                        pdu = p.answer_pdu() => Some(pdu),
                        () = async {
                            // The reader gone (the connection ends): answers still go out.
                            if given_up.wait_for(abandoned).await.is_err() {
                                std::future::pending::<()>().await;
                            }
                        } => None,
                    }
                };
                let fate = {
                    let mut l = lifetime.lock().unwrap_or_else(PoisonError::into_inner);
                    match &pdu {
                        None => Fate::Withhold,
                        Some(None) => {
                            l.unanswered(seq);
                            Fate::Deliver
                        }
                        Some(Some(_)) => l.answer(seq, born.elapsed()),
                    }
                };
                let Some(pdu) = pdu.filter(|_| fate == Fate::Deliver) else {
                    if rtu {
                        counts.server.abandoned(1);
                    } else {
                        counts.server.withheld_sequential();
                    }
                    continue;
                };
                // A broadcast: nobody answers it.
                let Some(pdu) = pdu else { continue };
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
        })
    };
    let mut next_seq = 0u64;
    // Numbers a request, notes whether the client gave up on the older ones, and hands it to
    // the writer; false once the writer is gone.
    let mut hand_on = async |pending: Pending| {
        let seq = next_seq;
        next_seq += 1;
        let gave_up = lifetime.lock().unwrap_or_else(PoisonError::into_inner).asked(seq, born.elapsed());
        if let Some(below) = gave_up {
            let _ = give_up.send(below);
        }
        tx.send((seq, pending)).await.is_ok()
    };
    let mut buf = Vec::with_capacity(600);
    let mut chunk = [0u8; 1024];
    let mut rtu_frames = mbtap_proto::request_frames::RtuRequestFramer::default();
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
                    if !hand_on(pending).await {
                        break;
                    }
                }
                partial_since = None;
                continue;
            }
            Err(_) if partial_since.is_some() => {
                // Slowloris: a request begun and never finished ends this connection only.
                routes.server.refused("slow_request");
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
                        routes.server.refused("garbage");
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
                        routes.server.refused("malformed_mbap");
                        break 'read;
                    }
                }
            };
            last_request = Instant::now();
            seen(client.id);
            let pending = request(&mut client, transaction_id, unit, pdu, routes, opts);
            if !hand_on(pending).await {
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
