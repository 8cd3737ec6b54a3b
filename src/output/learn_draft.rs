//! Draft profiles written while listening (`sniff --learn DRAFT.toml`, also `tap`, `replay`,
//! `demo`) and by `mbtap learn -o FILE` (one unit's profile: a profile describes one device)
//! or `--dir DIR` (one `learned-unit-N.toml` per unit). While listening the drafts are rewritten every [`EVERY_NS`] of line
//! time and at the end, each write atomic (a temporary file renamed), so a reader never sees
//! half a draft.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use mbtap_analysis::analyzer::{Event, Sink as _};
use mbtap_analysis::learn::Learner;

/// How often the drafts are rewritten while listening, in line time.
pub const EVERY_NS: u64 = 10_000_000_000;

/// Where drafts go: one file holding one unit's profile (`-o`), or a directory holding one
/// `learned-unit-N.toml` per unit (`learn --dir`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DraftTo {
    File(PathBuf),
    Dir(PathBuf),
}

impl DraftTo {
    /// The file for `unit`.
    #[must_use]
    pub fn file_for(&self, unit: u8) -> PathBuf {
        match self {
            Self::File(path) => path.clone(),
            Self::Dir(dir) => dir.join(format!("learned-unit-{unit}.toml")),
        }
    }
}

/// Why `-o FILE` cannot hold the drafts of several units (it wrote
/// `NAME-unit-N.toml` files nobody asked for instead).
fn one_file_for_many(path: &Path, units: &[u8]) -> String {
    let shown: Vec<String> = units.iter().map(u8::to_string).collect();
    format!(
        "{}: a profile describes one device, and {} units were heard ({}); give --unit N for one of them, \
         or --dir DIR for a profile per unit (DIR/learned-unit-N.toml)",
        path.display(),
        units.len(),
        shown.join(", ")
    )
}

/// Which existing files a draft may replace: with `--force` any; otherwise only those this run
/// wrote itself (a live draft rewrites its own file every 10 s), never one that was there before
/// — as `profiles import` keeps an existing profile.
#[derive(Debug, Clone, Default)]
pub struct Replace {
    pub force: bool,
    mine: std::collections::BTreeSet<PathBuf>,
}

impl Replace {
    #[must_use]
    pub fn new(force: bool) -> Self {
        Self { force, mine: std::collections::BTreeSet::new() }
    }
}

/// Writes one file atomically, through the one writer of whole files (no planted link is
/// followed); a file that was there before is replaced only under `--force`.
fn write_atomic(file: &Path, text: &str, replace: &mut Replace) -> anyhow::Result<()> {
    // A draft this run wrote before is its own to replace as the learner learns more.
    let existing = super::whole_file::Existing::forced(replace.force || replace.mine.contains(file));
    super::whole_file::write_whole(file, text.as_bytes(), existing)?;
    replace.mine.insert(file.to_path_buf());
    Ok(())
}

/// Writes the drafts of `learner` to `to`; the files written.
///
/// # Errors
/// Several units heard and one file asked for (said, with what to do instead); a file or the
/// directory that could not be written, named.
pub fn write_drafts(
    learner: &Learner,
    to: &DraftTo,
    source: &str,
    hints: &[mbtap_analysis::learn::hint::Hint],
    replace: &mut Replace,
) -> anyhow::Result<Vec<(u8, PathBuf)>> {
    match to {
        DraftTo::File(path) if learner.units.len() > 1 => {
            let units: Vec<u8> = learner.units.keys().copied().collect();
            anyhow::bail!("{}", one_file_for_many(path, &units))
        }
        DraftTo::Dir(dir) => std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?,
        DraftTo::File(_) => {}
    }
    let mut written = Vec::new();
    for (unit, u) in &learner.units {
        let file = to.file_for(*unit);
        write_atomic(&file, &mbtap_analysis::learn::draft::profile_toml(*unit, u, source, hints), replace)?;
        written.push((*unit, file));
    }
    Ok(written)
}

