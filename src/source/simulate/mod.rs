//! `mbtap simulate --link PATH`: simulated slaves on a pseudo-terminal, for trying mbtap, the
//! tests, and commissioning a SCADA before the hardware arrives.
//!
//! A master opens PATH as its serial port. Requests are framed from what it writes (the serial
//! fronts' one framer, [`mbtap_proto::request_frames`]), handed to every simulated slave, and
//! the one that answers is heard after a turnaround delay. Values move with the host clock ([`mbtap_sim::world`]).
//!
//! Its pieces: [`emulate_from`] (what is emulated, from what the user names) and [`emulated`] (the
//! one set of devices every front serves).

pub mod emulate_from;
pub mod emulated;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_serial::{SerialPort, SerialStream};

use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::framer::LineSettings;
use mbtap_proto::request_frames::{RequestFramer, end_silence};
use mbtap_proto::{encode_ascii, encode_rtu};
use mbtap_sim::bus::VirtualBus;
use mbtap_sim::uart::Listener;
use mbtap_sim::{Device, Slave};

use emulated::Emulated;

/// A profile device's time from a request to its answer when none is given (the MK4 document
/// gives no figure; a few milliseconds is typical of such controllers).
pub const DEFAULT_TURNAROUND: Duration = Duration::from_millis(3);

/// Simulation settings.
#[derive(Debug)]
pub struct SimulateOptions {
    /// The pseudo-terminal to serve on (None: only the listeners).
    pub link: Option<PathBuf>,
    /// The devices, shared with the listeners (`--listen`) when there are any.
    pub devices: Arc<Emulated>,
    pub line: LineSettings,
    pub mode: SerialMode,
    pub duration: Option<Duration>,
    /// Answer mode: take the line's time — a request ends when its characters would have
    /// crossed the line, and the answer leaves at the character rate (in 1 ms batches).
    pub paced: bool,
    /// The master's adapter hears its own transmission (a half-duplex transceiver whose
    /// receiver stays on): every byte the master sends comes back to it, before the answer.
    pub echo: bool,
    /// Play the master too (`--poll`): the whole line goes out on the pseudo-terminal, for a
    /// listener (`mbtap sniff`) to hear.
    pub poll: Option<PollOptions>,
    /// `--audit`: requests on the pseudo-terminal that may change a device, recorded.
    pub audit: Option<Arc<crate::output::audit::Audit>>,
}

/// The built-in master's settings.
#[derive(Debug, Clone, Default)]
pub struct PollOptions {
    pub faults: Vec<mbtap_sim::bus::Fault>,
    /// The listener's UART settings when they differ from the line's (a wrong-baud or
    /// wrong-parity training line).
    pub heard_at: Option<LineSettings>,
    /// Hear at the baud rate the listener set on the pty (its termios).
    pub follow_baud: bool,
}

/// The default line: all three built-in devices at the addresses used throughout the docs.
pub const DEFAULT_DEVICES: [(&str, u8); 3] = [("mk4", 1), ("display", 5), ("mkzp", 17)];

