//! `profiles import` run whole from a file's bytes, for the fuzz target `import_file` and the
//! seeds' replay in `cargo test`: the first byte picks the kind (CSV, XLSX, XLS, ODS, Home
//! Assistant YAML), the rest is the file — the container read, the rows, the points, the
//! profile written and loaded back, exactly as the command runs them.

use clap::{CommandFactory as _, FromArgMatches as _};

/// Imports `data` as a file. Refusals are answers; a panic (or, under the fuzzer's memory
/// limit, memory an input makes the import hold) is what is looked for.
pub fn import_file(data: &[u8]) {
    let Some((&kind, body)) = data.split_first() else { return };
    let ext = ["csv", "xlsx", "xls", "ods", "yaml"][usize::from(kind % 5)];
    let dir = std::env::temp_dir().join(format!(
        "mbtap-import-file-{}-{:?}",
        std::process::id(),
        std::thread::current().id()
    ));
    if std::fs::create_dir_all(&dir).is_err() {
        return;
    }
    let input = dir.join(format!("in.{ext}"));
    let out = dir.join("out.toml");
    if std::fs::write(&input, body).is_err() {
        return;
    }
    let (Some(input), Some(out)) = (input.to_str(), out.to_str()) else { return };
    let args = ["mbtap", "profiles", "import", input, "-o", out, "--force", "--name", "fuzz", "--table", "holding"];
    let Ok(matches) = crate::cmd::Cli::command().try_get_matches_from(args) else { return };
    let Ok(cli) = crate::cmd::Cli::from_arg_matches(&matches) else { return };
    let _ = crate::cmd::run(cli.command, &matches);
    let _ = std::fs::remove_dir_all(&dir);
}
