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

/// Every page: (file name, roff).
fn pages() -> anyhow::Result<Vec<(String, Vec<u8>)>> {
    let top = super::Cli::command().version(super::long_version());
    let mut out = Vec::new();
    let mut page = Vec::new();
    clap_mangen::Man::new(top.clone()).render(&mut page).context("rendering mbtap.1")?;
    out.push(("mbtap.1".to_owned(), page));
    for sub in top.get_subcommands() {
        let name = format!("mbtap-{}", sub.get_name());
        // The page's title is the command as typed (`mbtap-bridge`), as `man mbtap-bridge` finds it.
        let sub = sub.clone().name(name.clone()).version(super::long_version());
        let mut page = Vec::new();
        clap_mangen::Man::new(sub).render(&mut page).with_context(|| format!("rendering {name}.1"))?;
        out.push((format!("{name}.1"), page));
    }
    Ok(out)
}

fn write_all(dir: &Path) -> anyhow::Result<usize> {
    std::fs::create_dir_all(dir).with_context(|| format!("--dir {}: cannot create it", dir.display()))?;
    let pages = pages()?;
    for (name, page) in &pages {
        let path = dir.join(name);
        std::fs::write(&path, page).with_context(|| format!("writing {}", path.display()))?;
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
