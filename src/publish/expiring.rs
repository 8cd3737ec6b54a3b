//! Connections of the spy server under the bridge's rules: a connection silent for
//! the idle timeout is closed, and when every place is taken the gateway's one seat decision
//! ([`mbtap_gateway::seats::for_room`]) says whose place the newcomer takes — a socket
//! that never sent a byte, then the one stalled longest, else the idlest — instead of being
//! refused while idle sockets hold every place. (A grace for young silent sockets would let a
//! flood of them starve newcomers: none is given.)
//! tokio-modbus runs each connection's request loop itself; the stream it is given
//! ([`Expiring`]) keeps the time of the last byte read and ends (EOF) when it idles out or is
//! evicted.

use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll, Waker};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::{Instant, Sleep};

/// A connection's state as the table sees it.
#[derive(Debug)]
pub struct Conn {
    opened: Instant,
    /// When the client last sent a byte (None: never).
    last_read: Mutex<Option<Instant>>,
    evicted: AtomicBool,
    waker: Mutex<Option<Waker>>,
}

impl Conn {
    fn evict(&self) {
        self.evicted.store(true, Ordering::SeqCst);
        if let Some(w) = self.waker.lock().unwrap_or_else(PoisonError::into_inner).take() {
            w.wake();
        }
    }

    fn last_read(&self) -> Option<Instant> {
        *self.last_read.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The open connections (weak: a connection that ended leaves by itself), and the origin of
/// the times the seat decision is given.
#[derive(Debug)]
pub struct Connections {
    conns: Mutex<Vec<std::sync::Weak<Conn>>>,
    origin: Instant,
}

impl Default for Connections {
    fn default() -> Self {
        Self { conns: Mutex::new(Vec::new()), origin: Instant::now() }
    }
}

impl Connections {
    /// A new connection's state, registered.
    pub fn open(&self) -> Arc<Conn> {
        let c = Arc::new(Conn {
            opened: Instant::now(),
            last_read: Mutex::new(None),
            evicted: AtomicBool::new(false),
            waker: Mutex::new(None),
        });
        let mut t = self.conns.lock().unwrap_or_else(PoisonError::into_inner);
        t.retain(|w| w.strong_count() > 0);
        t.push(Arc::downgrade(&c));
        c
    }

    /// Ends one connection to make room, the one the gateway's seat decision names (the spy
    /// server sees bytes, not requests: a byte stands for both). False when every connection is
    /// busy.
    pub fn evict_idlest(&self, now: Instant) -> bool {
        let t = self.conns.lock().unwrap_or_else(PoisonError::into_inner);
        let live: Vec<Arc<Conn>> =
            t.iter().filter_map(std::sync::Weak::upgrade).filter(|c| !c.evicted.load(Ordering::SeqCst)).collect();
        drop(t);
        let since = |i: Instant| i.saturating_duration_since(self.origin);
        let seats: Vec<mbtap_gateway::seats::Seat> = live
            .iter()
            .map(|c| {
                let last = c.last_read().map(since);
                mbtap_gateway::seats::Seat {
                    ip: std::net::IpAddr::V4(std::net::Ipv4Addr::UNSPECIFIED),
                    opened: since(c.opened),
                    last_request: last,
                    last_byte: last,
                }
            })
            .collect();
        match mbtap_gateway::seats::for_room(seats.iter().enumerate(), since(now)).and_then(|i| live.get(i)) {
            Some(c) => {
                c.evict();
                true
            }
            None => false,
        }
    }
}

/// A stream that ends (reads EOF) after `idle` without a byte from the client, or when its
/// connection is evicted.
#[derive(Debug)]
pub struct Expiring<S> {
    inner: S,
    idle: Duration,
    deadline: Pin<Box<Sleep>>,
    conn: Arc<Conn>,
}

impl<S> Expiring<S> {
    pub fn new(inner: S, idle: Duration, conn: Arc<Conn>) -> Self {
        Self { inner, idle, deadline: Box::pin(tokio::time::sleep(idle)), conn }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Expiring<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<std::io::Result<()>> {
        if self.conn.evicted.load(Ordering::SeqCst) {
            return Poll::Ready(Ok(()));
        }
        *self.conn.waker.lock().unwrap_or_else(PoisonError::into_inner) = Some(cx.waker().clone());
        let before = buf.filled().len();
        match Pin::new(&mut self.inner).poll_read(cx, buf) {
            Poll::Ready(Ok(())) if buf.filled().len() > before => {
                let now = Instant::now();
                *self.conn.last_read.lock().unwrap_or_else(PoisonError::into_inner) = Some(now);
                let idle = self.idle;
                self.deadline.as_mut().reset(now + idle);
                Poll::Ready(Ok(()))
            }
            Poll::Pending => match self.deadline.as_mut().poll(cx) {
                // Idle too long: the connection ends as if the client had closed it.
                Poll::Ready(()) => Poll::Ready(Ok(())),
                Poll::Pending => Poll::Pending,
            },
            other @ Poll::Ready(_) => other,
        }
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Expiring<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, data)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn a_silent_socket_gives_its_place_then_the_idlest() {
        let t = Connections::default();
        let older = t.open();
        tokio::time::advance(Duration::from_millis(10)).await;
        let _young = t.open();
        // The bridge's rule: a silent socket gives its place at once, whatever its age (a
        // grace for young silent sockets would let a flood of them starve newcomers), the one
        // opened first before younger ones.
        assert!(t.evict_idlest(Instant::now()));
        assert!(older.evicted.load(Ordering::SeqCst));
        let _ = t.evict_idlest(Instant::now());
        let busy = t.open();
        *busy.last_read.lock().unwrap_or_else(PoisonError::into_inner) = Some(Instant::now());
        assert!(!t.evict_idlest(Instant::now()), "busy: the newcomer is refused");
        tokio::time::advance(mbtap_gateway::seats::EVICT_AFTER_IDLE).await;
        assert!(t.evict_idlest(Instant::now()));
    }

    #[tokio::test(start_paused = true)]
    async fn a_stream_ends_after_its_idle_time_and_when_evicted() {
        use tokio::io::AsyncReadExt as _;
        let (client, server) = tokio::io::duplex(64);
        let t = Connections::default();
        let mut w = Expiring::new(server, Duration::from_secs(5), t.open());
        let mut buf = [0u8; 8];
        let n = w.read(&mut buf).await.unwrap_or(99);
        assert_eq!(n, 0, "EOF after the idle time");
        drop(client);
        let (_client, server) = tokio::io::duplex(64);
        let conn = t.open();
        let mut w = Expiring::new(server, Duration::from_hours(1), Arc::clone(&conn));
        let reader = tokio::spawn(async move { w.read(&mut buf).await.unwrap_or(99) });
        tokio::task::yield_now().await;
        conn.evict();
        assert_eq!(reader.await.unwrap_or(99), 0, "EOF when evicted");
    }
}
