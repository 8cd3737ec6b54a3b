//! A command's `--config FILE` under its command line, merged *before* parsing: the file's
//! settings (as options) and the command line's options as given make one argument list, from
//! which clap builds one typed argument struct — every value checked once, by the same parsers.
//! An option the command line gave replaces the file's setting of it, lists included (a
//! `--allow-ip` on the command line replaces the file's list, it does not add to it); every
//! other option takes the file's value, else its default. No option has to be listed anywhere:
//! a new one is merged as it is declared. Any command whose options are a `clap::Args` struct
//! can use it (today `bridge`).

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::path::Path;

use anyhow::Context;
use clap::parser::ValueSource;
use clap::{ArgMatches, FromArgMatches};

/// The long names of `A`'s options a configuration file may set (all but `config`).
#[must_use]
pub fn known_keys<A: clap::Args>() -> Vec<String> {
    let command = A::augment_args(clap::Command::new("command"));
    command.get_arguments().filter_map(|a| a.get_long().map(str::to_owned)).filter(|l| l != "config").collect()
}

/// The file at `path`, turned into options by `to_options` (its text and the known keys),
/// under the options the command line gave (`matches`; none when `None`): one parse of both.
///
/// # Errors
/// The file cannot be read, or a setting is unknown or has a value its option refuses — each
/// said with the file, the key and the value.
pub fn under_command_line<A, F>(path: &Path, matches: Option<&ArgMatches>, to_options: F) -> anyhow::Result<A>
where
    A: clap::Args + FromArgMatches,
    F: FnOnce(&str, &[String]) -> Result<Vec<String>, String>,
{
    let shown = path.display();
    let text = std::fs::read_to_string(path).with_context(|| format!("reading the configuration {shown}"))?;
    let options = to_options(&text, &known_keys::<A>()).map_err(|e| anyhow::anyhow!("{shown}: {e}"))?;
    let command = A::augment_args(clap::Command::new("command").no_binary_name(true));
    let (given, from_cli) = matches.map_or_else(Default::default, |m| command_line_options(&command, m));
    let from_file = options.into_iter().map(OsString::from).filter(|o| {
        let key = o.to_str().and_then(|o| o.strip_prefix("--")).map(|k| k.split_once('=').map_or(k, |(k, _)| k));
        !key.is_some_and(|k| given.contains(k))
    });
    let argv: Vec<OsString> = from_file.chain(from_cli).collect();
    let parsed = command.try_get_matches_from(&argv).map_err(|e| {
        let message = e.to_string();
        let first = message.lines().next().unwrap_or("").trim_start_matches("error: ");
        anyhow::anyhow!("{shown}: {first}")
    })?;
    A::from_arg_matches(&parsed).map_err(|e| anyhow::anyhow!("{shown}: {e}"))
}

/// The options the command line gave (`matches`), as `--long=VALUE` (or `--long` for a flag)
/// in the order declared, and their long names. Options only: a command merged this way takes
/// no positional arguments, and every option is a flag or takes values (the bridge's
/// `every_option_can_be_given_again` test).
fn command_line_options(command: &clap::Command, m: &ArgMatches) -> (BTreeSet<String>, Vec<OsString>) {
    let (mut given, mut argv) = (BTreeSet::new(), Vec::new());
    for arg in command.get_arguments() {
        let id = arg.get_id().as_str();
        let (Some(long), true) = (arg.get_long(), m.value_source(id) == Some(ValueSource::CommandLine)) else {
            continue;
        };
        given.insert(long.to_owned());
        if arg.get_action().takes_values() {
            for value in m.get_raw_occurrences(id).into_iter().flatten().flatten() {
                let mut option = OsString::from(format!("--{long}="));
                option.push(value);
                argv.push(option);
            }
        } else {
            argv.push(OsString::from(format!("--{long}")));
        }
    }
    (given, argv)
}
