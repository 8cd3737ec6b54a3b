//! `mbtap man`: manual pages (roff) from the command definitions the parser uses
//! (clap_mangen) — `mbtap.1` and one `mbtap-COMMAND.1` per command, as `git` and `cargo` ship
//! them, written to a directory (the Debian package installs them), or one page on stdout.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;
use clap::CommandFactory as _;

/// Write the manual pages: `mbtap.1` and `mbtap-COMMAND.1` for every command.
///
/// Example: `mbtap man --dir /usr/share/man/man1`; `mbtap man bridge | man -l -`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Write every page into this directory (created if missing).
    #[arg(long, value_name = "DIR", conflicts_with = "command")]
    pub dir: Option<PathBuf>,
    /// Print this command's page on stdout (none: the top page, `mbtap.1`).
    #[arg(value_name = "COMMAND")]
    pub command: Option<String>,
}

/// Roff with its special characters escaped (a leading `.` or `'` would start a request).
fn roff(text: &str) -> String {
    let escaped = text.replace('\\', "\\e").replace('-', "\\-");
    if escaped.starts_with(['.', '\'']) { format!("\\&{escaped}") } else { escaped }
}

/// The README, whose command lines (`mbtap bridge … # what it does`) are the examples the
/// pages show beside their help's own.
const README: &str = include_str!("../../README.md");

/// The examples for the command typed as `typed` (`mbtap bridge`): its help's `` `mbtap …` ``
/// spans, then the README's lines of that command (with their comment), once each.
fn examples(cmd: &clap::Command, typed: &str) -> Vec<String> {
    let text = cmd.get_long_about().or_else(|| cmd.get_about()).map(ToString::to_string).unwrap_or_default();
    let mut out: Vec<String> = Vec::new();
    let mut add = |e: &str| {
        let key = e.split(" #").next().unwrap_or(e).trim();
        if !out.iter().any(|o| o.split(" #").next().unwrap_or(o).trim() == key) {
            out.push(e.to_owned());
        }
    };
    for span in text.split('`').skip(1).step_by(2) {
        let span = span.trim();
        if span.starts_with(&format!("{typed} ")) {
            add(span);
        }
    }
    let prefix = format!("{typed} ");
    for line in README.lines().map(str::trim).filter(|l| l.starts_with(&prefix)) {
        // `mbtap sniff … # live: …` → the command, two spaces, the comment.
        let (command, comment) = line.split_once(" # ").map_or((line, ""), |(c, m)| (c.trim(), m.trim()));
        add(&if comment.is_empty() { command.to_owned() } else { format!("{command}  # {comment}") });
    }
    out.truncate(12);
    out
}

/// The FILES section: the configuration files and directories the commands read.
const FILES: &[(&str, &str)] = &[
    (
        "$MBTAP_CONFIG, else $XDG_CONFIG_HOME/mbtap/config.toml, else ~/.config/mbtap/config.toml",
        "the configuration file: [devices] (UNIT = PROFILE) merged under every --device",
    ),
    (
        "$MBTAP_PROFILE_DIR, else $XDG_CONFIG_HOME/mbtap/profiles, else ~/.config/mbtap/profiles",
        "user profiles, NAME.toml, usable by name (profiles import writes here)",
    ),
    (
        "/etc/mbtap/bridge.toml",
        "the bridge's configuration as the Debian package's systemd unit (mbtap-bridge.service) reads it; a sample: mbtap generate-config",
    ),
];

/// One page: the title, NAME and a SYNOPSIS as typed (`mbtap bridge [OPTIONS] …`, with the
/// values options take — clap_mangen's lists every flag without its value), then
/// clap_mangen's DESCRIPTION, OPTIONS and command sections, EXAMPLES from the help, FILES, and
/// the version.
fn render(cmd: &clap::Command, typed: &str) -> anyhow::Result<Vec<u8>> {
    let man = clap_mangen::Man::new(cmd.clone());
    let mut page = Vec::new();
    man.render_title(&mut page)?;
    man.render_name_section(&mut page)?;
    let mut usage_cmd = cmd.clone().bin_name(typed);
    let usage = usage_cmd.render_usage().to_string();
    let usage = usage.trim().trim_start_matches("Usage:").trim();
    page.extend_from_slice(b".SH SYNOPSIS\n");
    for line in usage.lines() {
        page.extend_from_slice(format!("{}\n.br\n", roff(line.trim())).as_bytes());
    }
    man.render_description_section(&mut page)?;
    if cmd.get_arguments().any(|a| !a.is_hide_set()) {
        man.render_options_section(&mut page)?;
    }
    if cmd.has_subcommands() {
        man.render_subcommands_section(&mut page)?;
    }
    let examples = examples(cmd, typed);
    if !examples.is_empty() {
        page.extend_from_slice(b".SH EXAMPLES\n");
        for e in examples {
            page.extend_from_slice(format!(".PP\n.nf\n{}\n.fi\n", roff(&e)).as_bytes());
        }
    }
    page.extend_from_slice(b".SH FILES\n");
    for (path, what) in FILES {
        page.extend_from_slice(format!(".TP\n{}\n{}\n", roff(path), roff(what)).as_bytes());
    }
    man.render_version_section(&mut page)?;
    Ok(page)
}

