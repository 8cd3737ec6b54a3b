//! `mbtap profiles list|check|show|import|export`: the device profiles — built in, the user's, a
//! file; imported from register sheets and Home Assistant YAML, exported to the site's tools.

use mbtap_analysis::report::format::printable;
use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Subcommand, ValueEnum};
use mbtap_device::profile::Table;
use mbtap_device::profile::export::Target;
use mbtap_device::profile::import::sheet::{SheetOptions, parse_columns};

use crate::config::devices::{load_profile_file, resolve_profile, user_profile_dir};

/// Device profiles: check a profile file, or show what it defines.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// List the built-in profiles.
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

/// A profile loaded — by name or file, as every command finds it (issue 42: the name
/// `profiles import` said was usable failed here with "os error 2") — its first problem with
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

/// The format of `path`: by extension, else by content.
fn detect(path: &std::path::Path) -> anyhow::Result<ImportFormat> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    Ok(match ext.as_str() {
        "xlsx" | "xlsm" | "xls" | "ods" => ImportFormat::Xlsx,
        "yaml" | "yml" => ImportFormat::HomeAssistant,
        "csv" | "tsv" | "txt" => ImportFormat::Csv,
        _ => {
            let head = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
            let head = &head[..head.len().min(4096)];
            if head.starts_with(b"PK\x03\x04") || head.starts_with(&[0xD0, 0xCF, 0x11, 0xE0]) {
                ImportFormat::Xlsx
            } else if String::from_utf8_lossy(head).contains("input_type:")
                || String::from_utf8_lossy(head).contains("modbus:")
            {
                ImportFormat::HomeAssistant
            } else {
                ImportFormat::Csv
            }
        }
    })
}

/// `--type TYPE`, read as a sheet's type column would read it.
fn parse_type_arg(s: &str) -> Result<(mbtap_device::profile::format::ValueType, Option<u16>), String> {
    mbtap_device::profile::import::notation::parse_type(s)
}

/// `profiles import`: the sheets read, the profile written and loaded back, what was skipped said.
fn import(args: &ImportArgs) -> anyhow::Result<ExitCode> {
    let columns = match &args.columns {
        Some(c) => parse_columns(c).map_err(|e| anyhow::anyhow!("--columns {c:?}: {e}"))?,
        None => Vec::new(),
    };
    let opts = SheetOptions {
        columns,
        table: args.table.map(|t| match t {
            TableArg::Holding => Table::HoldingRegisters,
            TableArg::Input => Table::InputRegisters,
            TableArg::Coils => Table::Coils,
            TableArg::Discrete => Table::DiscreteInputs,
        }),
        word_order: args.word_order.map(|w| match w {
            WordOrderArg::HighFirst => mbtap_device::profile::format::WordOrder::HighFirst,
            WordOrderArg::LowFirst => mbtap_device::profile::format::WordOrder::LowFirst,
        }),
        value_type: args.value_type,
    };
    let mut all = mbtap_device::profile::import::Imported::default();
    let mut err = std::io::stderr().lock();
    if let Some(target) = &args.from {
        anyhow::ensure!(
            args.format.is_none_or(|f| f == ImportFormat::Sunspec) && args.files.is_empty(),
            "--from reads a SunSpec device: give no files (and --format sunspec or none)"
        );
        let unit = args.unit.unwrap_or(1);
        let timeout = std::time::Duration::from_secs(1);
        let mut link = crate::master::link::Link::new(target, &args.line, timeout)?;
        let imported = crate::cmd::runtime()?.block_on(crate::master::sunspec::import(&mut link, unit, timeout, 2))?;
        for n in &imported.notes {
            writeln!(err, "mbtap: {target}: {}", printable(n))?;
        }
        for p in &imported.problems {
            writeln!(err, "mbtap: {target}: skipped {}", printable(&p.to_string()))?;
        }
        return write_imported(args, &imported, std::slice::from_ref(target), &mut err);
    }
    anyhow::ensure!(
        args.format != Some(ImportFormat::Sunspec),
        "--format sunspec reads a device: give --from HOST:PORT or a serial port"
    );
    for file in &args.files {
        let format = match args.format {
            Some(f) => f,
            None => detect(file)?,
        };
        let one = match format {
            ImportFormat::Csv => {
                mbtap_device::profile::import::sheet::parse_sheet(&crate::config::sheets::read_csv(file)?, &opts)
            }
            ImportFormat::Xlsx => mbtap_device::profile::import::sheet::parse_sheet(
                &crate::config::sheets::read_workbook(file, args.sheet.as_deref())?,
                &opts,
            ),
            ImportFormat::Sunspec => anyhow::bail!("--format sunspec reads a device: give --from"),
            ImportFormat::HomeAssistant => {
                let yaml = crate::config::sheets::read_yaml(file)?;
                let (imported, unit) =
                    mbtap_device::profile::import::home_assistant::parse_home_assistant(&yaml, args.unit)
                        .with_context(|| format!("reading {}", file.display()))?;
                writeln!(err, "mbtap: {}: device {unit}", file.display())?;
                imported
            }
        };
        for n in &one.notes {
            writeln!(err, "mbtap: {}: {}", file.display(), printable(n))?;
        }
        for p in one.problems {
            writeln!(err, "mbtap: {}: skipped {}", file.display(), printable(&p.to_string()))?;
            all.problems.push(p);
        }
        for mut p in one.points {
            if args.files.len() > 1 {
                p.origin = format!("{}, {}", file.display(), p.origin);
            }
            all.add(p);
        }
        all.notes.extend(one.notes.into_iter().map(|n| format!("{}: {n}", file.display())));
    }
    let sources: Vec<String> = args.files.iter().map(|f| f.display().to_string()).collect();
    write_imported(args, &all, &sources, &mut err)
}

