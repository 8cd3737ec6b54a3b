//! `mbtap profiles list|check|show`: the device profiles — built in, the user's, a file.

use mbtap_core::report::format::printable;
use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Subcommand;
use mbtap_core::profile::Table;

use crate::config::devices::{load_profile_file, resolve_profile, user_profile_dir};

/// Device profiles: check a profile file, or show what it defines.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// List the built-in profiles.
    List,
    /// Load a profile file and report the first problem with file:line:column, or a summary.
    Check { file: PathBuf },
    /// Print every address a profile (a built-in name or a file) defines, per table.
    Show { profile: String },
}

pub fn run(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::List => list(),
        Command::Check { file } => check(&file),
        Command::Show { profile } => show(&profile),
    }
}

/// The built-in profiles, then the user's (each says whether it loads).
fn list() -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    for name in mbtap_core::profile::builtin::names() {
        if let Some(Ok(p)) = mbtap_core::profile::builtin::get(name) {
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
                Ok(p) => format!("{name:<8} user      {} — {}", p.meta.device, f.display()),
                Err(e) => format!("{name:<8} user      does not load: {e:#}"),
            };
            writeln!(out, "{}", printable(&line))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// A profile file loaded, its first problem with file:line:column or a summary.
fn check(file: &std::path::Path) -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    let p = load_profile_file(file)?;
    let count = |t| p.addresses(t).count();
    let line = format!(
        "{}: ok — {} ({}): {} coils, {} discrete inputs, {} holding registers, {} input registers, {} reserved ranges",
        file.display(),
        p.meta.name,
        p.meta.device,
        count(Table::Coils),
        count(Table::DiscreteInputs),
        count(Table::HoldingRegisters),
        count(Table::InputRegisters),
        p.reserved.len()
    );
    writeln!(out, "{}", printable(&line))?;
    Ok(ExitCode::SUCCESS)
}

/// Every address a profile defines, per table.
fn show(profile: &str) -> anyhow::Result<ExitCode> {
    let p = resolve_profile(profile)?;
    let mut out = std::io::stdout().lock();
    // Names, units and devices come from files anyone may have written: escaped (issue 24).
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
