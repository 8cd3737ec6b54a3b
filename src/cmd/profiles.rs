//! `mbtap profiles list|check|show|import|export`: the device profiles — built in, the user's, a
//! file; imported from register sheets and Home Assistant YAML, exported to the site's tools.
//!
//! The import's pieces sit beside it: `import` (the command), `sheets` (the spreadsheet and YAML
//! readers), `profile_file` (the profile written as it is read).

use mbtap_analysis::report::format::printable;
use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Subcommand, ValueEnum};
use mbtap_device::profile::Table;
use mbtap_device::profile::export::Target;

use crate::config::devices::{load_profile_file, resolve_profile, user_profile_dir};

pub mod fuzzing;
mod import;
mod profile_file;
mod sheets;
use import::{import, parse_type_arg};

/// Device profiles: list them, show or check one, import one from a vendor's sheet, export one
/// for Home Assistant, ESPHome or Telegraf.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// List the profiles there are — built in (the seeds' devices and the energy meters) and in the
    /// user profile directory — with where each came from.
    List,
    /// Load a profile file and report the first problem with file:line:column, or a summary.
    /// A built-in name, a user profile's name (as `profiles import` leaves it), or a file.
    Check { file: String },
    /// Print every address a profile (a built-in name or a file) defines, per table.
    Show { profile: String },
    /// Make a profile from a vendor register sheet (CSV, XLSX) or Home Assistant `modbus:` YAML.
    ///
    /// Columns are found by their header names (address, name, type, scale, unit, access, word
    /// order, table, length, description — English, German, Chinese), below any title rows.
    /// Addresses as decimal, 0x2000, 2000H or Modicon numbers (40001). Every row that cannot be
    /// read is listed with its row, column and why, and skipped. Without -o, the profile goes to
    /// the user profile directory as NAME.toml and is usable by name at once.
    Import(ImportArgs),
    /// Write a profile as the configuration Home Assistant, ESPHome or Telegraf reads.
    Export(ExportArgs),
}

/// `profiles import`.
#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    /// The sheets or YAML files (several: one device's tables in separate files).
    #[arg(required_unless_present = "from")]
    pub files: Vec<PathBuf>,
    /// A SunSpec device to describe itself (`HOST:PORT`, `/dev/ttyX` with the line options):
    /// its model chain is discovered and written as a profile (`--format sunspec`).
    #[arg(long, value_name = "TARGET")]
    pub from: Option<String>,
    #[command(flatten)]
    pub line: crate::cli::args::SerialLineArgs,
    /// Where to write the profile (default: the user profile directory, NAME.toml).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// The source's format (default: from the file's extension or content).
    #[arg(long, value_enum)]
    pub format: Option<ImportFormat>,
    /// Columns by field: `address=B,name=A,type=D` (a letter, a number from 1, or a header text).
    #[arg(long)]
    pub columns: Option<String>,
    /// The table where the sheet does not say (no table column, no Modicon numbers).
    #[arg(long, value_enum)]
    pub table: Option<TableArg>,
    /// The word order of 32-bit values where the sheet does not say.
    #[arg(long, value_enum)]
    pub word_order: Option<WordOrderArg>,
    /// The type of registers where the sheet does not say (no type column, or an empty cell):
    /// `f32`, `u32`, `i16`, `string(8)`, … as a type column would give it. Without it and
    /// without a type column, registers are u16 and the import says so.
    #[arg(long = "type", value_name = "TYPE", value_parser = parse_type_arg)]
    pub value_type: Option<(mbtap_device::profile::format::ValueType, Option<u16>)>,
    /// The profile's name (default: the first file's name).
    #[arg(long)]
    pub name: Option<String>,
    /// The device's description in the profile (default: the name).
    #[arg(long)]
    pub device: Option<String>,
    /// Home Assistant YAML with several devices: the one to import (`slave`/`device_address`).
    #[arg(long)]
    pub unit: Option<u8>,
    /// The workbook sheet to read (default: the first).
    #[arg(long)]
    pub sheet: Option<String>,
    /// Replace a profile file that already exists (without it, an existing file is kept and
    /// the import refused).
    #[arg(long)]
    pub force: bool,
}