/// A learner fed while listening, its drafts kept up to date.
#[derive(Debug)]
pub struct LiveDraft {
    pub learner: Learner,
    /// Where the drafts go; `None`: kept in memory only (`mbtap learn PORT` without `-o`).
    pub to: Option<DraftTo>,
    pub source: String,
    last_write_ns: Option<u64>,
    /// One file asked for and a second unit heard: that file keeps the first unit's draft,
    /// and the others are said once at the end (a listening session is not ended for it).
    pub left_out: Vec<u8>,
    /// Which existing files may be replaced (`--force`; its own, rewritten, always).
    pub replace: Replace,
}

impl LiveDraft {
    #[must_use]
    pub fn new(to: Option<DraftTo>, source: String) -> Self {
        Self {
            learner: Learner::default(),
            to,
            source,
            last_write_ns: None,
            left_out: Vec::new(),
            replace: Replace::default(),
        }
    }

    fn write(&mut self) -> anyhow::Result<Vec<(u8, PathBuf)>> {
        let Some(to) = &self.to else { return Ok(Vec::new()) };
        if let DraftTo::File(path) = to
            && let Some((&first, u)) = self.learner.units.iter().next()
        {
            self.left_out = self.learner.units.keys().copied().filter(|&k| k != first).collect();
            write_atomic(
                path,
                &mbtap_analysis::learn::draft::profile_toml(first, u, &self.source, &[]),
                &mut self.replace,
            )?;
            return Ok(vec![(first, path.clone())]);
        }
        write_drafts(&self.learner, to, &self.source, &[], &mut self.replace)
    }

    /// What to say of the units heard but not written (one file asked for), if any.
    #[must_use]
    pub fn left_out_note(&self) -> Option<String> {
        let Some(DraftTo::File(path)) = &self.to else { return None };
        let first = self.learner.units.keys().next()?;
        (!self.left_out.is_empty()).then(|| {
            let shown: Vec<String> = self.left_out.iter().map(u8::to_string).collect();
            format!(
                "{}: the draft of unit {first} only (a profile describes one device); units {} were heard too \
                 and not drafted — `mbtap learn --dir DIR` drafts one profile per unit",
                path.display(),
                shown.join(", ")
            )
        })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A read of holding register 0 (MAP v1.1b3 §6.3: 03, address 0000, quantity 0001) and its
    /// answer (03, byte count 02, value 0007).
    const READ: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x01];
    const ANSWER: [u8; 4] = [0x03, 0x02, 0x00, 0x07];

    /// `-o FILE` with several units wrote `NAME-unit-N.toml` files instead of the file
    /// named. Once: refused, saying what to do; while listening: the file holds the first unit's
    /// draft and the others are said at the end; a directory holds one per unit.
    #[test]
    fn one_file_holds_one_unit_and_a_directory_holds_each() {
        let dir = std::env::temp_dir().join(format!("mbtap-drafts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut l = Learner::default();
        l.observe(1, &READ, &ANSWER, 0);
        l.observe(5, &READ, &ANSWER, 1);
        let file = dir.join("meter.toml");
        let e = write_drafts(&l, &DraftTo::File(file.clone()), "test", &[], &mut Replace::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 units were heard (1, 5)") && e.contains("--unit N") && e.contains("--dir DIR"), "{e}");
        assert!(!file.exists());
        let written = write_drafts(&l, &DraftTo::Dir(dir.join("d")), "test", &[], &mut Replace::default()).unwrap();
        assert_eq!(written.iter().map(|(u, _)| *u).collect::<Vec<_>>(), [1, 5]);
        assert!(dir.join("d/learned-unit-5.toml").exists());
        let mut live = LiveDraft::new(Some(DraftTo::File(file.clone())), "test".into());
        live.learner = l;
        assert_eq!(live.finish().unwrap(), [(1, file.clone())]);
        let note = live.left_out_note().unwrap();
        assert!(note.contains("unit 1 only") && note.contains("units 5 were heard too"), "{note}");
        // Its own file is rewritten at every turn; a file that was there before this run is kept
        // unless --force.
        assert_eq!(live.finish().unwrap(), [(1, file.clone())], "its own draft, rewritten");
        let e = write_drafts(&live.learner, &DraftTo::Dir(dir.join("d")), "test", &[], &mut Replace::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("already exists") && e.contains("--force"), "{e}");
        assert!(
            write_drafts(&live.learner, &DraftTo::Dir(dir.join("d")), "test", &[], &mut Replace::new(true)).is_ok()
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
