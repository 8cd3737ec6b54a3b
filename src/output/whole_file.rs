//! The one writer of whole files (drafts, profiles, exports, generated captures, register images,
//! man pages): the bytes go to a temporary file created exclusively in the target's directory —
//! never through a link someone planted there, never over a file already there — synced, then
//! renamed over the target. A reader sees the old file or the new one, never half of one; a
//! write that fails or is abandoned leaves the old file as it was and removes its temporary.
//! A file already at the target (or a link) is replaced only when the user said so (`--force`,
//! [`Existing::Replace`]); otherwise it is kept and the write refused, saying so — one rule for
//! every command.

use std::fs::File;
use std::io::Write;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::Context as _;

/// Temporaries made by this process so far: each name is new, whatever runs at once.
static MADE: AtomicU64 = AtomicU64::new(0);

/// What becomes of a file already at the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Existing {
    /// Kept: the write is refused, naming the file and `--force`.
    Keep,
    /// Replaced (`--force`, or a file this run wrote itself).
    Replace,
}

impl Existing {
    /// `--force` given: replace; else keep.
    #[must_use]
    pub const fn forced(force: bool) -> Self {
        if force { Self::Replace } else { Self::Keep }
    }
}

/// The refusal for a file already there.
fn kept(target: &Path) -> anyhow::Error {
    anyhow::anyhow!(
        "{} already exists: kept as it is; give --force to replace it, or write elsewhere",
        target.display()
    )
}

/// A whole file being written; [`WholeFile::commit`] puts it in place.
#[derive(Debug)]
pub struct WholeFile {
    file: File,
    tmp: PathBuf,
    target: PathBuf,
    existing: Existing,
    committed: bool,
}

impl WholeFile {
    /// Starts writing `target`.
    ///
    /// # Errors
    /// A file (or link) already at `target` under [`Existing::Keep`]; the target's directory
    /// cannot take a new file (missing, not writable), named.
    pub fn create(target: &Path, existing: Existing) -> anyhow::Result<Self> {
        if existing == Existing::Keep && target.symlink_metadata().is_ok() {
            return Err(kept(target));
        }
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = target.file_name().map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
        let tmp =
            dir.join(format!(".{name}.mbtap-{}-{}.tmp", std::process::id(), MADE.fetch_add(1, Ordering::Relaxed)));
        // `create_new` is O_CREAT | O_EXCL: it never opens what is already there, a symbolic link
        // included; O_NOFOLLOW says so once more for the final component.
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o644)
            .custom_flags(nix::fcntl::OFlag::O_NOFOLLOW.bits())
            .open(&tmp)
            .with_context(|| {
                format!(
                    "writing {}: cannot create a new file in {} (is it there and writable?)",
                    target.display(),
                    dir.display()
                )
            })?;
        Ok(Self { file, tmp, target: target.to_path_buf(), existing, committed: false })
    }

    /// Syncs the bytes and renames the temporary over the target (a link at the target is
    /// replaced, never followed).
    ///
    /// # Errors
    /// The bytes could not be synced or the rename failed, naming the target.
    pub fn commit(mut self) -> anyhow::Result<()> {
        self.file.flush().with_context(|| format!("writing {}", self.target.display()))?;
        self.file.sync_all().with_context(|| format!("writing {}", self.target.display()))?;
        match self.existing {
            Existing::Replace => {
                std::fs::rename(&self.tmp, &self.target)
                    .with_context(|| format!("writing {}", self.target.display()))?;
            }
            // A hard link is made only where nothing is: a file that appeared meanwhile is kept.
            Existing::Keep => match std::fs::hard_link(&self.tmp, &self.target) {
                Ok(()) => {
                    let _ = std::fs::remove_file(&self.tmp);
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Err(kept(&self.target)),
                Err(e) => return Err(e).with_context(|| format!("writing {}", self.target.display())),
            },
        }
        self.committed = true;
        Ok(())
    }
}

impl Write for WholeFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Drop for WholeFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Writes `bytes` as the whole of `target` through a [`WholeFile`].
///
/// # Errors
/// As [`WholeFile::create`] and [`WholeFile::commit`], and a failed write, naming the target.
pub fn write_whole(target: &Path, bytes: &[u8], existing: Existing) -> anyhow::Result<()> {
    let mut f = WholeFile::create(target, existing)?;
    f.write_all(bytes).with_context(|| format!("writing {}", target.display()))?;
    f.commit()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("mbtap-whole-file-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_link_planted_at_the_temporary_or_the_target_is_never_written_through() {
        let d = scratch("links");
        let victim = d.join("victim");
        std::fs::write(&victim, "keep").unwrap();
        // A link at every name an older writer used for its temporary, and at the target.
        std::os::unix::fs::symlink(&victim, d.join("learned-unit-1.toml.tmp")).unwrap();
        std::os::unix::fs::symlink(&victim, d.join("learned-unit-1.toml")).unwrap();
        let e = write_whole(&d.join("learned-unit-1.toml"), b"new", Existing::Keep).unwrap_err();
        assert!(format!("{e:#}").contains("--force"), "a link at the target is kept without --force: {e:#}");
        write_whole(&d.join("learned-unit-1.toml"), b"new", Existing::Replace).unwrap();
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep");
        assert_eq!(std::fs::read_to_string(d.join("learned-unit-1.toml")).unwrap(), "new");
        assert!(!d.join("learned-unit-1.toml").is_symlink(), "the link is replaced by the file");
    }

    #[test]
    fn an_abandoned_write_leaves_the_old_file_and_no_temporary() {
        let d = scratch("abandoned");
        let target = d.join("profile.toml");
        std::fs::write(&target, "old").unwrap();
        {
            let mut f = WholeFile::create(&target, Existing::Replace).unwrap();
            f.write_all(b"half").unwrap();
        }
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "only the target is left");
    }

    #[test]
    fn a_directory_that_is_not_there_is_named() {
        let e = write_whole(Path::new("/nonexistent-dir/x.toml"), b"x", Existing::Keep).unwrap_err();
        assert!(format!("{e:#}").contains("/nonexistent-dir"), "{e:#}");
    }

    #[test]
    fn a_file_already_there_is_kept_unless_replacing_was_asked_for() {
        let d = scratch("kept");
        let target = d.join("export.pcap");
        std::fs::write(&target, "old").unwrap();
        let e = write_whole(&target, b"new", Existing::Keep).unwrap_err();
        assert!(format!("{e:#}").contains("already exists") && format!("{e:#}").contains("--force"), "{e:#}");
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        // A file that appears while the new one is written is kept too.
        let late = d.join("late.pcap");
        let f = WholeFile::create(&late, Existing::Keep).unwrap();
        std::fs::write(&late, "theirs").unwrap();
        assert!(f.commit().is_err());
        assert_eq!(std::fs::read_to_string(&late).unwrap(), "theirs");
        write_whole(&target, b"new", Existing::Replace).unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 2, "no temporary left");
    }
}
