//! The pseudo-terminal `tap` offers the application, read and written without a busy loop.
//!
//! A pty master reports hang-up while no program holds the slave open, and tokio keeps a
//! "read closed" readiness for good once seen: through tokio-serial's stream, every read after
//! the application has once been away (or before it first opens the path) wakes at once, fails
//! with EAGAIN and tries again — a core burnt while the application sits idle. Here the
//! master's readiness is registered afresh after every hang-up, so an idle application costs
//! nothing.

use std::fs::File;
use std::io::{Read as _, Write as _};
use std::os::fd::{AsRawFd as _, OwnedFd};
use std::path::PathBuf;

use anyhow::Context as _;
use tokio::io::unix::AsyncFd;

/// The master side of a pseudo-terminal.
#[derive(Debug)]
pub struct PtyMaster {
    fd: OwnedFd,
    io: Option<AsyncFd<File>>,
}

/// A pseudo-terminal in raw mode (8 bits, no echo, no line editing: a serial line); the
/// master, and the path of its slave for the application to open.
///
/// # Errors
/// When no pseudo-terminal can be had.
pub fn open() -> anyhow::Result<(PtyMaster, PathBuf)> {
    use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
    let pty = nix::pty::openpty(None, None).context("creating a pseudo-terminal")?;
    let mut t = tcgetattr(&pty.slave).context("reading the pseudo-terminal's settings")?;
    cfmakeraw(&mut t);
    tcsetattr(&pty.slave, SetArg::TCSANOW, &t).context("setting the pseudo-terminal raw")?;
    let path = nix::unistd::ttyname(&pty.slave).context("the pseudo-terminal has no name")?;
    let raw = pty.master.as_raw_fd();
    let flags = nix::fcntl::fcntl(raw, nix::fcntl::FcntlArg::F_GETFL).context("the pty's flags")?;
    let flags = nix::fcntl::OFlag::from_bits_truncate(flags) | nix::fcntl::OFlag::O_NONBLOCK;
    nix::fcntl::fcntl(raw, nix::fcntl::FcntlArg::F_SETFL(flags)).context("the pty non-blocking")?;
    // The slave is closed here: the application opens it by its path (settings stay with the
    // pty while the master is open).
    drop(pty.slave);
    Ok((PtyMaster { fd: pty.master, io: None }, path))
}

impl PtyMaster {
    // `AsyncFd::new` is deprecated for types that may not own their descriptor; a `File` made
    // from our own duplicate owns it, which is the I/O safety the deprecation asks for.
    #[allow(deprecated)]
    fn io(&mut self) -> std::io::Result<&AsyncFd<File>> {
        if self.io.is_none() {
            self.io = Some(AsyncFd::new(File::from(self.fd.try_clone()?))?);
        }
        self.io.as_ref().ok_or_else(|| std::io::Error::other("no registration"))
    }

    /// Reads what the application wrote. An error (EIO) means no application holds the slave
    /// open: the registration is dropped, so the next read starts afresh.
    ///
    /// # Errors
    /// EIO while the application is away, or another read error.
    pub async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        loop {
            let io = self.io()?;
            let mut guard = io.readable().await?;
            match guard.try_io(|f| {
                let mut file: &File = f.get_ref();
                file.read(buf)
            }) {
                Ok(Ok(n)) if n > 0 => return Ok(n),
                Ok(Ok(_)) => {
                    self.io = None;
                    return Ok(0);
                }
                Ok(Err(e)) => {
                    self.io = None;
                    return Err(e);
                }
                Err(_would_block) => {}
            }
        }
    }

    /// Writes all of `bytes` for the application.
    ///
    /// # Errors
    /// When the application is away (EIO) or the write fails.
    pub async fn write_all(&mut self, mut bytes: &[u8]) -> std::io::Result<()> {
        while !bytes.is_empty() {
            let io = self.io()?;
            let mut guard = io.writable().await?;
            match guard.try_io(|f| {
                let mut file: &File = f.get_ref();
                file.write(bytes)
            }) {
                Ok(Ok(n)) => bytes = bytes.get(n..).unwrap_or_default(),
                Ok(Err(e)) => {
                    self.io = None;
                    return Err(e);
                }
                Err(_would_block) => {}
            }
        }
        Ok(())
    }
}
