//! The `mbtap` binary: parse the command line, run the command, map the outcome to an exit
//! code. Errors are printed once, with their context; a closed pipe is not an error.

use std::io;
use std::process::ExitCode;

use clap::Parser;
use mbtap::cli::Cli;

fn main() -> ExitCode {
    let cli = Cli::parse();
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
