//! `read`, `write`, `watch`, `probe` with `--mode ascii`: the port wrapped so that tokio-modbus's
//! RTU client speaks Modbus ASCII on it. Each frame it writes leaves, at its flush, as one ASCII
//! frame; ASCII frames heard are handed to it as RTU frames ([`mbtap_proto::ascii_link`] does
//! both, sans-IO). A frame heard with a bad LRC is dropped, so the request times out as one
//! with a damaged answer does in RTU; the count is kept for the message.

use std::pin::Pin;
use std::task::{Context, Poll};

use mbtap_proto::ascii_link::AsciiLink;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

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
        loop {
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
