//! `mbtap completions SHELL`: the shell completion script for bash, zsh, fish, PowerShell or
//! elvish, from the same command definitions the parser uses (clap_complete), on stdout.
//! `source <(mbtap completions bash)`, or installed by the Debian package.

use std::process::ExitCode;

use std::io::Write as _;

use anyhow::Context as _;
use clap::CommandFactory as _;

/// Print the shell completion script (bash, zsh, fish, powershell, elvish) on stdout.
///
/// Example: `mbtap completions bash > /etc/bash_completion.d/mbtap`, or `source <(mbtap
/// completions bash)` for this shell only.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The shell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let mut cmd = super::Cli::command();
    // Into memory first: clap_complete panics on a failed write (`| head`), and a closed pipe
    // is success here as everywhere in mbtap.
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "mbtap", &mut script);
    match std::io::stdout().lock().write_all(&script) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e).context("writing the script"),
        _ => Ok(ExitCode::SUCCESS),
    }
}
