//! Draft profiles written while listening (`sniff --learn DRAFT.toml`, also `tap`, `replay`,
//! `demo`) and by `mbtap learn -o`: one file for one unit heard, `NAME-unit-N.toml` beside it
//! per unit for several. While listening the drafts are rewritten every [`EVERY_NS`] of line
//! time and at the end, each write atomic (a temporary file renamed), so a reader never sees
//! half a draft.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use mbtap_core::analyzer::{Event, Sink as _};
use mbtap_core::learn::Learner;

/// How often the drafts are rewritten while listening, in line time.
pub const EVERY_NS: u64 = 10_000_000_000;

/// The file for `unit` when `many` units were heard.
#[must_use]
pub fn file_for(path: &Path, unit: u8, many: bool) -> PathBuf {
    if many {
        let stem = path.file_stem().map_or_else(|| "draft".into(), |s| s.to_string_lossy().into_owned());
        path.with_file_name(format!("{stem}-unit-{unit}.toml"))
    } else {
        path.to_path_buf()
    }
}

/// Writes a draft per unit of `learner` for `path`; the files written.
///
/// # Errors
/// A file that could not be written, named.
pub fn write_drafts(
    learner: &Learner,
    path: &Path,
    source: &str,
    hints: &[mbtap_core::learn::hint::Hint],
) -> anyhow::Result<Vec<(u8, PathBuf)>> {
    let many = learner.units.len() > 1;
    let mut written = Vec::new();
    for (unit, u) in &learner.units {
        let file = file_for(path, *unit, many);
        let tmp = file.with_extension("toml.tmp");
        std::fs::write(&tmp, mbtap_core::learn::draft::profile_toml(*unit, u, source, hints))
            .with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, &file).with_context(|| format!("writing {}", file.display()))?;
        written.push((*unit, file));
    }
    Ok(written)
}

/// A learner fed while listening, its drafts kept up to date.
#[derive(Debug)]
pub struct LiveDraft {
    pub learner: Learner,
    /// Where the drafts go; `None`: kept in memory only (`mbtap learn PORT` without `-o`).
    pub path: Option<PathBuf>,
    pub source: String,
    last_write_ns: Option<u64>,
    /// The drafts so far went to `path` itself (one unit heard): when a second unit is heard,
    /// that file gives way to one per unit.
    wrote_single: bool,
}

impl LiveDraft {
    #[must_use]
    pub fn new(path: Option<PathBuf>, source: String) -> Self {
        Self { learner: Learner::default(), path, source, last_write_ns: None, wrote_single: false }
    }

    fn write(&mut self) -> anyhow::Result<Vec<(u8, PathBuf)>> {
        let Some(path) = &self.path else { return Ok(Vec::new()) };
        let written = write_drafts(&self.learner, path, &self.source, &[])?;
        let single = written.len() == 1;
        if !single && self.wrote_single {
            std::fs::remove_file(path).with_context(|| format!("removing {}", path.display()))?;
        }
        self.wrote_single = single;
        Ok(written)
    }

    /// Takes an event (at line time `t_ns`); rewrites the drafts when they are due.
    ///
    /// # Errors
    /// A draft that could not be written.
    pub fn event(&mut self, e: &Event<'_>, t_ns: u64) -> anyhow::Result<()> {
        self.learner.event(e);
        let due = self.last_write_ns.is_none_or(|last| t_ns.saturating_sub(last) >= EVERY_NS);
        if due && !self.learner.units.is_empty() {
            self.last_write_ns = Some(t_ns);
            self.write()?;
        }
        Ok(())
    }

    /// The final drafts.
    ///
    /// # Errors
    /// A draft that could not be written.
    pub fn finish(&mut self) -> anyhow::Result<Vec<(u8, PathBuf)>> {
        self.write()
    }
}
