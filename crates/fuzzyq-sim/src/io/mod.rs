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

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so
/// the destination holds either its old content or all of the new.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp = temp_file_beside(path, ".tmp")?;
    tmp.write_all(bytes)?;
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
