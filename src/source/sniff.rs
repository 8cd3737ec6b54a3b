//! `mbtap sniff PORT`: a live serial port through the analyzer, optionally recorded.
//!
//! Each read becomes a chunk stamped with the host clock when the read returned. While the
//! line is quiet the analyzer gets ticks, so frames and timeouts come out without waiting for
//! the next byte. A port that disappears (USB adapter pulled) is reported and reopened every
//! second until it is back; the recording goes on.
//!
//! `rtu-over-tcp://HOST:PORT` (or `rtu+tcp://`) listens to a serial server in transparent mode
//! (ser2net raw, USR, Elfin, NPort): the remote line's bytes as TCP delivers them. TCP keeps no
//! timing — a segment may hold parts of several frames, or be held back — so the framer is told
//! not to trust silences shorter than [`crate::io::stream::SERIAL_SERVER_LATENCY`] and finds frame ends by their
//! structure and CRC; a connection that drops is made again every second.

use std::io::Write;
use std::time::Duration;

use crate::io::serial::now;
use crate::io::stream::{LineStream, Transport};
use crate::output::{EventWriter, SourceError};
use crate::source::record::Recorder;
use crate::source::session::Session;
use mbtap_analysis::analyzer::{AnalyzerConfig, SerialMode};
use mbtap_analysis::chunk::{Chunk, PortId};
use mbtap_analysis::framer::{FramerConfig, LineSettings};
use mbtap_analysis::line_args::LineOverrides;

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

/// The serial server's `HOST:PORT` when `port` names one (raw or RFC 2217).
fn serial_server(port: &str) -> Option<&str> {
    match Transport::of(port) {
        Transport::RtuOverTcp(addr) | Transport::Rfc2217(addr) => Some(addr),
        Transport::Serial(_) | Transport::ModbusTcp(_) => None,
    }
}

/// Opens `opts.port`: the serial port (by name, by-id link or usb:VID:PID), or a connection to
/// the serial server it names.
async fn open_source(
    opts: &SniffOptions,
    watch: &mut crate::io::serial::DeviceWatch,
    err: &mut dyn Write,
) -> anyhow::Result<LineStream> {
    LineStream::open_line(&opts.port, opts.line, watch, err).await
}

/// How often the analyzer hears the time while the line is quiet.
const TICK: Duration = Duration::from_millis(10);
/// Recording flush interval: a killed process loses at most this much.
const FLUSH: Duration = Duration::from_secs(1);

/// Runs the sniffer until Ctrl-C, SIGTERM or the duration ends.
///
/// # Errors
/// [`SourceError::NotStarted`] when the recording cannot be created or the port cannot be
/// opened at start (nothing heard: no summary is due); [`SourceError::Stopped`] when the
/// recording cannot be written later.
pub async fn sniff<W: Write>(
    opts: SniffOptions,
    writer: &mut EventWriter<W>,
    err: &mut dyn Write,
) -> Result<(), SourceError> {
    let remote = serial_server(&opts.port).is_some();
    let latency_ns = match Transport::of(&opts.port).latency_ns(opts.latency_ns) {
        Some(ns) if remote => ns,
        _ => crate::io::serial::prepare_latency(&opts.port, opts.latency_ns, err),
    };
    let description = LineOverrides::describe(opts.mode, opts.line, latency_ns);
    let recorder = match &opts.record {
        Some(path) => Some(Recorder::create(path, &[(&opts.port, &description)]).map_err(SourceError::NotStarted)?),
        None => None,
    };
    let config = AnalyzerConfig {
        mode: opts.mode,
        // A latency the user gave is kept; otherwise valid frames may show the reads later.
        framer: FramerConfig { learn_latency: opts.latency_ns.is_none(), ..FramerConfig::new(opts.line, latency_ns) },
        ..AnalyzerConfig::default()
    };
    let mut session = Session::new(config).recording(recorder).telling_observers();
    let mut watch = crate::io::serial::DeviceWatch::default();
    let mut stream = open_source(&opts, &mut watch, err).await.map_err(SourceError::NotStarted)?;
    let _ = writeln!(
        err,
        "mbtap: sniffing {} at {} {} (reads trusted to {} µs: --latency-ms{})",
        opts.port,
        opts.line,
        opts.mode.name(),
        latency_ns / 1000,
        if remote { "; a serial server's TCP stream keeps no timing: frames found by structure and CRC" } else { "" }
    );
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    let mut last_flush = tokio::time::Instant::now();
    let mut buf = vec![0u8; 4096];
    // The deadline is part of the stop: it holds while the port is away too (a sniff of a
    // vanished port with --duration ends on time).
    let mut stop = Box::pin(crate::io::signals::stop_or_deadline(deadline));
    loop {
        if deadline.is_some_and(|d| tokio::time::Instant::now() >= d) {
            break;
        }
        tokio::select! {
            () = &mut stop => break,
            r = tokio::time::timeout(TICK, stream.read(&mut buf)) => match r {
                Ok(Ok(n)) if n > 0 => {
                    let t = now();
                    session.chunk(&Chunk { port: PortId(0), t, bytes: &buf[..n] }, writer, err);
                }
                Ok(Ok(_) | Err(_)) => {
                    let _ = writeln!(err, "mbtap: lost {}; waiting for it to come back", opts.port);
                    session.tick(now(), writer);
                    stream = loop {
                        tokio::select! {
                            () = &mut stop => return Ok(session.finish(writer, err)?),
                            () = tokio::time::sleep(Duration::from_secs(1)) => {}
                        }
                        if let Some(r) = session.recorder() {
                            r.flush(err);
                        }
                        // A by-id link or usb:VID:PID finds the adapter under its new name; a
                        // serial server is connected to again.
                        if let Ok(s) = open_source(&opts, &mut watch, err).await {
                            let _ = writeln!(err, "mbtap: {} is back", opts.port);
                            break s;
                        }
                    };
                }
                Err(_) => session.tick(now(), writer),
            },
        }
        if last_flush.elapsed() >= FLUSH {
            last_flush = tokio::time::Instant::now();
            session.flush(writer, err);
        }
    }
    Ok(session.finish(writer, err)?)
}
