//! Files: training configurations ([`config`]), policy files ([`policy_file`]), checkpoints
//! of training runs ([`checkpoint`]), logged transitions ([`transitions`]), and the atomic
//! writing every output of fuzzyq goes through.

pub mod checkpoint;
pub mod config;
mod container;
pub mod export;
pub mod policy_file;
pub mod transitions;

use std::io::Write;
use std::path::Path;
use std::time::{Duration, SystemTime};

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so
/// the destination holds either its old content or all of the new.
///
/// Stale temporaries of earlier killed writers in that directory are removed first
/// ([`remove_stale`]). An error names what went wrong in words, not the temporary file's
/// random name (the caller names `path`).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomically_with(path, |f| f.write_all(bytes))
}

/// [`write_atomically`] of what `write` writes into the temporary file (from its start), so
/// that a large file is written as it is encoded.
pub fn write_atomically_with(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = dir_of(path);
    let mut tmp = temp_file_beside(path, ".tmp").map_err(|e| {
        let why = if dir.is_dir() {
            format!(
                "cannot create a file in {} ({})",
                dir.display(),
                std::io::Error::from(e.kind())
            )
        } else {
            format!("the directory {} does not exist", dir.display())
        };
        std::io::Error::new(e.kind(), why)
    })?;
    remove_stale(dir, owner_of(tmp.path()));
    write(tmp.as_file_mut())?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// The directory `path` is in (`.` for a bare file name).
#[must_use]
pub fn dir_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// A temporary file in `path`'s directory (so that a rename onto `path` is atomic), named with
/// `suffix`, readable like a freshly created file (mode 0644 on Unix rather than the 0600 of
/// temporary files). Dropped without `persist`, it is removed.
pub fn temp_file_beside(path: &Path, suffix: &str) -> std::io::Result<tempfile::NamedTempFile> {
    let dir = dir_of(path);
    let mut b = tempfile::Builder::new();
    b.prefix(".fuzzyq-").suffix(suffix);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(0o644));
    }
    b.tempfile_in(dir)
}

/// Temporaries older than this are stale: no run of fuzzyq keeps one open that long.
pub const STALE_AFTER: Duration = Duration::from_secs(3600);

/// The user owning `path` (`None` where the platform has no such notion).
#[cfg(unix)]
#[must_use]
pub fn owner_of(path: &Path) -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| m.uid())
}

/// The user owning `path` (`None` where the platform has no such notion).
#[cfg(not(unix))]
#[must_use]
pub fn owner_of(_path: &Path) -> Option<u32> {
    None
}

/// Removes from `dir` the temporaries of earlier killed runs (best effort): regular files
/// named `.fuzzyq-*`, of `owner`, untouched for [`STALE_AFTER`] (no run keeps one that long,
/// so a live run's files stay).
pub fn remove_stale(dir: &Path, owner: Option<u32>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let now = SystemTime::now();
    for entry in entries.flatten() {
        let name = entry.file_name();
        if !name.to_string_lossy().starts_with(".fuzzyq-") {
            continue;
        }
        // `symlink_metadata`: a link is not ours to remove.
        let Ok(m) = std::fs::symlink_metadata(entry.path()) else {
            continue;
        };
        let old = m
            .modified()
            .ok()
            .and_then(|t| now.duration_since(t).ok())
            .is_some_and(|age| age > STALE_AFTER);
        if m.is_file() && old && owner.is_some() && owner_of(&entry.path()) == owner {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression (issue 49): a writer killed mid-write (SIGKILL during a checkpoint) left a
    /// `.fuzzyq-*.tmp` that later writes never removed; and a write into a missing directory
    /// named the temporary file instead of what was wrong.
    #[test]
    fn writes_remove_stale_temporaries_and_name_a_missing_directory() {
        let dir = tempfile::tempdir().unwrap();
        let stale = dir.path().join(".fuzzyq-killed.tmp");
        let fresh = dir.path().join(".fuzzyq-live.tmp");
        for p in [&stale, &fresh] {
            std::fs::write(p, b"partial").unwrap();
        }
        let old = SystemTime::now() - STALE_AFTER - Duration::from_secs(60);
        std::fs::File::options()
            .write(true)
            .open(&stale)
            .unwrap()
            .set_modified(old)
            .unwrap();
        write_atomically(&dir.path().join("run.ckpt"), b"state").unwrap();
        assert!(!stale.exists(), "the stale temporary was removed");
        assert!(fresh.exists(), "a recent one may be a live writer's");
        assert_eq!(
            std::fs::read(dir.path().join("run.ckpt")).unwrap(),
            b"state"
        );

        let missing = dir.path().join("no/such/dir/x.fzq");
        let e = write_atomically(&missing, b"x").unwrap_err().to_string();
        assert!(
            e.contains("does not exist") && !e.contains(".fuzzyq-"),
            "{e}"
        );
    }
}
