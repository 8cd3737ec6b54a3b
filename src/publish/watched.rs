//! Connections of the spy server under the bridge's rules (issue 24): a connection silent for
//! the idle timeout is closed, and when every place is taken the newcomer gets the place of a
//! socket that never sent a byte (after a short grace) or of the idlest one, instead of being
//! refused while idle sockets hold every place. tokio-modbus runs each connection's
//! request loop itself; the stream it is given ([`Watched`]) keeps the time of the last byte
//! read and ends (EOF) when it idles out or is evicted.

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

/// The open connections (weak: a connection that ended leaves by itself).
#[derive(Debug, Default)]
pub struct Table(Mutex<Vec<std::sync::Weak<Conn>>>);

/// A connection that never sent a byte gives its place after this long.
pub const FIRST_REQUEST_GRACE: Duration = Duration::from_millis(200);
/// A connection quiet this long gives its place to a newcomer when the table is full.
pub const EVICT_AFTER_IDLE: Duration = Duration::from_secs(1);

impl Table {
    /// A new connection's state, registered.
    pub fn open(&self) -> Arc<Conn> {
        let c = Arc::new(Conn {
            opened: Instant::now(),
            last_read: Mutex::new(None),
            evicted: AtomicBool::new(false),
            waker: Mutex::new(None),
        });
        let mut t = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        t.retain(|w| w.strong_count() > 0);
        t.push(Arc::downgrade(&c));
        c
    }

    /// Ends one connection to make room: the oldest that never sent a byte within
    /// [`FIRST_REQUEST_GRACE`], else the idlest quiet for [`EVICT_AFTER_IDLE`]. False when every
    /// connection is busy.
    pub fn evict_idlest(&self, now: Instant) -> bool {
        let t = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        let live: Vec<Arc<Conn>> =
            t.iter().filter_map(std::sync::Weak::upgrade).filter(|c| !c.evicted.load(Ordering::SeqCst)).collect();
        drop(t);
        let silent = live
            .iter()
            .filter(|c| c.last_read().is_none() && now.saturating_duration_since(c.opened) >= FIRST_REQUEST_GRACE)
            .min_by_key(|c| c.opened);
        let idlest = || {
            live.iter()
                .filter_map(|c| c.last_read().map(|l| (l, c)))
                .filter(|(l, _)| now.saturating_duration_since(*l) >= EVICT_AFTER_IDLE)
                .min_by_key(|(l, _)| *l)
                .map(|(_, c)| c)
        };
        match silent.or_else(idlest) {
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
pub struct Watched<S> {
    inner: S,
    idle: Duration,
    deadline: Pin<Box<Sleep>>,
    conn: Arc<Conn>,
}

impl<S> Watched<S> {
    pub fn new(inner: S, idle: Duration, conn: Arc<Conn>) -> Self {
        Self { inner, idle, deadline: Box::pin(tokio::time::sleep(idle)), conn }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Watched<S> {
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

impl<S: AsyncWrite + Unpin> AsyncWrite for Watched<S> {
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
        let t = Table::default();
        let quiet = t.open();
        tokio::time::advance(Duration::from_millis(100)).await;
        assert!(!t.evict_idlest(Instant::now()), "within the grace");
        tokio::time::advance(Duration::from_millis(150)).await;
        assert!(t.evict_idlest(Instant::now()));
        assert!(quiet.evicted.load(Ordering::SeqCst));
        let busy = t.open();
        *busy.last_read.lock().unwrap_or_else(PoisonError::into_inner) = Some(Instant::now());
        assert!(!t.evict_idlest(Instant::now()), "busy: the newcomer is refused");
        tokio::time::advance(EVICT_AFTER_IDLE).await;
        assert!(t.evict_idlest(Instant::now()));
    }

    #[tokio::test(start_paused = true)]
    async fn a_stream_ends_after_its_idle_time_and_when_evicted() {
        use tokio::io::AsyncReadExt as _;
        let (client, server) = tokio::io::duplex(64);
        let t = Table::default();
        let mut w = Watched::new(server, Duration::from_secs(5), t.open());
        let mut buf = [0u8; 8];
        let n = w.read(&mut buf).await.unwrap_or(99);
        assert_eq!(n, 0, "EOF after the idle time");
        drop(client);
        let (_client, server) = tokio::io::duplex(64);
        let conn = t.open();
        let mut w = Watched::new(server, Duration::from_hours(1), Arc::clone(&conn));
        let reader = tokio::spawn(async move { w.read(&mut buf).await.unwrap_or(99) });
        tokio::task::yield_now().await;
        conn.evict();
        assert_eq!(reader.await.unwrap_or(99), 0, "EOF when evicted");
    }
}