/// Runs until Ctrl-C or the duration ends.
///
/// # Errors
/// When the pseudo-terminal or the link cannot be created.
pub async fn simulate(opts: SimulateOptions, link: &Path, err: &mut dyn Write) -> anyhow::Result<()> {
    let (mut master_side, slave) = SerialStream::pair().context("creating a pseudo-terminal")?;
    let slave_path = slave.name().context("the pseudo-terminal has no name")?;
    // Our handle on the far end holds an exclusive lock: let it go so the master can open it.
    drop(slave);
    crate::io::link::make(link, &slave_path)?;
    let _ = writeln!(
        err,
        "mbtap: open {} ({slave_path}) at {} {} as the master's serial port",
        link.display(),
        opts.line,
        opts.mode.name()
    );

    if let Some(poll) = opts.poll {
        // The built-in master polls what a profile describes (a recording has no poll plan).
        let (slaves, turnaround) = {
            let devices = opts.devices.devices.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            let slaves: Vec<Slave> = devices
                .iter()
                .filter_map(|d| match d {
                    Device::Profile(s) => Some(s.clone()),
                    Device::Recorded(_) | Device::Mirror { .. } => None,
                })
                .collect();
            (slaves, opts.devices.turnaround.unwrap_or(DEFAULT_TURNAROUND))
        };
        let mut bus = VirtualBus::new(slaves, opts.line);
        // An empty poll list would spin without end (and never see --duration).
        anyhow::ensure!(
            bus.poll_count() > 0,
            "--poll: nothing to poll — the built-in master polls devices from profiles (--device), and these map no register"
        );
        bus.faults = poll.faults;
        bus.ascii = opts.mode == SerialMode::Ascii;
        bus.turnaround_ns = u64::try_from(turnaround.as_nanos()).unwrap_or(u64::MAX);
        let listener = Listener::new(opts.line, poll.heard_at.unwrap_or(opts.line));
        let follow = poll.follow_baud.then_some(opts.line);
        let result = drive_line(&mut master_side, bus, listener, follow, opts.duration).await;
        crate::io::link::remove(link, &slave_path);
        return result;
    }
    let deadline = opts.duration.map(|d| Instant::now() + d);
    let gap = end_silence(opts.line);
    let mut framer = RequestFramer::new(opts.mode);
    let mut buf = [0u8; 512];
    let mut out = Vec::with_capacity(260);
    let char_time = Duration::from_nanos(opts.line.char_ns());
    // Paced: when the first byte of the request being heard arrived, and how many bytes so far.
    let mut request_start: Option<(tokio::time::Instant, usize)> = None;
    loop {
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        let read = tokio::select! {
            r = tokio::time::timeout(gap, master_side.read(&mut buf)) => r,
            _ = tokio::signal::ctrl_c() => break,
        };
        let mut requests = Vec::new();
        match read {
            Ok(Ok(0)) => {
                // No master has the port open: wait for one.
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
            Ok(Ok(n)) => {
                let (_, count) = request_start.get_or_insert((tokio::time::Instant::now(), 0));
                *count += n;
                if opts.echo {
                    let echo = buf.get(..n).unwrap_or_default();
                    if opts.paced {
                        write_paced(&mut master_side, echo, char_time).await?;
                    } else {
                        AsyncWriteExt::write_all(&mut master_side, echo)
                            .await
                            .context("echoing to the pseudo-terminal")?;
                    }
                }
                framer.push(buf.get(..n).unwrap_or_default(), &mut requests);
            }
            // EIO while no master has the far end open; try again shortly.
            Ok(Err(_)) => {
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
            Err(_) => requests.extend(framer.silence()),
        }
        // Paced: a request is over when its characters would have crossed the line.
        let heard = if requests.is_empty() { None } else { request_start.take() };
        for request in requests {
            let answered = opts.devices.answer(request.unit, &request.pdu);
            if let Some(audit) = &opts.audit
                && let Some(change) = mbtap_gateway::audit::change(&request.pdu)
            {
                let outcome = match &answered {
                    Some((pdu, _)) => {
                        mbtap_gateway::audit::outcome(&mbtap_gateway::transaction::Reply::Pdu(pdu.clone()))
                    }
                    None if request.unit == 0 => "broadcast (no answer)".to_owned(),
                    None => "not answered: no device here has this address".to_owned(),
                };
                let who = crate::output::audit::Who { transport: "pty", address: None, role: None };
                audit.record(&who, request.unit, &change, &outcome);
            }
            let Some((pdu, wait)) = answered else { continue };
            if let (true, Some((first, count))) = (opts.paced, heard) {
                let ended = first + char_time * u32::try_from(count).unwrap_or(u32::MAX);
                crate::io::pace::wait_until(ended + wait).await;
            } else if !wait.is_zero() {
                crate::io::pace::wait_until(tokio::time::Instant::now() + wait).await;
            }
            out.clear();
            match opts.mode {
                SerialMode::Rtu => encode_rtu(request.unit, &pdu, &mut out),
                SerialMode::Ascii => encode_ascii(request.unit, &pdu, &mut out),
            }
            if opts.paced {
                write_paced(&mut master_side, &out, char_time).await?;
            } else {
                AsyncWriteExt::write_all(&mut master_side, &out)
                    .await
                    .context("writing a response to the pseudo-terminal")?;
            }
            let _ = AsyncWriteExt::flush(&mut master_side).await;
        }
    }
    crate::io::link::remove(link, &slave_path);
    let _ = master_side.clear(tokio_serial::ClearBuffer::All);
    Ok(())
}

/// How long a write may wait for the far end before we conclude nobody is listening and drop
/// what is buffered: a listener that opens the line later must hear it live, not seconds late.
const STALL: Duration = Duration::from_millis(50);

/// Writes the virtual line onto the pseudo-terminal, each byte when the listener would get
/// it. The timer has 1 ms steps, so bytes leave in 1 ms batches — as a USB adapter delivers
/// them; the listener sees the line's pauses, not its character spacing within a batch.
///
/// With `follow` (the sender's settings), the listener's baud rate is read from the pty's
/// termios before each transaction: whatever rate the program at the far end set.
async fn drive_line(
    port: &mut SerialStream,
    mut bus: VirtualBus,
    mut listener: Listener,
    follow: Option<LineSettings>,
    duration: Option<Duration>,
) -> anyhow::Result<()> {
    let mut start = tokio::time::Instant::now();
    let mut stop = Box::pin(crate::io::signals::shutdown_signal());
    let mut batch = Vec::with_capacity(64);
    let began = Instant::now();
    let mut scratch = [0u8; 256];
    let mut heard_baud = None;
    loop {
        if let Some(sender) = follow {
            // The master side of a pty reports the far end's termios (Linux: the slave's).
            let baud = tokio_serial::SerialPort::baud_rate(port).unwrap_or(sender.baud);
            if heard_baud != Some(baud) {
                heard_baud = Some(baud);
                listener = Listener::new(sender, LineSettings { baud, ..sender });
            }
        }
        for frame in bus.next_transaction() {
            let heard = listener.hear(&frame);
            let mut i = 0;
            while let Some(&(t, _)) = heard.get(i) {
                let due = Duration::from_nanos(t);
                if duration.is_some_and(|d| began.elapsed() >= d) {
                    return Ok(());
                }
                // Behind (a stalled write while nobody listened): move the line's clock on
                // rather than rush the backlog out with its timing lost.
                let late = start.elapsed().saturating_sub(due);
                if late > STALL {
                    start += late;
                }
                tokio::select! {
                    () = &mut stop => return Ok(()),
                    () = tokio::time::sleep_until(start + due) => {}
                }
                let now = u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX);
                batch.clear();
                while let Some(&(_, b)) = heard.get(i).filter(|(t, _)| *t <= now) {
                    batch.push(b);
                    i += 1;
                }
                if nobody_listening(port, &mut scratch).await {
                    // Keep nothing for a listener that opens later: it hears the line live.
                    let _ = port.clear(tokio_serial::ClearBuffer::All);
                    continue;
                }
                match tokio::time::timeout(STALL, AsyncWriteExt::write_all(port, &batch)).await {
                    Ok(r) => r.context("writing the line to the pseudo-terminal")?,
                    Err(_) => {
                        let _ = port.clear(tokio_serial::ClearBuffer::All);
                    }
                }
            }
        }
    }
}

/// True when no one has the far end open: a read then fails at once (EIO) instead of waiting.
/// Whatever a listener writes is read and dropped here (a sniffer writes nothing).
async fn nobody_listening(port: &mut SerialStream, scratch: &mut [u8]) -> bool {
    matches!(tokio::time::timeout(Duration::ZERO, port.read(scratch)).await, Ok(Err(_) | Ok(0)))
}

/// Writes `bytes` at the character rate, in 1 ms batches (the timer's granularity).
async fn write_paced(port: &mut SerialStream, bytes: &[u8], char_time: Duration) -> anyhow::Result<()> {
    let start = tokio::time::Instant::now();
    let mut sent = 0;
    while sent < bytes.len() {
        let due = u32::try_from(start.elapsed().as_nanos() / char_time.as_nanos().max(1)).unwrap_or(u32::MAX);
        let upto = usize::try_from(due).unwrap_or(usize::MAX).saturating_add(1).min(bytes.len());
        if upto > sent {
            AsyncWriteExt::write_all(port, bytes.get(sent..upto).unwrap_or_default())
                .await
                .context("writing a response to the pseudo-terminal")?;
            sent = upto;
        }
        if sent < bytes.len() {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }
    Ok(())
}
