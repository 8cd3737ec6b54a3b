//! The bridge's values before it starts: the configuration file's merged under the command
//! line's, and those no bridge can run with refused, naming where each came from.

use super::Args;
use clap::ArgMatches;
use std::path::Path;

/// Values no bridge can run with are refused before it starts, naming where they came from —
/// the command line's option or the configuration file's key — and the value: a bridge that
/// accepts no connection, queues no request or times out at once fails closed, not silently.
pub(super) fn check_values(args: &Args, matches: Option<&ArgMatches>) -> anyhow::Result<()> {
    use clap::parser::ValueSource;
    let origin = |id: &str, key: &str, value: String| {
        let on_command_line = matches
            .is_some_and(|m| m.ids().any(|i| i.as_str() == id) && m.value_source(id) == Some(ValueSource::CommandLine));
        match (&args.config, on_command_line) {
            (Some(file), false) => format!("{}: {key} = {value}", file.display()),
            _ => format!("--{key} {value}"),
        }
    };
    let at_least_one = [
        ("max_connections", "max-connections", args.max_connections as u64),
        ("queue_per_client", "queue-per-client", args.queue_per_client as u64),
        ("timeout_ms", "timeout-ms", args.timeout_ms),
    ];
    for (id, key, value) in at_least_one {
        anyhow::ensure!(value > 0, "{}: expected 1 or more", origin(id, key, value.to_string()));
    }
    if let Some(rate) = args.rate_limit {
        anyhow::ensure!(
            rate.is_finite() && rate > 0.0,
            "{}: expected requests per second above 0 (leave it out for no limit)",
            origin("rate_limit", "rate-limit", rate.to_string())
        );
    }
    Ok(())
}

/// `--config FILE` under the command line ([`crate::config::merge`]): the `[bridge]` table's
/// settings as options ([`crate::bridge::config::options`]), replaced by any the command line
/// gave, parsed once into one [`Args`].
///
/// # Errors
/// The file cannot be read, or a setting is unknown or has a value its option refuses — each
/// said with the file, the key and the value.
pub(super) fn merge(path: &Path, cli: Args, matches: Option<&ArgMatches>) -> anyhow::Result<Args> {
    let mut merged: Args = crate::config::merge::under_command_line(path, matches, crate::bridge::config::options)?;
    merged.config = cli.config;
    Ok(merged)
}
