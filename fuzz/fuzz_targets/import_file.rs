//! Any bytes as a file `mbtap profiles import` is given — CSV, XLSX, XLS, ODS or Home Assistant
//! YAML, by the first byte — imported whole, as the command runs it: the container read, the
//! rows, the points, the profile written and loaded back. No crash, and no input may make it
//! produce past its budgets: `.ci/run` runs this under `-rss_limit_mb=256`, so memory an input
//! makes the import hold (not what the file claims) is what fails it.
#![no_main]

use clap::{CommandFactory, FromArgMatches};

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&kind, body)) = data.split_first() else { return };
    let ext = ["csv", "xlsx", "xls", "ods", "yaml"][usize::from(kind % 5)];
    let dir = std::env::temp_dir().join(format!("mbtap-fuzz-import-{}", std::process::id()));
    if std::fs::create_dir_all(&dir).is_err() {
        return;
    }
    let input = dir.join(format!("in.{ext}"));
    if std::fs::write(&input, body).is_err() {
        return;
    }
    let out = dir.join("out.toml");
    let args = [
        "mbtap",
        "profiles",
        "import",
        input.to_str().unwrap_or_default(),
        "-o",
        out.to_str().unwrap_or_default(),
        "--force",
        "--name",
        "fuzz",
        "--table",
        "holding",
    ];
    let Ok(matches) = mbtap::cmd::Cli::command().try_get_matches_from(args) else { return };
    let Ok(cli) = mbtap::cmd::Cli::from_arg_matches(&matches) else { return };
    // Refusals are answers; a panic or memory past the limit is what the fuzzer looks for.
    let _ = mbtap::cmd::run(cli.command, &matches);
});
