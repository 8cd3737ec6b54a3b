//! `mbtap tap PORT --link PATH`: a software tap for when the master runs on this computer.
//!
//! mbtap opens the real port and offers a pseudo-terminal at PATH for the application to open
//! instead; bytes are relayed both ways untouched, each as soon as a read returns them, and
//! both directions are analysed with the direction known (what the application writes are
//! requests, what the port answers are responses). Like `sniff` it shows, and with --record
//! keeps, a two-port capture (`role=requests` / `role=responses` in the interface
//! descriptions) that `replay` and `export` read with the directions intact.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

use crate::io::rs485::Rs485Args;
use crate::io::serial::now;
use crate::io::stream::{LineStream, Transport};
use crate::output::{EventWriter, SourceError};
use crate::source::record::Recorder;
use crate::source::session::Session;
use mbtap_analysis::analyzer::{AnalyzerConfig, SerialMode};
use mbtap_analysis::chunk::{Chunk, PortId};
use mbtap_analysis::framer::{FramerConfig, LineSettings};
use mbtap_analysis::line_args::LineOverrides;
use mbtap_analysis::pairing::PairingConfig;

/// The application's side (requests) and the bus's side (responses).
pub const APP_PORT: PortId = PortId(0);
pub const BUS_PORT: PortId = PortId(1);

/// Tap settings.
#[derive(Debug, Clone)]
pub struct TapOptions {
    pub port: String,
    pub link: PathBuf,
    pub mode: SerialMode,
    pub line: LineSettings,
    /// Delivery latency to allow (`--latency-ms`); `None`: from the adapter, at least 1 ms.
    pub latency_ns: Option<u64>,
    pub record: Option<PathBuf>,
    pub duration: Option<Duration>,
}

/// How long a write to the application's side may wait for it to read before it is dropped.
const APP_STALL: Duration = Duration::from_millis(50);

