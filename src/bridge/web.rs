//! `bridge --web ADDR`: a live page served by the bridge itself — no external resource, working
//! offline — and its figures as JSON. `GET /` the page, `GET /api/state` the figures
//! ([`state`]), `GET /events` the same every second as server-sent events (the page's feed).
//! Read-only: nothing on it writes; any other method is 405. Bounded like every other front:
//! [`CONNECTIONS`] at once (past them a connection is closed unanswered), [`STREAMS`] of them
//! event streams, a request head of at most [`HEAD_LIMIT`] bytes within [`HEAD_TIMEOUT`], and a
//! reader that does not take an event within [`WRITE_TIMEOUT`] is dropped. Bound to loopback
//! unless told otherwise: any other address needs `--web-allow-ip` (who may look), checked at
//! start and on every connection.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use mbtap_gateway::admit::IpNet;
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;

use super::request::Routes;

/// Connections served at once.
pub const CONNECTIONS: usize = 32;
/// Event streams at once (each holds a connection).
pub const STREAMS: usize = 16;
/// The longest request head read.
pub const HEAD_LIMIT: usize = 8192;
/// How long a request head may take.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// How long one write to a reader may take before it is dropped.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);
/// How often the event stream speaks.
pub const EVERY: Duration = Duration::from_secs(1);
/// Transactions the state carries, all lines together, newest last.
pub const TRANSACTIONS: usize = 200;

/// The page: HTML, CSS and script in one file, nothing fetched from elsewhere.
const PAGE: &str = include_str!("web_page.html");

/// `--web` and `--web-allow-ip`.
#[derive(Debug, Clone)]
pub struct WebOptions {
    pub addr: String,
    pub allow: Vec<IpNet>,
}

impl WebOptions {
    /// Checks that a non-loopback address comes with an allow-list.
    ///
    /// # Errors
    /// An address that is not loopback (`0.0.0.0`, a LAN address, `:PORT`) without
    /// `--web-allow-ip`.
    pub fn check(&self, local: SocketAddr) -> anyhow::Result<()> {
        anyhow::ensure!(
            local.ip().is_loopback() || !self.allow.is_empty(),
            "--web {}: {} is not a loopback address, and the view shows every client and transaction: give --web-allow-ip NET \
             for who may look (e.g. 10.0.0.0/24), or --web 127.0.0.1:PORT",
            self.addr,
            local.ip()
        );
        Ok(())
    }

    fn admits(&self, peer: SocketAddr) -> bool {
        self.allow.is_empty() || self.allow.iter().any(|n| n.contains(peer.ip()))
    }
}

/// Binds `opts.addr`, refusing a non-loopback one without an allow-list; the listener.
///
/// # Errors
/// The address cannot be bound, or is open without an allow-list.
pub async fn bind(opts: &WebOptions) -> anyhow::Result<TcpListener> {
    let addr = crate::io::listen::bind_addr(&opts.addr);
    let listener = TcpListener::bind(&addr).await.with_context(|| format!("--web {addr}: cannot listen there"))?;
    opts.check(listener.local_addr()?)?;
    Ok(listener)
}

/// Serves the view until the process ends.
pub async fn serve(listener: TcpListener, opts: WebOptions, routes: Arc<Routes>, started: Instant) {
    let slots = Arc::new(Semaphore::new(CONNECTIONS));
    let streams = Arc::new(Semaphore::new(STREAMS));
    let opts = Arc::new(opts);
    loop {
        let Ok((stream, peer)) = listener.accept().await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        if !opts.admits(peer) {
            routes.server.refused("web_not_allowed");
            continue;
        }
        let Ok(slot) = Arc::clone(&slots).try_acquire_owned() else {
            routes.server.refused("web_connections");
            continue;
        };
        let (routes, streams) = (Arc::clone(&routes), Arc::clone(&streams));
        tokio::spawn(async move {
            let _slot = slot;
            one(stream, &routes, &streams, started).await;
        });
    }
}

