//! `profiles import`: a vendor sheet (CSV, XLSX, XLS, ODS), SunSpec or Home Assistant YAML read
//! into a profile, written to the profile directory without replacing one in silence.

use super::*;
use mbtap_analysis::report::format::printable;
use mbtap_device::profile::Table;
use mbtap_device::profile::import::Sink as _;
use mbtap_device::profile::import::sheet::{SheetOptions, parse_columns, read_sheet};
use profile_file::{ProfileFile, destination};
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
    let out = destination(args.output.as_deref(), &name)?;
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => std::path::PathBuf::from("."),
    };
    let mut err = std::io::stderr().lock();
    let mut sink = ProfileFile::new(&dir, &mut err)?;
    let sources: Vec<String>;
    if let Some(target) = &args.from {
        anyhow::ensure!(
            args.format.is_none_or(|f| f == ImportFormat::Sunspec) && args.files.is_empty(),
            "--from reads a SunSpec device: give no files (and --format sunspec or none)"
        );
        let unit = args.unit.unwrap_or(1);
        let timeout = std::time::Duration::from_secs(1);
        let mut link = crate::master::link::Link::new(target, &args.line, timeout, 2)?;
        let imported = crate::cmd::runtime()?.block_on(crate::master::sunspec::import(&mut link, unit))?;
        sink.reading(target, false);
        for n in imported.notes {
            sink.note(n);
        }
        for p in imported.problems {
            sink.problem(p);
        }
        for p in imported.points {
            sink.point(p);
        }
        sources = vec![target.clone()];
    } else {
        anyhow::ensure!(
            args.format != Some(ImportFormat::Sunspec),
            "--format sunspec reads a device: give --from HOST:PORT or a serial port"
        );
        for file in &args.files {
            let format = match args.format {
                Some(f) => f,
                None => detect(file)?,
            };
            sink.reading(&file.display().to_string(), args.files.len() > 1);
            match format {
                ImportFormat::Csv => {
                    let mut rows = super::sheets::csv_rows(file)?;
                    if let Some(note) = rows.encoding_note() {
                        sink.note(note.to_owned());
                    }
                    read_sheet(&mut rows, &opts, &mut sink)?;
                }
                ImportFormat::Xlsx => {
                    read_sheet(&mut super::sheets::read_workbook(file, args.sheet.as_deref())?, &opts, &mut sink)?;
                }
                ImportFormat::Sunspec => anyhow::bail!("--format sunspec reads a device: give --from"),
                ImportFormat::HomeAssistant => {
                    let unit = super::sheets::read_yaml(file, args.unit, &mut sink)?;
                    sink.note(format!("device {unit}"));
                }
            }
        }
        sources = args.files.iter().map(|f| f.display().to_string()).collect();
    }
    if let Some(target) = args.from.as_ref().filter(|_| sink.hint().is_some()) {
        // A device, not a sheet: the sheet's advice (header rows, --columns) would not help.
        anyhow::bail!(
            "{target}: its SunSpec models (listed above) hold no point a profile can keep: no profile written; \
             check --unit, or see what the device says with `mbtap read {target} --device sunspec`"
        );
    }
    if sink.unsaid() > 0 {
        eprintln!("mbtap: … and {} more problems like those above, not listed", sink.unsaid());
    }
    if let Some(why) = sink.refused() {
        anyhow::bail!("nothing imported: {why}");
    }
    if let Some(hint) = sink.hint() {
        anyhow::bail!("nothing imported ({} problem(s), listed above): {hint}", sink.problems());
    }
    let device = args.device.clone().unwrap_or_else(|| name.clone());
    // Reserved first: a profile (or a link) already there is kept, unless --force.
    if !args.force {
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&out) {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => anyhow::bail!(
                "{} already exists (a profile or a link): kept as it is; give --force to replace it, or another --name/-o",
                out.display()
            ),
            Err(e) => return Err(e).with_context(|| format!("creating {}", out.display())),
        }
    }
    let tmp = out.with_extension(format!("toml.new-{}", std::process::id()));
    // The new file replaces the path itself (a link there is replaced, not followed).
    let written = sink
        .write(&tmp, &name, &device, &sources.join(", "))
        .and_then(|()| std::fs::rename(&tmp, &out).with_context(|| format!("replacing {}", out.display())));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        if !args.force {
            let _ = std::fs::remove_file(&out);
        }
        return Err(e);
    }
    let [holding, input, coils, discrete] = sink.counts();
    let skipped = sink.problems();
    drop(sink);
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
        "mbtap: wrote {} ({}): {holding} holding registers, {input} input registers, {coils} coils, {discrete} discrete inputs; {skipped} skipped",
        out.display(),
        printable(&name),
    )?;
    Ok(ExitCode::SUCCESS)
}
