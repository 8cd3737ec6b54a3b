//! The `mbtap` binary: parse the command line, run the command, map the outcome to an exit
//! code. Errors are printed once, with their context; a closed pipe is not an error.

use std::io;
use std::process::ExitCode;

use clap::Parser;
use mbtap::cli::Cli;

fn main() -> ExitCode {
    // `bridge --config FILE`: the file's settings become options the command line overrides.
    let args = match mbtap::bridge_config::expand(std::env::args_os().collect()) {
        Ok(args) => args,
        Err(e) => {
            eprintln!("mbtap: {e}");
            return ExitCode::from(2);
        }
    };
    let cli = Cli::parse_from(args);
    match mbtap::commands::run(cli.command) {
        Ok(code) => code,
        Err(e) => {
            // A closed pipe (`mbtap decode ... | head`) is not a failure.
            if e.downcast_ref::<io::Error>().is_some_and(|io| io.kind() == io::ErrorKind::BrokenPipe) {
                return ExitCode::SUCCESS;
            }
            eprintln!("mbtap: {e:#}");
            ExitCode::from(2)
        }
    }
}
