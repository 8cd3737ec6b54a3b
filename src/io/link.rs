//! The path a program opens to reach our pseudo-terminal (`simulate --link`, `tap --link`): a
//! symbolic link we make, and only ever replace or remove when it is one of ours.

use std::path::Path;

use anyhow::Context;

/// Where pseudo-terminals live on Linux (`/dev/pts/N`).
const PTY_DIR: &str = "/dev/pts/";

/// Points `link` at the pseudo-terminal `pty`. What a previous run left — a symbolic link to a
/// pseudo-terminal — is replaced; anything else at the path (a regular file, a serial device, a
/// directory, a link elsewhere) is refused, naming it: the path may be the user's data or their
/// real port, and deleting it is not ours to do.
///
/// # Errors
/// Something else is at `link`, or the link cannot be made.
pub fn make(link: &Path, pty: &str) -> anyhow::Result<()> {
    match std::fs::symlink_metadata(link) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(e).with_context(|| format!("looking at {}", link.display())),
        Ok(meta) => {
            let ours = meta.file_type().is_symlink()
                && std::fs::read_link(link).is_ok_and(|t| t.to_string_lossy().starts_with(PTY_DIR));
            anyhow::ensure!(
                ours,
                "{} already exists and is not a link to a pseudo-terminal that mbtap made: not replacing it (choose another --link, or remove it yourself)",
                link.display()
            );
            std::fs::remove_file(link).with_context(|| format!("replacing the old link {}", link.display()))?;
        }
    }
    std::os::unix::fs::symlink(pty, link).with_context(|| format!("creating the link {} -> {pty}", link.display()))
}

/// Removes `link` if it still points at `pty` (someone may have replaced it meanwhile).
pub fn remove(link: &Path, pty: &str) {
    if std::fs::read_link(link).is_ok_and(|t| t.as_os_str() == pty) {
        let _ = std::fs::remove_file(link);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("mbtap-link-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{e}"));
        d
    }

    /// `simulate --link` and `tap --link` replace only a link of their own: a user's file at the
    /// path is refused and left as it is.
    #[test]
    fn a_regular_file_at_the_link_is_refused_and_kept() {
        let d = dir("file");
        let f = d.join("precious.txt");
        std::fs::write(&f, "data").unwrap_or_else(|e| panic!("{e}"));
        let e = make(&f, "/dev/pts/999").unwrap_err().to_string();
        assert!(e.contains("precious.txt") && e.contains("not replacing"), "{e}");
        assert_eq!(std::fs::read_to_string(&f).unwrap_or_default(), "data");
    }

    #[test]
    fn a_link_elsewhere_is_refused_and_our_old_link_is_replaced() {
        let d = dir("links");
        let elsewhere = d.join("to-tty");
        let _ = std::fs::remove_file(&elsewhere);
        std::os::unix::fs::symlink("/dev/ttyS0", &elsewhere).unwrap_or_else(|e| panic!("{e}"));
        assert!(make(&elsewhere, "/dev/pts/999").is_err());
        assert_eq!(std::fs::read_link(&elsewhere).unwrap_or_default(), Path::new("/dev/ttyS0"));
        let ours = d.join("bus");
        let _ = std::fs::remove_file(&ours);
        std::os::unix::fs::symlink("/dev/pts/998", &ours).unwrap_or_else(|e| panic!("{e}"));
        make(&ours, "/dev/pts/999").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(std::fs::read_link(&ours).unwrap_or_default(), Path::new("/dev/pts/999"));
        remove(&ours, "/dev/pts/1");
        assert!(std::fs::symlink_metadata(&ours).is_ok(), "not ours any more: kept");
        remove(&ours, "/dev/pts/999");
        assert!(std::fs::symlink_metadata(&ours).is_err());
    }
}
