//! `read`, `write`, `watch`, `probe` with `--mode ascii`: the port wrapped so that tokio-modbus's
//! RTU client speaks Modbus ASCII on it. Each frame it writes leaves, at its flush, as one ASCII
//! frame; ASCII frames heard are handed to it as RTU frames ([`mbtap_proto::ascii_link`] does
//! both, sans-IO). A frame heard with a bad LRC is dropped, so the request times out as one
//! with a damaged answer does in RTU; the count is kept for the message.

use std::pin::Pin;
use std::task::{Context, Poll};
#[cfg(test)]
use std::time::Duration;

use mbtap_proto::ascii_link::AsciiLink;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// Reads of the port in one poll before giving the runtime back.
const READS_BEFORE_YIELD: usize = 16;

/// A byte stream (a serial port, a TCP stream to a converter) speaking ASCII underneath.
#[derive(Debug)]
pub struct AsciiStream<S> {
    inner: S,
    link: AsciiLink,
    /// The ASCII frame being written, and how much of it has gone.
    out: Vec<u8>,
    out_at: usize,
}

impl<S> AsciiStream<S> {
    pub const fn new(inner: S) -> Self {
        Self { inner, link: AsciiLink::new(), out: Vec::new(), out_at: 0 }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for AsciiStream<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<std::io::Result<()>> {
        let this = &mut *self;
        // A line that streams characters and never a whole frame must not hold the runtime:
        // after a few reads without an answer the task yields (woken at once), so the caller's
        // timeout is looked at.
        for _ in 0..READS_BEFORE_YIELD {
            if this.link.has_answer() {
                buf.put_slice(&this.link.take_answer(buf.remaining()));
                return Poll::Ready(Ok(()));
            }
            let mut chars = [0u8; 256];
            let mut read = ReadBuf::new(&mut chars);
            match Pin::new(&mut this.inner).poll_read(cx, &mut read) {
                Poll::Ready(Ok(())) if read.filled().is_empty() => return Poll::Ready(Ok(())),
                Poll::Ready(Ok(())) => this.link.heard(read.filled()),
                other => return other,
            }
        }
        cx.waker().wake_by_ref();
        Poll::Pending
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for AsciiStream<S> {
    fn poll_write(mut self: Pin<&mut Self>, _cx: &mut Context<'_>, buf: &[u8]) -> Poll<std::io::Result<usize>> {
        self.link.sent(buf);
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        let this = &mut *self;
        if this.out_at >= this.out.len() {
            match this.link.take_request() {
                Ok(Some(frame)) => {
                    this.out = frame;
                    this.out_at = 0;
                }
                Ok(None) => {}
                Err(e) => {
                    return Poll::Ready(Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string())));
                }
            }
        }
        while this.out_at < this.out.len() {
            let rest = this.out.get(this.out_at..).unwrap_or_default();
            match Pin::new(&mut this.inner).poll_write(cx, rest) {
                Poll::Ready(Ok(0)) => return Poll::Ready(Err(std::io::ErrorKind::WriteZero.into())),
                Poll::Ready(Ok(n)) => this.out_at += n,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => return Poll::Pending,
            }
        }
        Pin::new(&mut this.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

    /// A line that always has characters and never a frame (a babbling device at a wrong
    /// setting): endless 'A's.
    struct Babble;

    impl AsyncRead for Babble {
        fn poll_read(self: Pin<&mut Self>, _cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<std::io::Result<()>> {
            let n = buf.remaining().min(64);
            buf.put_slice(&[b'A'; 64][..n]);
            Poll::Ready(Ok(()))
        }
    }

    #[tokio::test]
    async fn a_babbling_line_does_not_hold_the_runtime_past_the_timeout() {
        let mut s = AsciiStream::new(Babble);
        let mut buf = [0u8; 8];
        let r = tokio::time::timeout(Duration::from_millis(50), s.read(&mut buf)).await;
        assert!(r.is_err(), "the read must time out, not spin forever");
    }

    #[tokio::test]
    async fn a_written_frame_leaves_as_ascii_at_the_flush() {
        let (near, mut far) = tokio::io::duplex(256);
        let mut s = AsciiStream::new(near);
        // Unit 1, FC 03, address 0x0065, quantity 3, CRC 0xD415 low byte first.
        s.write_all(&[0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4]).await.unwrap();
        s.flush().await.unwrap();
        let mut out = [0u8; 17];
        far.read_exact(&mut out).await.unwrap();
        assert_eq!(&out, b":01030065000394\r\n");
    }
}
