//! The commands, one file each: its options (clap derive) and its `run`. The work itself is in
//! the libraries (`crates/`) and the edge modules (`bridge`, `source`, `tui`,
//! `output`); a command file glues them to the command line. Adding a command is adding a file
//! here and a line to [`Command`] and [`run`].

use std::process::ExitCode;

use clap::{ArgMatches, Parser, Subcommand};

pub mod bridge;
pub mod completions;
pub mod decode;
pub mod demo;
pub mod diff;
pub mod export;
pub mod generate;
pub mod generate_config;
pub mod learn;
pub mod man;
pub mod play;
pub mod probe;
pub mod profiles;
pub mod read;
pub mod replay;
pub mod report;
pub mod scan;
pub mod simulate;
pub mod sniff;
pub mod tap;
pub mod watch;
pub mod write;

/// mbtap — a Modbus RTU/ASCII bus analyzer: sniff, decode, record, replay, bridge, read and write.
#[derive(Debug, Parser)]
#[command(name = "mbtap", version = long_version(), about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    Decode(decode::Args),
    Replay(replay::Args),
    Generate(generate::Args),
    Export(export::Args),
    Sniff(sniff::Args),
    Play(play::Args),
    Tap(tap::Args),
    Demo(demo::Args),
    Simulate(simulate::Args),
    #[command(args_override_self = true)]
    Bridge(Box<bridge::Args>),
    GenerateConfig(generate_config::Args),
    Scan(scan::Args),
    Report(report::Args),
    #[command(subcommand)]
    Profiles(profiles::Command),
    Read(read::Args),
    Write(write::Args),
    Watch(watch::Args),
    Learn(learn::Args),
    Probe(probe::Args),
    Diff(diff::Args),
    Completions(completions::Args),
    Man(man::Args),
}

/// `0.1.0 (commit 1a2b3c4d 2026-12-02)`: the version, and the commit and its date when the
/// build had a git checkout (set by build.rs; a build from a source archive says so).
#[must_use]
pub fn long_version() -> &'static str {
    concat!(env!("CARGO_PKG_VERSION"), " (", env!("MBTAP_BUILD_COMMIT"), ")")
}

/// Runs one command; the exit code on success. `matches` is the whole command line as parsed,
/// for the commands that need to know which options were given (`bridge --config`).
///
/// # Errors
/// What went wrong, with context, for `main` to print once.
pub fn run(command: Command, matches: &ArgMatches) -> anyhow::Result<ExitCode> {
    match command {
        Command::Decode(args) => decode::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Generate(args) => generate::run(&args),
        Command::Export(args) => export::run(args),
        Command::Sniff(args) => sniff::run(args),
        Command::Play(args) => play::run(&args),
        Command::Tap(args) => tap::run(args),
        Command::Demo(args) => demo::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Bridge(args) => bridge::run(*args, matches.subcommand_matches("bridge")),
        Command::GenerateConfig(args) => generate_config::run(&args),
        Command::Scan(args) => scan::run(&args),
        Command::Report(args) => report::run(args),
        Command::Profiles(command) => profiles::run(command),
        Command::Read(args) => read::run(&args),
        Command::Write(args) => write::run(&args),
        Command::Watch(args) => watch::run(&args),
        Command::Learn(args) => learn::run(&args),
        Command::Probe(args) => probe::run(&args),
        Command::Diff(args) => diff::run(&args),
        Command::Completions(args) => completions::run(&args),
        Command::Man(args) => man::run(&args),
    }
}

pub(crate) use crate::runtime;