/// `profiles export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// A built-in profile name, a user profile name or a file.
    pub profile: String,
    #[arg(long, value_enum)]
    pub format: ExportFormat,
    /// The device's address in the exported configuration.
    #[arg(long, default_value_t = 1)]
    pub unit: u8,
    /// Where to write it (default: standard output).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Replace the file if it is already there (without, it is kept and nothing is written).
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ImportFormat {
    Csv,
    /// XLSX (also XLS and ODS).
    Xlsx,
    HomeAssistant,
    /// A SunSpec device's own description, read with --from.
    Sunspec,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    HomeAssistant,
    Esphome,
    Telegraf,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TableArg {
    Holding,
    Input,
    Coils,
    Discrete,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WordOrderArg {
    /// ABCD: the high word first.
    HighFirst,
    /// CDAB: the low word first ("word swapped").
    LowFirst,
}

pub fn run(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::List => list(),
        Command::Check { file } => check(&file),
        Command::Show { profile } => show(&profile),
        Command::Import(args) => import(&args),
        Command::Export(args) => export(&args),
    }
}

/// The built-in profiles, then the user's (each says whether it loads).
fn list() -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    for name in mbtap_device::profile::builtin::names() {
        if let Some(Ok(p)) = mbtap_device::profile::builtin::get(name) {
            let line = format!("{name:<8} built-in  {} — {}", p.meta.device, p.meta.document.as_deref().unwrap_or(""));
            writeln!(out, "{}", printable(&line))?;
        }
    }
    if let Some(dir) = user_profile_dir()
        && let Ok(entries) = std::fs::read_dir(&dir)
    {
        let mut files: Vec<_> =
            entries.flatten().map(|e| e.path()).filter(|p| p.extension().is_some_and(|e| e == "toml")).collect();
        files.sort();
        for f in files {
            let name = f.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let line = match load_profile_file(&f) {
                Ok(p) => {
                    // Where it came from: an import says so in its document.
                    let origin = p.meta.document.as_deref().filter(|d| d.starts_with("imported from"));
                    let origin = origin.map(|d| format!(" ({d})")).unwrap_or_default();
                    format!("{name:<8} user      {} — {}{origin}", p.meta.device, f.display())
                }
                Err(e) => format!("{name:<8} user      does not load: {e:#}"),
            };
            writeln!(out, "{}", printable(&line))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// A profile loaded — by name or file, as every command finds it (a name `profiles import`
/// says is usable is usable here) — its first problem with
/// file:line:column, or a summary counting entries as import counts them, and the registers
/// they cover.
fn check(spec: &str) -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    let p = resolve_profile(spec)?;
    let count = |t| {
        let entries = p.addresses(t).filter(|&a| p.slot(t, a).is_some_and(|(slot, _)| slot.part == 0)).count();
        let registers = p.addresses(t).count();
        if entries == registers { format!("{entries}") } else { format!("{entries} ({registers} registers)") }
    };
    let line = format!(
        "{spec}: ok — {} ({}): {} holding registers, {} input registers, {} coils, {} discrete inputs, {} reserved ranges",
        p.meta.name,
        p.meta.device,
        count(Table::HoldingRegisters),
        count(Table::InputRegisters),
        count(Table::Coils),
        count(Table::DiscreteInputs),
        p.reserved.len()
    );
    writeln!(out, "{}", printable(&line))?;
    Ok(ExitCode::SUCCESS)
}

/// Every address a profile defines, per table.
fn show(profile: &str) -> anyhow::Result<ExitCode> {
    let p = resolve_profile(profile)?;
    let mut out = std::io::stdout().lock();
    // Names, units and devices come from files anyone may have written: escaped.
    writeln!(out, "{}", printable(&format!("{} — {}", p.meta.name, p.meta.device)))?;
    for t in [Table::Coils, Table::DiscreteInputs, Table::HoldingRegisters, Table::InputRegisters] {
        writeln!(out, "[{}]", t.name())?;
        for a in p.addresses(t) {
            if let Some((slot, def)) = p.slot(t, a)
                && slot.part == 0
            {
                let ru = def.name_ru.as_deref().map(|r| format!(" ({r})")).unwrap_or_default();
                let unit = def.unit.as_deref().map(|u| format!(" [{u}]")).unwrap_or_default();
                writeln!(out, "{}", printable(&format!("  {a:>5} {}{ru}{unit}", slot.name)))?;
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `profiles export`.
fn export(args: &ExportArgs) -> anyhow::Result<ExitCode> {
    let p = resolve_profile(&args.profile)?;
    let target = match args.format {
        ExportFormat::HomeAssistant => Target::HomeAssistant,
        ExportFormat::Esphome => Target::Esphome,
        ExportFormat::Telegraf => Target::Telegraf,
    };
    let e = mbtap_device::profile::export::export(&p, args.unit, target);
    match &args.output {
        Some(o) => crate::output::whole_file::write_whole(
            o,
            e.text.as_bytes(),
            crate::output::whole_file::Existing::forced(args.force),
        )?,
        None => std::io::stdout().lock().write_all(e.text.as_bytes())?,
    }
    let mut err = std::io::stderr().lock();
    for s in &e.skipped {
        writeln!(err, "mbtap: left out {}", printable(s))?;
    }
    writeln!(err, "mbtap: {} entries written, {} left out", e.written, e.skipped.len())?;
    Ok(ExitCode::SUCCESS)
}
