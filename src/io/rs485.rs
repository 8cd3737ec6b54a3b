//! RS-485 direction control for the ports mbtap drives (the bridge's lines, reverse mode,
//! `play`): the kernel's RS-485 mode (`TIOCSRS485`, set through serial2 so our code stays free
//! of `unsafe`), or RTS raised by mbtap around each frame and dropped when the transmit
//! completes (`tcdrain`, not a guess from the baud rate). A port that cannot do the mode asked
//! for — a pseudo-terminal, a driver without RS-485 — is refused with its name and what to do,
//! never silently driven without direction control.

use std::time::Duration;

use anyhow::Context as _;
use clap::Args;
use tokio::io::AsyncWriteExt as _;
use tokio_serial::SerialPort as _;

/// How the transmitter is switched on and off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Rs485Mode {
    /// Nothing: an adapter with automatic direction control, or RS-232/RS-422.
    #[default]
    Off,
    /// The kernel's RS-485 mode (TIOCSRS485): the driver raises RTS for each transmission.
    Kernel,
    /// mbtap raises RTS before each frame and drops it when the frame has left (tcdrain).
    Rts,
}

/// `--rs485` options.
#[derive(Debug, Clone, Copy, Args, Default)]
pub struct Rs485Args {
    /// Transmitter direction control: off (auto-direction adapters), kernel (TIOCSRS485), rts
    /// (mbtap toggles RTS around each frame).
    #[arg(long, value_enum, default_value_t = Rs485Mode::Off, value_name = "MODE")]
    pub rs485: Rs485Mode,
    /// Delay after raising RTS before the first character, µs (kernel: rounded to ms).
    #[arg(long, default_value_t = 0, value_name = "US")]
    pub rs485_delay_before_us: u64,
    /// Delay after the last character before dropping RTS, µs (kernel: rounded to ms).
    #[arg(long, default_value_t = 0, value_name = "US")]
    pub rs485_delay_after_us: u64,
    /// Kernel mode: keep the receiver on while sending (full-duplex / 4-wire RS-485; a 2-wire
    /// bus then hears its own frames: use --echo).
    #[arg(long)]
    pub rs485_rx_during_tx: bool,
}

impl Rs485Args {
    fn before(&self) -> Duration {
        Duration::from_micros(self.rs485_delay_before_us)
    }

    fn after(&self) -> Duration {
        Duration::from_micros(self.rs485_delay_after_us)
    }

    /// Sets the port up for the mode (kernel: the driver's RS-485 configuration; rts: RTS
    /// dropped, proving the port has it). Called before every open of the port.
    ///
    /// # Errors
    /// The port cannot do the mode: said with its name and what to do instead.
    pub fn prepare(&self, path: &str) -> anyhow::Result<()> {
        match self.rs485 {
            Rs485Mode::Off => Ok(()),
            Rs485Mode::Kernel => {
                let port = serial2::SerialPort::open(path, serial2::KeepSettings)
                    .with_context(|| format!("--rs485 kernel: opening {path}"))?;
                let mut config = serial2::rs4xx::Rs485Config::new();
                config.set_delay_before_send(self.before());
                config.set_delay_after_send(self.after());
                config.set_full_duplex(self.rs485_rx_during_tx);
                port.set_rs4xx_mode(config).with_context(|| {
                    format!(
                        "--rs485 kernel: {path} does not take the kernel's RS-485 mode (TIOCSRS485) — a pseudo-terminal or a driver without RS-485 support; use an adapter with automatic direction control (--rs485 off), or --rs485 rts if its RTS pin drives the transceiver"
                    )
                })
            }
            Rs485Mode::Rts => {
                let port = serial2::SerialPort::open(path, serial2::KeepSettings)
                    .with_context(|| format!("--rs485 rts: opening {path}"))?;
                port.set_rts(false).with_context(|| {
                    format!(
                        "--rs485 rts: {path} has no RTS line mbtap can drive (a pseudo-terminal, or a USB adapter without modem lines); use --rs485 kernel if its driver supports RS-485, or an adapter with automatic direction control (--rs485 off)"
                    )
                })
            }
        }
    }

    /// Writes one frame with the mode's direction control; returns once it is on its way
    /// (with `rts`: once it has left — tcdrain — and RTS is down again).
    ///
    /// # Errors
    /// The write or a modem-line change failed.
    pub async fn send(&self, port: &mut tokio_serial::SerialStream, frame: &[u8]) -> std::io::Result<()> {
        if self.rs485 != Rs485Mode::Rts {
            return port.write_all(frame).await;
        }
        port.write_request_to_send(true).map_err(std::io::Error::other)?;
        if !self.before().is_zero() {
            tokio::time::sleep(self.before()).await;
        }
        let written = port.write_all(frame).await;
        // tcdrain: back when the last character has left the UART, not when it was queued.
        let drained = if written.is_ok() { port.flush().await } else { Ok(()) };
        if !self.after().is_zero() {
            tokio::time::sleep(self.after()).await;
        }
        port.write_request_to_send(false).map_err(std::io::Error::other)?;
        written.and(drained)
    }

    /// As [`Self::send`], on a blocking port (`play`, which paces its writes on a thread).
    ///
    /// # Errors
    /// The write or a modem-line change failed.
    pub fn send_blocking(&self, port: &mut dyn tokio_serial::SerialPort, bytes: &[u8]) -> std::io::Result<()> {
        if self.rs485 != Rs485Mode::Rts {
            return port.write_all(bytes);
        }
        port.write_request_to_send(true).map_err(std::io::Error::other)?;
        std::thread::sleep(self.before());
        let written = port.write_all(bytes);
        let drained = if written.is_ok() { port.flush() } else { Ok(()) };
        std::thread::sleep(self.after());
        port.write_request_to_send(false).map_err(std::io::Error::other)?;
        written.and(drained)
    }
}
