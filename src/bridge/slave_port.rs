//! A serial port on which the bridge is the slave (reverse mode, `--listen-serial`): requests
//! framed from the bytes the way a slave's UART sees them by the serial fronts' one framer
//! ([`mbtap_proto::request_frames`]: structure, CRC and silence in RTU; ':' … CR LF in ASCII),
//! and answers written after the slave's turnaround under the port's direction control.

use std::time::Duration;

use tokio::io::AsyncReadExt;
use tokio_serial::SerialStream;

use mbtap_analysis::analyzer::SerialMode;
use mbtap_analysis::framer::LineSettings;
use mbtap_proto::request_frames::{RequestFrame, RequestFramer, end_silence};
use mbtap_proto::{encode_ascii, encode_rtu};

/// The requests heard on one port, in its mode.
#[derive(Debug)]
pub struct Requests {
    framer: RequestFramer,
    /// The silence that ends an RTU request on this port's line ([`end_silence`]).
    silence: Duration,
    buf: Vec<u8>,
}

impl Requests {
    /// Requests framed in `mode` on `line`.
    #[must_use]
    pub fn new(mode: SerialMode, line: LineSettings) -> Self {
        Self { framer: RequestFramer::new(mode), silence: end_silence(line), buf: Vec::new() }
    }

    /// Waits for bytes (or, with an RTU frame begun, the silence that ends it); the requests
    /// they complete, and the bytes read (for the monitor). `Ok` with nothing: a silence.
    ///
    /// # Errors
    /// The port failed or closed.
    pub async fn next(&mut self, port: &mut SerialStream) -> std::io::Result<(Vec<RequestFrame>, Vec<u8>)> {
        let wait = if self.framer.waits_for_silence() { self.silence } else { Duration::from_hours(1) };
        self.buf.resize(512, 0);
        let mut requests = Vec::new();
        match tokio::time::timeout(wait, port.read(&mut self.buf)).await {
            Ok(Ok(0)) => Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the port closed")),
            Ok(Ok(n)) => {
                let got = self.buf.get(..n).unwrap_or_default().to_vec();
                self.framer.push(&got, &mut requests);
                Ok((requests, got))
            }
            Ok(Err(e)) => Err(e),
            Err(_) => {
                requests.extend(self.framer.silence());
                Ok((requests, Vec::new()))
            }
        }
    }
}

/// Writes the answer `pdu` of `unit` after `turnaround`, framed in `mode`; the frame written.
///
/// # Errors
/// The port failed.
pub async fn answer(
    port: &mut SerialStream,
    rs485: &crate::io::rs485::Rs485Args,
    mode: SerialMode,
    turnaround: Duration,
    unit: u8,
    pdu: &[u8],
) -> std::io::Result<Vec<u8>> {
    tokio::time::sleep(turnaround).await;
    let mut out = Vec::with_capacity(pdu.len() * 2 + 5);
    match mode {
        SerialMode::Rtu => encode_rtu(unit, pdu, &mut out),
        SerialMode::Ascii => encode_ascii(unit, pdu, &mut out),
    }
    rs485.send(port, &out).await?;
    Ok(out)
}
