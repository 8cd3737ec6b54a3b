//! `mbtap scan PORT|FILE`: which line settings give valid frames — live by trying them, or from
//! stored bytes.

use std::io::{self, Write};
use std::process::ExitCode;

use crate::cmd::runtime;

#[derive(Debug, clap::Args)]
/// Find a live bus's line settings: try baud rates, parities, character sizes and both
/// modes, and rank them by the valid frames they give.
///
/// Given a file instead of a port — a capture (pcap/pcapng) or a raw dump of received
/// bytes — it tells the mode and character size from the stored bytes (their baud rate
/// and parity can no longer be changed: a wrong receiver's lost bits are gone).
pub struct Args {
    /// The serial port, or a file of stored bytes.
    pub port: String,
    /// Only these baud rates (repeatable; default: 1200 to 256000).
    #[arg(long = "baud")]
    pub bauds: Vec<u32>,
    /// How long to listen at each setting, ms.
    #[arg(long, default_value_t = 600)]
    pub dwell_ms: u64,
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let Args { port, bauds, dwell_ms } = args;
    let dwell_ms = *dwell_ms;
    anyhow::ensure!(
        !std::fs::metadata(port).is_ok_and(|m| m.is_dir()),
        "{port} is a directory: give a serial port (/dev/ttyUSB0) or a file of stored bytes (a capture or a raw dump)"
    );
    if std::fs::metadata(port).is_ok_and(|m| m.is_file()) {
        let (text, ok) = crate::source::scan::scan_file(std::path::Path::new(&port))?;
        io::stdout().lock().write_all(text.as_bytes())?;
        return Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) });
    }
    let dwell = std::time::Duration::from_millis(dwell_ms.max(1));
    let scores = runtime()?.block_on(crate::source::scan::scan(port, bauds, dwell, &mut io::stderr()))?;
    io::stdout().lock().write_all(crate::source::scan::describe(&scores).as_bytes())?;
    Ok(if scores.first().is_some_and(|b| b.valid_frames > 0) { ExitCode::SUCCESS } else { ExitCode::from(1) })
}
