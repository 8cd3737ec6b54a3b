//! The `mbtap` binary: parse the command line, run the command, map the outcome to an exit
//! code. Errors are printed once, with their context; a closed pipe is not an error.

use std::io;
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches};
use mbtap::cmd::{self, Cli};

fn main() -> ExitCode {
    let matches = Cli::command().get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    match cmd::run(cli.command, &matches) {
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