/// Runs the tap until Ctrl-C, SIGTERM or the duration ends.
///
/// # Errors
/// [`SourceError::NotStarted`] when the port, the pseudo-terminal or the recording cannot be
/// set up (nothing relayed: no summary is due); [`SourceError::Stopped`] when the port or the
/// recording cannot be written later.
pub async fn tap<W: Write>(
    opts: TapOptions,
    writer: &mut EventWriter<W>,
    err: &mut dyn Write,
) -> Result<(), SourceError> {
    // A serial server's stream keeps no timing: as for `sniff`, frames are found by structure.
    let transport = Transport::of(&opts.port);
    let latency_ns = match transport.latency_ns(opts.latency_ns) {
        Some(ns) if transport.networked() => ns,
        _ => crate::io::serial::prepare_latency(&opts.port, opts.latency_ns, err),
    };
    let mut watch = crate::io::serial::DeviceWatch::default();
    let mut bus =
        LineStream::open_line(&opts.port, opts.line, &mut watch, err).await.map_err(SourceError::NotStarted)?;
    // The pty lives as long as we hold the master; the application opens the slave's path.
    let (mut app, slave_path) = crate::io::pty::open().map_err(SourceError::NotStarted)?;
    let slave_path = slave_path.to_string_lossy().into_owned();
    crate::io::link::make(&opts.link, &slave_path).map_err(SourceError::NotStarted)?;
    let _ = writeln!(
        err,
        "mbtap: tapping {} at {}; point the application at {} ({slave_path})",
        opts.port,
        opts.line,
        opts.link.display()
    );

    let recorder = match &opts.record {
        Some(path) => {
            let d = LineOverrides::describe(opts.mode, opts.line, latency_ns);
            let app_name = format!("{} (application)", opts.link.display());
            let (requests, responses) = (format!("{d} role=requests"), format!("{d} role=responses"));
            Some(
                Recorder::create(path, &[(&app_name, &requests), (&opts.port, &responses)])
                    .map_err(SourceError::NotStarted)?,
            )
        }
        None => None,
    };
    let pairing =
        PairingConfig { request_port: Some(APP_PORT), response_port: Some(BUS_PORT), ..PairingConfig::default() };
    // A latency the user gave is kept; otherwise valid frames may show the reads later.
    let framer = FramerConfig { learn_latency: opts.latency_ns.is_none(), ..FramerConfig::new(opts.line, latency_ns) };
    let mut session =
        Session::new(AnalyzerConfig { mode: opts.mode, framer, pairing }).recording(recorder).telling_observers();
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    // The deadline is part of the stop, so it holds while the port is away too.
    let mut stop = Box::pin(crate::io::signals::stop_or_deadline(deadline));
    let (mut from_app, mut from_bus) = (vec![0u8; 4096], vec![0u8; 4096]);
    let mut last_flush = tokio::time::Instant::now();
    let mut app_closed = false;
    loop {
        if deadline.is_some_and(|d| tokio::time::Instant::now() >= d) {
            break;
        }
        let (port, n) = tokio::select! {
            () = &mut stop => break,
            r = app.read(&mut from_app) => match r {
                Ok(n) if n > 0 => {
                    app_closed = false;
                    bus.send(&Rs485Args::default(), &from_app[..n]).await.context("writing to the serial port")?;
                    (APP_PORT, n)
                }
                // The application closed its end (EIO on the master): wait for it to reopen.
                // What was heard so far is flushed now (a SIGKILL after the
                // application closed lost the last transactions), and the loop goes on to its
                // own flushes (a `continue` here skipped them for as long as it stayed closed).
                _ => {
                    if !app_closed {
                        app_closed = true;
                        session.flush(writer, err);
                    }
                    tokio::time::sleep(Duration::from_millis(20)).await;
                    (APP_PORT, 0)
                }
            },
            r = bus.read(&mut from_bus) => match r {
                Ok(n) if n > 0 => {
                    // Nobody reading the pty is not an error worth stopping for, nor a reason
                    // to stall the line: what the application does not take soon is dropped.
                    let _ = tokio::time::timeout(APP_STALL, app.write_all(&from_bus[..n])).await;
                    (BUS_PORT, n)
                }
                // The real port went away (an adapter pulled): the application's side stays
                // open — it sees a quiet line, not a vanished device — while the port is
                // reopened as `sniff` does.
                _ => {
                    let _ = writeln!(err, "mbtap: lost {}; the application's side stays open, waiting for the port to come back", opts.port);
                    match reopen(&opts, &mut app, &mut stop, session.recorder(), &mut watch, err).await {
                        Some(b) => {
                            let _ = writeln!(err, "mbtap: {} is back", opts.port);
                            bus = b;
                            continue;
                        }
                        None => break,
                    }
                }
            },
            () = tokio::time::sleep(Duration::from_millis(10)) => {
                session.tick(now(), writer);
                (APP_PORT, 0)
            }
        };
        if n > 0 {
            let t = now();
            let bytes = if port == APP_PORT { &from_app[..n] } else { &from_bus[..n] };
            session.chunk(&Chunk { port, t, bytes }, writer, err);
        }
        // At least once a second, traffic or not: a killed process loses at most a second.
        if last_flush.elapsed() >= Duration::from_secs(1) {
            last_flush = tokio::time::Instant::now();
            session.flush(writer, err);
        }
    }
    session.finish(writer, err)?;
    crate::io::link::remove(&opts.link, &slave_path);
    Ok(())
}

/// Waits for the real port to come back, trying once a second, while the application's side
/// stays open (what it writes meanwhile has no line to go to: read and dropped, so it does not
/// block). `None` when a stop was asked for.
async fn reopen(
    opts: &TapOptions,
    app: &mut crate::io::pty::PtyMaster,
    stop: &mut std::pin::Pin<Box<impl std::future::Future<Output = ()>>>,
    mut recorder: Option<&mut Recorder>,
    watch: &mut crate::io::serial::DeviceWatch,
    err: &mut dyn Write,
) -> Option<LineStream> {
    let mut scratch = [0u8; 1024];
    // One timer for the whole wait: the application's reads must not restart it.
    let mut retry = tokio::time::interval(Duration::from_secs(1));
    retry.tick().await;
    loop {
        tokio::select! {
            () = &mut *stop => return None,
            r = app.read(&mut scratch) => {
                if !matches!(r, Ok(n) if n > 0) {
                    // The application closed its end (EIO on the master): nothing to drain.
                    tokio::time::sleep(Duration::from_millis(20)).await;
                }
            }
            _ = retry.tick() => {
                if let Some(r) = recorder.as_deref_mut() {
                    r.flush(err);
                }
                if let Ok(b) = LineStream::open_line(&opts.port, opts.line, watch, err).await {
                    return Some(b);
                }
            }
        }
    }
}
