//! `mbtap sniff PORT`: a live serial port through the analyzer, optionally recorded.
//!
//! Each read becomes a chunk stamped with the host clock when the read returned. While the
//! line is quiet the analyzer gets ticks, so frames and timeouts come out without waiting for
//! the next byte. A port that disappears (USB adapter pulled) is reported and reopened every
//! second until it is back; the recording goes on.

use std::io::Write;
use std::time::Duration;

use anyhow::Context;
use tokio::io::AsyncReadExt;
use tokio_serial::SerialPortBuilderExt;

use crate::replay_cmd::EventWriter;
use crate::source::serial::{builder, now};
use mbtap_core::analyzer::{Analyzer, AnalyzerConfig, Event, SerialMode};
use mbtap_core::capture::PcapNgWriter;
use mbtap_core::chunk::{Chunk, PortId};
use mbtap_core::framer::{FramerConfig, LineSettings};
use mbtap_core::line_args::LineOverrides;

/// Sniff settings.
#[derive(Debug, Clone)]
pub struct SniffOptions {
    pub port: String,
    pub mode: SerialMode,
    pub line: LineSettings,
    /// Delivery latency to allow (`--latency-ms`); `None`: from the adapter, at least 1 ms.
    pub latency_ns: Option<u64>,
    pub record: Option<std::path::PathBuf>,
    /// Stop after this long (for tests and timed captures); `None` runs until Ctrl-C.
    pub duration: Option<Duration>,
}

/// How often the analyzer hears the time while the line is quiet.
const TICK: Duration = Duration::from_millis(10);
/// Recording flush interval: a killed process loses at most this much.
const FLUSH: Duration = Duration::from_secs(1);

/// Runs the sniffer until Ctrl-C, SIGTERM or the duration ends.
///
/// # Errors
/// When the port cannot be opened at start, or the recording cannot be written.
pub async fn sniff<W: Write>(
    opts: SniffOptions,
    writer: &mut EventWriter<W>,
    err: &mut dyn Write,
) -> anyhow::Result<()> {
    let latency_ns = crate::source::serial::prepare_latency(&opts.port, opts.latency_ns, err);
    let mut recorder = match &opts.record {
        Some(path) => {
            let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
            let mut w = PcapNgWriter::new(std::io::BufWriter::new(file))?;
            w.add_serial_interface(&opts.port, &LineOverrides::describe(opts.mode, opts.line, latency_ns))?;
            Some(w)
        }
        None => None,
    };
    let config = AnalyzerConfig {
        mode: opts.mode,
        framer: FramerConfig::new(opts.line, latency_ns),
        ..AnalyzerConfig::default()
    };
    let mut analyzer = Analyzer::new(config);
    let mut stream = builder(&opts.port, opts.line)
        .open_native_async()
        .with_context(|| format!("opening serial port {} ({})", opts.port, opts.line))?;
    let _ = writeln!(
        err,
        "mbtap: sniffing {} at {} {} (reads trusted to {} µs: --latency-ms)",
        opts.port,
        opts.line,
        opts.mode.name(),
        latency_ns / 1000
    );
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    let mut last_flush = tokio::time::Instant::now();
    let mut buf = vec![0u8; 4096];
    let mut stop = Box::pin(shutdown_signal());
    loop {
        if deadline.is_some_and(|d| tokio::time::Instant::now() >= d) {
            break;
        }
        tokio::select! {
            () = &mut stop => break,
            r = tokio::time::timeout(TICK, stream.read(&mut buf)) => match r {
                Ok(Ok(n)) if n > 0 => {
                    let t = now();
                    let chunk = Chunk { port: PortId(0), t, bytes: &buf[..n] };
                    if let Some(w) = recorder.as_mut() {
                        w.write_packet(0, t, chunk.bytes).context("writing the recording")?;
                    }
                    analyzer.push(&chunk, &mut |e: &Event<'_>| writer.write(e));
                }
                Ok(Ok(_) | Err(_)) => {
                    let _ = writeln!(err, "mbtap: lost {}; waiting for it to come back", opts.port);
                    analyzer.tick(now(), &mut |e: &Event<'_>| writer.write(e));
                    stream = loop {
                        tokio::select! {
                            () = &mut stop => {
                                finish(&mut analyzer, writer, recorder.as_mut())?;
                                return Ok(());
                            }
                            () = tokio::time::sleep(Duration::from_secs(1)) => {}
                        }
                        if let Some(w) = recorder.as_mut() {
                            w.flush()?;
                        }
                        if let Ok(s) = builder(&opts.port, opts.line).open_native_async() {
                            let _ = writeln!(err, "mbtap: {} is back", opts.port);
                            break s;
                        }
                    };
                }
                Err(_) => analyzer.tick(now(), &mut |e: &Event<'_>| writer.write(e)),
            },
        }
        if last_flush.elapsed() >= FLUSH {
            last_flush = tokio::time::Instant::now();
            if let Some(w) = recorder.as_mut() {
                w.flush().context("flushing the recording")?;
            }
            let _ = writer.out.flush();
        }
    }
    finish(&mut analyzer, writer, recorder.as_mut())
}

fn finish<W: Write, R: Write>(
    analyzer: &mut Analyzer,
    writer: &mut EventWriter<W>,
    recorder: Option<&mut PcapNgWriter<R>>,
) -> anyhow::Result<()> {
    analyzer.finish(&mut |e: &Event<'_>| writer.write(e));
    if let Some(w) = recorder {
        w.flush().context("flushing the recording")?;
    }
    Ok(())
}

/// Set once something asked the program to stop (a signal, or `q` in the terminal UI).
static STOP_REQUESTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// Set when the stop came from SIGTERM or SIGINT (the UI then closes too).
static SIGNALLED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// Wakes a [`shutdown_signal`] waiting in another thread; a stored permit covers one that is
/// not waiting yet.
static STOP: tokio::sync::Notify = tokio::sync::Notify::const_new();

/// Asks every running [`shutdown_signal`] to fire (the terminal UI's `q`).
pub fn request_stop() {
    STOP_REQUESTED.store(true, std::sync::atomic::Ordering::SeqCst);
    STOP.notify_one();
}

/// Whether a stop was asked for (for loops that do not await).
#[must_use]
pub fn stop_requested() -> bool {
    STOP_REQUESTED.load(std::sync::atomic::Ordering::SeqCst)
}

/// Whether a signal (Ctrl-C outside raw mode, SIGTERM) arrived.
#[must_use]
pub fn signalled() -> bool {
    SIGNALLED.load(std::sync::atomic::Ordering::SeqCst)
}

/// Ctrl-C, SIGTERM, or [`request_stop`].
pub(crate) async fn shutdown_signal() {
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    if stop_requested() {
        return;
    }
    tokio::select! {
        _ = tokio::signal::ctrl_c() => SIGNALLED.store(true, std::sync::atomic::Ordering::SeqCst),
        () = term => SIGNALLED.store(true, std::sync::atomic::Ordering::SeqCst),
        () = STOP.notified() => {}
    }
    STOP_REQUESTED.store(true, std::sync::atomic::Ordering::SeqCst);
    // Another waiter (a second loop in the same run) stops too.
    STOP.notify_one();
}
