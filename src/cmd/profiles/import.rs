//! `profiles import`: a vendor sheet (CSV, XLSX, XLS, ODS), SunSpec or Home Assistant YAML read
//! into a profile, written to the profile directory without replacing one in silence.

use super::*;
use crate::config::devices::user_profile_dir;
use mbtap_analysis::report::format::printable;
use mbtap_device::profile::Table;
use mbtap_device::profile::import::sheet::{SheetOptions, parse_columns};
use std::process::ExitCode;

/// The format of `path`: by extension, else by content.
pub(super) fn detect(path: &std::path::Path) -> anyhow::Result<ImportFormat> {
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
pub(super) fn parse_type_arg(s: &str) -> Result<(mbtap_device::profile::format::ValueType, Option<u16>), String> {
    mbtap_device::profile::import::notation::parse_type(s)
}

/// `profiles import`: the sheets read, the profile written and loaded back, what was skipped said.
pub(super) fn import(args: &ImportArgs) -> anyhow::Result<ExitCode> {
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
pub(super) fn write_imported(
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
pub(super) fn write_profile_file(path: &std::path::Path, text: &str, force: bool) -> anyhow::Result<()> {
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
