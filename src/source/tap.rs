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
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_serial::{SerialPort, SerialPortBuilderExt, SerialStream};

use crate::output::EventWriter;
use crate::source::serial::{builder, now};
use mbtap_core::analyzer::{Analyzer, AnalyzerConfig, Event, SerialMode};
use mbtap_core::capture::PcapNgWriter;
use mbtap_core::chunk::{Chunk, PortId};
use mbtap_core::framer::{FramerConfig, LineSettings};
use mbtap_core::line_args::LineOverrides;
use mbtap_core::pairing::PairingConfig;

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

/// Runs the tap until Ctrl-C, SIGTERM or the duration ends.
///
/// # Errors
/// When the port or the pseudo-terminal cannot be set up, or the recording written.
pub async fn tap<W: Write>(opts: TapOptions, writer: &mut EventWriter<W>, err: &mut dyn Write) -> anyhow::Result<()> {
    let latency_ns = crate::source::serial::prepare_latency(&opts.port, opts.latency_ns, err);
    let mut bus = builder(&opts.port, opts.line)
        .open_native_async()
        .with_context(|| format!("opening serial port {} ({})", opts.port, opts.line))?;
    let (mut app, slave) = SerialStream::pair().context("creating a pseudo-terminal")?;
    let slave_path = slave.name().context("the pseudo-terminal has no name")?;
    // Our handle on the application's end holds an exclusive lock: let it go, so the
    // application can open the path. The pty lives as long as we hold the master.
    drop(slave);
    let _ = std::fs::remove_file(&opts.link);
    std::os::unix::fs::symlink(&slave_path, &opts.link)
        .with_context(|| format!("creating the link {} -> {slave_path}", opts.link.display()))?;
    let _ = writeln!(
        err,
        "mbtap: tapping {} at {}; point the application at {} ({slave_path})",
        opts.port,
        opts.line,
        opts.link.display()
    );

    let mut recorder = match &opts.record {
        Some(path) => {
            let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
            let mut w = PcapNgWriter::new(std::io::BufWriter::new(file))?;
            let d = LineOverrides::describe(opts.mode, opts.line, latency_ns);
            w.add_serial_interface(&format!("{} (application)", opts.link.display()), &format!("{d} role=requests"))?;
            w.add_serial_interface(&opts.port, &format!("{d} role=responses"))?;
            Some(w)
        }
        None => None,
    };
    let pairing =
        PairingConfig { request_port: Some(APP_PORT), response_port: Some(BUS_PORT), ..PairingConfig::default() };
    let mut analyzer =
        Analyzer::new(AnalyzerConfig { mode: opts.mode, framer: FramerConfig::new(opts.line, latency_ns), pairing });
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    let mut stop = Box::pin(crate::signals::shutdown_signal());
    let (mut from_app, mut from_bus) = (vec![0u8; 4096], vec![0u8; 4096]);
    let mut last_flush = tokio::time::Instant::now();
    loop {
        if deadline.is_some_and(|d| tokio::time::Instant::now() >= d) {
            break;
        }
        let (port, n) = tokio::select! {
            () = &mut stop => break,
            r = app.read(&mut from_app) => match r {
                Ok(n) if n > 0 => {
                    AsyncWriteExt::write_all(&mut bus, &from_app[..n]).await.context("writing to the serial port")?;
                    (APP_PORT, n)
                }
                // The application closed its end (EIO on the master): wait for it to reopen.
                _ => {
                    tokio::time::sleep(Duration::from_millis(20)).await;
                    continue;
                }
            },
            r = bus.read(&mut from_bus) => match r {
                Ok(n) if n > 0 => {
                    // Nobody reading the pty is not an error worth stopping for.
                    let _ = AsyncWriteExt::write_all(&mut app, &from_bus[..n]).await;
                    (BUS_PORT, n)
                }
                _ => anyhow::bail!("lost serial port {}", opts.port),
            },
            () = tokio::time::sleep(Duration::from_millis(10)) => {
                analyzer.tick(now(), &mut |e: &Event<'_>| writer.write(e));
                continue;
            }
        };
        let t = now();
        let bytes = if port == APP_PORT { &from_app[..n] } else { &from_bus[..n] };
        if let Some(w) = recorder.as_mut() {
            w.write_packet(u32::from(port.0), t, bytes).context("writing the recording")?;
        }
        analyzer.push(&Chunk { port, t, bytes }, &mut |e: &Event<'_>| writer.write(e));
        if last_flush.elapsed() >= Duration::from_secs(1) {
            last_flush = tokio::time::Instant::now();
            if let Some(w) = recorder.as_mut() {
                w.flush()?;
            }
            let _ = writer.out.flush();
        }
    }
    analyzer.finish(&mut |e: &Event<'_>| writer.write(e));
    if let Some(w) = recorder.as_mut() {
        w.flush()?;
    }
    let _ = std::fs::remove_file(&opts.link);
    Ok(())
}