/// Every page: (file name, roff). No `help` command has a page (`mbtap(1)` named an
/// `mbtap-help(1)` that does not exist).
fn pages() -> anyhow::Result<Vec<(String, Vec<u8>)>> {
    let top = super::Cli::command().version(super::long_version()).disable_help_subcommand(true);
    let mut out = vec![("mbtap.1".to_owned(), render(&top, "mbtap").context("rendering mbtap.1")?)];
    for sub in top.get_subcommands() {
        let name = format!("mbtap-{}", sub.get_name());
        // The page's title is the command as typed (`mbtap-bridge`), as `man mbtap-bridge` finds it.
        let typed = format!("mbtap {}", sub.get_name());
        let sub = sub.clone().name(name.clone()).version(super::long_version());
        out.push((format!("{name}.1"), render(&sub, &typed).with_context(|| format!("rendering {name}.1"))?));
    }
    Ok(out)
}

fn write_all(dir: &Path) -> anyhow::Result<usize> {
    std::fs::create_dir_all(dir).with_context(|| format!("--dir {}: cannot create it", dir.display()))?;
    let pages = pages()?;
    for (name, page) in &pages {
        let path = dir.join(name);
        // The pages are this command's own, in the directory given: made again, they replace.
        crate::output::whole_file::write_whole(&path, page, crate::output::whole_file::Existing::Replace)?;
    }
    Ok(pages.len())
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    if let Some(dir) = &args.dir {
        let n = write_all(dir)?;
        eprintln!("mbtap: {n} manual pages written to {}", dir.display());
        return Ok(ExitCode::SUCCESS);
    }
    let wanted = args.command.as_deref().map_or_else(|| "mbtap.1".to_owned(), |c| format!("mbtap-{c}.1"));
    let pages = pages()?;
    let Some((_, page)) = pages.iter().find(|(n, _)| *n == wanted) else {
        let known: Vec<&str> = pages.iter().filter_map(|(n, _)| n.strip_prefix("mbtap-")?.strip_suffix(".1")).collect();
        anyhow::bail!(
            "no command {:?}; the commands are {}",
            args.command.as_deref().unwrap_or_default(),
            known.join(", ")
        );
    };
    match std::io::stdout().lock().write_all(page) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e).context("writing the page"),
        _ => Ok(ExitCode::SUCCESS),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each page's SYNOPSIS names the command as typed (`mbtap bridge`, not `mbtap-bridge`) with
    /// its options' values, every page has EXAMPLES and FILES, and `mbtap(1)` names no
    /// `mbtap-help(1)` (there is none).
    #[test]
    fn pages_have_a_typed_synopsis_examples_and_files_and_no_help_page() {
        let pages = pages().unwrap();
        let page = |n: &str| String::from_utf8(pages.iter().find(|(p, _)| p == n).unwrap().1.clone()).unwrap();
        let bridge = page("mbtap-bridge.1");
        assert!(bridge.contains(".SH SYNOPSIS\nmbtap bridge [OPTIONS]"), "{bridge}");
        assert!(bridge.contains(".SH EXAMPLES") && bridge.contains("mbtap bridge \\-\\-serial"), "{bridge}");
        assert!(bridge.contains(".SH FILES") && bridge.contains("/etc/mbtap/bridge.toml"), "{bridge}");
        assert!(pages.iter().all(|(n, _)| n != "mbtap-help.1"));
        assert!(!page("mbtap.1").contains("mbtap\\-help"), "{}", page("mbtap.1"));
    }
}
