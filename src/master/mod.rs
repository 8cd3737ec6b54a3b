//! `read`, `write` and `watch`: mbtap as a Modbus master that speaks in the profiles' names.
//! The requests are planned and checked by `mbtap_device::query` (pure); this module opens the
//! link ([`link`]: a line of the bridge's, through the gateway core), sends them ([`exec`]) and
//! prints what came back ([`show`]).
//!
//! Masters of other commands go through the same link: [`sunspec`] (`--device sunspec`: the model
//! chain discovered), [`remote`] (writes from the broker), [`mirror`] (`simulate --mirror`'s reads
//! of the source device), [`confirm`] (`learn --confirm`'s reads).

pub mod confirm;
pub mod exec;
pub mod link;
pub mod mirror;
pub mod remote;
pub mod show;
pub mod sunspec;

use clap::Args;

use crate::cli::args::SerialLineArgs;

/// Where and whom the master asks, shared by `read`, `write` and `watch`.
#[derive(Debug, Clone, Args)]
pub struct MasterArgs {
    /// The device: a serial port (`/dev/ttyUSB0`, RTU), `HOST:PORT` or `tcp://HOST:PORT`
    /// (Modbus TCP), or `rtu+tcp://HOST:PORT` (RTU frames over TCP, as cheap Ethernet-to-RS-485
    /// converters speak).
    pub target: String,
    /// The unit (slave) address [default: the profile's default address, else 1].
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=247))]
    pub unit: Option<u8>,
    /// The device's profile, for names, scaling and checks: a built-in name (mk4, mkzp,
    /// display), a user profile or a file; `sunspec`: the device's SunSpec models, discovered,
    /// points named MODEL.POINT (common.Mn, inverter_three_phase.W, 103.W).
    #[arg(long, value_name = "PROFILE")]
    pub device: Option<String>,
    /// How long to wait for each answer, in ms.
    #[arg(long, default_value_t = 1000, value_name = "MS")]
    pub timeout_ms: u64,
    /// How often to send a request again after no answer (never after an exception).
    #[arg(long, default_value_t = 0)]
    pub retries: u32,
    /// Output format [default: text on a terminal, jsonl in a pipe].
    #[arg(long, value_enum)]
    pub format: Option<MasterFormat>,
    #[command(flatten)]
    pub line: SerialLineArgs,
}

/// How values are printed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MasterFormat {
    /// One line per value: `input 430 Phase A (L1) voltage = 230.5 V (raw 2305)`.
    Text,
    /// One JSON object per value: unit, table, address, name, raw, value, unit_of_measure.
    Jsonl,
}

impl MasterArgs {
    /// The format asked for, else text on a terminal and JSON lines in a pipe.
    #[must_use]
    pub fn format(&self) -> MasterFormat {
        use std::io::IsTerminal;
        self.format.unwrap_or(if std::io::stdout().is_terminal() { MasterFormat::Text } else { MasterFormat::Jsonl })
    }

    /// Whether `--device sunspec` asks for the device's own SunSpec description.
    #[must_use]
    pub fn sunspec(&self) -> bool {
        self.device.as_deref().is_some_and(|d| d.eq_ignore_ascii_case("sunspec"))
    }

    /// The profile named by `--device`, if any. `--device sunspec` (for `watch` and `write`;
    /// `read` decodes SunSpec itself): the device's model chain discovered now and made a
    /// profile, its scale factors as read now.
    pub fn profile(&self) -> anyhow::Result<Option<mbtap_device::profile::Profile>> {
        if self.sunspec() {
            let unit = self.unit.unwrap_or(1);
            let timeout = std::time::Duration::from_millis(self.timeout_ms);
            let mut link = link::Link::new(&self.target, &self.line, timeout, self.retries)?;
            let imported = crate::runtime()?.block_on(sunspec::import(&mut link, unit))?;
            let toml = imported.to_toml("sunspec", &format!("SunSpec device at {}", self.target), &self.target);
            return Ok(Some(mbtap_device::profile::load("sunspec", &toml)?));
        }
        self.device.as_deref().map(crate::config::devices::resolve_profile).transpose()
    }

    /// When the unit was not given: which address was asked and why, for a failure's message.
    #[must_use]
    pub fn unit_hint(&self, profile: Option<&mbtap_device::profile::Profile>) -> Option<String> {
        if self.unit.is_some() {
            return None;
        }
        let unit = self.unit(profile);
        Some(match profile.and_then(|p| p.meta.default_address.map(|_| p.meta.name.as_str())) {
            Some(name) => format!(
                "unit {unit} was asked because it is the {name} profile's default address: give --unit N if the device answers at another"
            ),
            None => format!("unit {unit} was asked by default: give --unit N for the device's address"),
        })
    }

    /// `--unit`, else the profile's default address, else 1.
    #[must_use]
    pub fn unit(&self, profile: Option<&mbtap_device::profile::Profile>) -> u8 {
        self.unit.or_else(|| profile.and_then(|p| p.meta.default_address)).unwrap_or(1)
    }
}