/// One connection: one request, answered.
async fn one(mut stream: TcpStream, routes: &Routes, streams: &Arc<Semaphore>, started: Instant) {
    let Some(head) = read_head(&mut stream).await else { return };
    let mut words = head.split_whitespace();
    let (method, path) = (words.next().unwrap_or(""), words.next().unwrap_or(""));
    if method != "GET" {
        let _ = reply(&mut stream, "405 Method Not Allowed", "text/plain", b"read-only: GET only\n").await;
        return;
    }
    match path.split('?').next().unwrap_or("") {
        "/" | "/index.html" => {
            let _ = reply(&mut stream, "200 OK", "text/html; charset=utf-8", PAGE.as_bytes()).await;
        }
        "/api/state" => {
            let body = state(routes, started).to_string();
            let _ = reply(&mut stream, "200 OK", "application/json", body.as_bytes()).await;
        }
        "/events" => {
            let Ok(_stream_slot) = Arc::clone(streams).try_acquire_owned() else {
                let _ = reply(&mut stream, "503 Service Unavailable", "text/plain", b"too many event streams\n").await;
                return;
            };
            let head = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\n\
                        X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n";
            if write_all(&mut stream, head.as_bytes()).await.is_err() {
                return;
            }
            loop {
                let event = format!("data: {}\n\n", state(routes, started));
                // A reader that does not keep up is dropped, never waited for.
                if write_all(&mut stream, event.as_bytes()).await.is_err() {
                    return;
                }
                tokio::time::sleep(EVERY).await;
            }
        }
        _ => {
            let _ = reply(&mut stream, "404 Not Found", "text/plain", b"not here: / /api/state /events\n").await;
        }
    }
}

async fn read_head(stream: &mut TcpStream) -> Option<String> {
    let mut buf = Vec::with_capacity(1024);
    let deadline = tokio::time::Instant::now() + HEAD_TIMEOUT;
    let mut chunk = [0u8; 1024];
    while !buf.windows(4).any(|w| w == b"\r\n\r\n") {
        let n = tokio::time::timeout_at(deadline, stream.read(&mut chunk)).await.ok()?.ok()?;
        if n == 0 || buf.len() + n > HEAD_LIMIT {
            return None;
        }
        buf.extend_from_slice(chunk.get(..n)?);
    }
    Some(String::from_utf8_lossy(&buf).into_owned())
}

async fn write_all(stream: &mut TcpStream, bytes: &[u8]) -> std::io::Result<()> {
    tokio::time::timeout(WRITE_TIMEOUT, stream.write_all(bytes))
        .await
        .map_err(|_| std::io::Error::from(std::io::ErrorKind::TimedOut))?
}

async fn reply(stream: &mut TcpStream, status: &str, kind: &str, body: &[u8]) -> std::io::Result<()> {
    // Nothing on the page comes from elsewhere or runs from elsewhere.
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         X-Content-Type-Options: nosniff\r\nContent-Security-Policy: default-src 'none'; script-src 'unsafe-inline'; \
         style-src 'unsafe-inline'; connect-src 'self'; img-src data:\r\nConnection: close\r\n\r\n",
        body.len()
    );
    write_all(stream, head.as_bytes()).await?;
    write_all(stream, body).await?;
    let _ = stream.shutdown().await;
    Ok(())
}

/// The figures: lines and their units, clients, the last transactions, the server's counts.
#[must_use]
pub fn state(routes: &Routes, started: Instant) -> Value {
    let mut lines = Vec::new();
    let mut transactions = Vec::new();
    for (i, r) in routes.lines.iter().enumerate() {
        let (mut line, last) = r.line.metrics.snapshot();
        line["line"] = json!(i);
        line["units_served"] = json!(format!("{}-{}", r.units.start(), r.units.end()));
        lines.push(line);
        transactions.extend(last.into_iter().map(|mut t| {
            t["line"] = json!(i);
            t
        }));
    }
    transactions.sort_by_key(|t| t["t_ms"].as_u64().unwrap_or(0));
    let skip = transactions.len().saturating_sub(TRANSACTIONS);
    let (clients, forgotten) = routes.clients.as_ref().map(|c| c.snapshot()).unwrap_or_default();
    json!({
        "uptime_s": started.elapsed().as_secs_f64(),
        "lines": lines,
        "clients": clients,
        "clients_forgotten": forgotten,
        "transactions": transactions.split_off(skip),
        "server": routes.server.server_snapshot(),
    })
}