/// The profile from `all` (made from `sources`) written, loaded back and summarised.
fn write_imported(
    args: &ImportArgs,
    all: &mbtap_device::profile::import::Imported,
    sources: &[String],
    err: &mut impl std::io::Write,
) -> anyhow::Result<ExitCode> {
    let stem = args
        .files
        .first()
        .and_then(|f| f.file_stem())
        .map_or_else(|| "sunspec".into(), |s| s.to_string_lossy().into_owned());
    let name = args.name.clone().unwrap_or(stem);
    anyhow::ensure!(
        !name.is_empty() && !name.contains(['/', '\\']) && name != "." && name != "..",
        "--name {name:?}: a profile name is used as a file name (no slashes)"
    );
    let device = args.device.clone().unwrap_or_else(|| name.clone());
    let toml = all.to_toml(&name, &device, &sources.join(", "));
    let counts = all.counts();
    let count = |t| counts.get(&t).copied().unwrap_or(0);
    if all.points.is_empty() {
        // The hint names the fix the problems point to (issue 42: "check the header row or give
        // --columns" where every row wanted --table).
        let said = |what: &str| all.problems.iter().any(|p| p.why.contains(what));
        let hint = if said("give --table") {
            "the sheet does not say which table: give --table holding|input|coils|discrete"
        } else if said("no header row") {
            "give the columns with --columns address=B,name=A,…"
        } else {
            "fix the rows named above, or give --columns, --table, --type"
        };
        anyhow::bail!("nothing imported ({} problem(s), listed above): {hint}", all.problems.len());
    }
    // What is written must load like a hand-written profile: checked before it is kept.
    mbtap_device::profile::import::load_back(&name, &toml)
        .context("the imported profile does not load (a bug: please report it with the sheet)")?;
    let out = if let Some(o) = &args.output {
        o.clone()
    } else {
        let dir = user_profile_dir().context("no user profile directory (set MBTAP_PROFILE_DIR or HOME), give -o")?;
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        dir.join(format!("{name}.toml"))
    };
    write_profile_file(&out, &toml, args.force)?;
    if args.output.is_none() && mbtap_device::profile::builtin::get(&name).is_some() {
        writeln!(
            err,
            "mbtap: warning: {name} is also a built-in profile, which is found first by that name; \
             use the file ({}) or import again with another --name",
            out.display()
        )?;
    }
    writeln!(
        err,
        "mbtap: wrote {} ({}): {} holding registers, {} input registers, {} coils, {} discrete inputs; {} skipped",
        out.display(),
        printable(&name),
        count(Table::HoldingRegisters),
        count(Table::InputRegisters),
        count(Table::Coils),
        count(Table::DiscreteInputs),
        all.problems.len()
    )?;
    Ok(ExitCode::SUCCESS)
}

/// Writes a profile to `path` without ever writing through a link placed there: a new file is
/// created exclusively (`O_EXCL` refuses an existing file or symlink); with `force`, the text goes
/// to a new temporary file beside it that then replaces the path itself (a symlink is replaced,
/// not followed).
fn write_profile_file(path: &std::path::Path, text: &str, force: bool) -> anyhow::Result<()> {
    let exclusive = |p: &std::path::Path| std::fs::OpenOptions::new().write(true).create_new(true).open(p);
    if !force {
        let mut f = match exclusive(path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => anyhow::bail!(
                "{} already exists (a profile or a link): kept as it is; give --force to replace it, or another --name/-o",
                path.display()
            ),
            Err(e) => return Err(e).with_context(|| format!("creating {}", path.display())),
        };
        return f.write_all(text.as_bytes()).with_context(|| format!("writing {}", path.display()));
    }
    let tmp = path.with_extension(format!("toml.new-{}", std::process::id()));
    let mut f = exclusive(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    let written = f.write_all(text.as_bytes()).and_then(|()| f.sync_all());
    drop(f);
    if let Err(e) = written.and_then(|()| std::fs::rename(&tmp, path)) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e).with_context(|| format!("replacing {}", path.display()));
    }
    Ok(())
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
        Some(o) => std::fs::write(o, &e.text).with_context(|| format!("writing {}", o.display()))?,
        None => std::io::stdout().lock().write_all(e.text.as_bytes())?,
    }
    let mut err = std::io::stderr().lock();
    for s in &e.skipped {
        writeln!(err, "mbtap: left out {}", printable(s))?;
    }
    writeln!(err, "mbtap: {} entries written, {} left out", e.written, e.skipped.len())?;
    Ok(ExitCode::SUCCESS)
}
