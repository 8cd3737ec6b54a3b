//! Build script: the commit and its date for `mbtap --version`, when the source is a git
//! checkout (`MBTAP_BUILD_COMMIT`: `commit 1a2b3c4d5e6f 2026-12-02`; without git: `no git
//! commit: built from a source archive`). Re-run when HEAD moves.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned()).filter(|s| !s.is_empty())
}

fn main() {
    let described = match (git(&["rev-parse", "--short=12", "HEAD"]), git(&["log", "-1", "--format=%cs"])) {
        (Some(commit), Some(date)) => format!("commit {commit} {date}"),
        _ => "no git commit: built from a source archive".to_owned(),
    };
    println!("cargo:rustc-env=MBTAP_BUILD_COMMIT={described}");
    if let Some(head) = git(&["rev-parse", "--git-path", "HEAD"]) {
        println!("cargo:rerun-if-changed={head}");
    }
    if let Some(refs) = git(&["rev-parse", "--git-path", "refs"]) {
        println!("cargo:rerun-if-changed={refs}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
