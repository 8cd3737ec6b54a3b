//! A socket that notes when it last brought bytes in: the seat decision
//! (`mbtap_gateway::seats`) tells a client still talking — a TLS handshake under way, a request
//! arriving — from a socket that stalled, whatever their ages (under a TLS flood, handing the
//! oldest socket's seat to each newcomer whatever it is doing resets 2–3 % of TLS clients
//! mid-handshake).

use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// When the socket last brought bytes in, in nanoseconds on the listeners' clock plus one (0:
/// never).
pub type LastByte = Arc<AtomicU64>;

/// `inner`, with its reads noted in `last` as `clock()` says.
#[derive(Debug)]
pub struct Watched<S> {
    pub inner: S,
    pub last: LastByte,
    pub clock: fn() -> std::time::Duration,
}

impl<S: AsyncRead + Unpin> AsyncRead for Watched<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let polled = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(polled, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            let at = u64::try_from((self.clock)().as_nanos()).unwrap_or(u64::MAX).saturating_add(1);
            self.last.store(at, Ordering::Relaxed);
        }
        polled
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Watched<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
}

/// The time `last` holds, when bytes ever came.
#[must_use]
pub fn last_byte(last: &LastByte) -> Option<std::time::Duration> {
    match last.load(Ordering::Relaxed) {
        0 => None,
        n => Some(std::time::Duration::from_nanos(n - 1)),
    }
}
