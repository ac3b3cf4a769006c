//! A command's output files, written as one transaction.
//!
//! Every command first [`plan`]s all its outputs with its inputs. Planning refuses an output
//! that names a directory, sits in a missing or read-only directory, is neither a regular file
//! nor a character device or FIFO, names the same file as another output, or names one of the
//! command's inputs (paths compared after resolving links, and existing files also by their
//! device and inode, so hard links count too). Planning also removes stale temporaries of
//! earlier killed runs from the output directories: only files named `.fuzzyq-*`, regular,
//! owned by the user, and untouched for an hour.
//!
//! The command then [`stage`]s each output. The output is written in full to a temporary file
//! beside its destination, and nothing is replaced yet. When the command has succeeded, `main`
//! [`commit`]s: the temporaries are renamed into place one after the other. On failure `main`
//! [`discard`]s them, so a failed command replaces no file. A link to a regular file keeps its
//! link: the file it points to is replaced. Character devices and FIFOs (`/dev/null`,
//! `/dev/stdout`, a pipe) are never replaced: their content is written to them at commit.

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use fuzzyq_sim::io::dir_of;

/// Where a planned output goes.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Target {
    /// A regular file, new or replaced by a rename (links resolved).
    Regular(PathBuf),
    /// A character device or FIFO, written to in place.
    Special(PathBuf),
}

#[derive(Debug)]
struct Planned {
    given: PathBuf,
    flag: String,
    target: Target,
    /// The existing file's device and inode.
    id: Option<FileId>,
}

#[derive(Debug)]
struct Staged {
    target: Target,
    flag: String,
    given: PathBuf,
    tmp: tempfile::TempPath,
}

#[derive(Debug, Default)]
struct Transaction {
    planned: Vec<Planned>,
    staged: Vec<Staged>,
}

thread_local! {
    /// The command's transaction. A command plans, stages and commits on its main thread (its
    /// workers compute, they write nothing), so one per thread is one per command; tests on
    /// separate threads stay apart.
    static TRANSACTION: RefCell<Transaction> = RefCell::default();
}

fn with<R>(f: impl FnOnce(&mut Transaction) -> R) -> R {
    TRANSACTION.with(|t| f(&mut t.borrow_mut()))
}

/// A file's device and inode.
type FileId = (u64, u64);

/// The file identity of an existing path (links followed).
#[cfg(unix)]
fn identity(path: &Path) -> Option<FileId> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn identity(_path: &Path) -> Option<FileId> {
    None
}

/// The absolute location `path` names, links resolved; for a file that does not exist yet, its
/// resolved directory joined with its name.
fn location(path: &Path) -> std::io::Result<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Ok(p);
    }
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "no file name"))?;
    Ok(std::fs::canonicalize(dir_of(path))?.join(name))
}

fn target_of(path: &Path, flag: &str) -> anyhow::Result<Target> {
    let shown = path.display();
    if path.as_os_str().is_empty() {
        bail!("{flag}: the path is empty");
    }
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => bail!("{flag} {shown} is a directory"),
        Ok(m) if m.is_file() => Ok(Target::Regular(location(path)?)),
        Ok(m) => {
            if is_device_or_fifo(&m) {
                Ok(Target::Special(path.to_path_buf()))
            } else {
                bail!("{flag} {shown} is not a regular file, a character device or a FIFO")
            }
        }
        Err(_) => {
            let dir = dir_of(path);
            if !dir.is_dir() {
                bail!("{flag} {shown}: directory {} does not exist", dir.display());
            }
            if path.file_name().is_none() {
                bail!("{flag} {shown} names no file");
            }
            Ok(Target::Regular(location(path).with_context(|| {
                format!("{flag} {shown}: cannot resolve its directory")
            })?))
        }
    }
}

#[cfg(unix)]
fn is_device_or_fifo(m: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::FileTypeExt;
    m.file_type().is_char_device() || m.file_type().is_fifo()
}

#[cfg(not(unix))]
fn is_device_or_fifo(_m: &std::fs::Metadata) -> bool {
    false
}

/// Checks that `dir` accepts new files (nothing is left behind) and removes its stale
/// temporaries.
fn prepare_dir(dir: &Path, flag: &str, given: &Path) -> anyhow::Result<()> {
    let probe = tempfile::Builder::new()
        .prefix(".fuzzyq-probe-")
        .tempfile_in(dir)
        .with_context(|| format!("{flag} {}: cannot write there", given.display()))?;
    let owner = fuzzyq_sim::io::owner_of(probe.path());
    drop(probe);
    fuzzyq_sim::io::remove_stale(dir, owner);
    Ok(())
}

/// Plans the command's outputs (`(path, flag)`, the absent ones skipped) against its inputs
/// (the same), before any long work: see the [module docs](self) for what is refused.
pub(crate) fn plan(
    outputs: &[(Option<&Path>, &str)],
    inputs: &[(Option<&Path>, &str)],
) -> anyhow::Result<()> {
    let inputs: Vec<(PathBuf, Option<FileId>, &str)> = inputs
        .iter()
        .filter_map(|(p, flag)| p.map(|p| (p, *flag)))
        .map(|(p, flag)| {
            let loc = location(p).unwrap_or_else(|_| p.to_path_buf());
            (loc, identity(p), flag)
        })
        .collect();
    let mut planned: Vec<Planned> = Vec::new();
    let mut prepared: Vec<PathBuf> = Vec::new();
    for (path, flag) in outputs {
        let Some(path) = path else { continue };
        let target = target_of(path, flag)?;
        let shown = path.display();
        let id = identity(path);
        for (loc, input_id, input_flag) in &inputs {
            let same_id = id.is_some() && id == *input_id;
            if same_id || matches!(&target, Target::Regular(t) if t == loc) {
                bail!("{flag} {shown} would overwrite the {input_flag} input; name another file");
            }
        }
        for other in &planned {
            let same_id = id.is_some() && id == other.id;
            if same_id || other.target == target {
                bail!(
                    "{flag} {shown} and {} {} name the same file; give each output its own",
                    other.flag,
                    other.given.display()
                );
            }
        }
        if let Target::Regular(t) = &target {
            let dir = dir_of(t);
            if !prepared.iter().any(|p| p == dir) {
                prepare_dir(dir, flag, path)?;
                prepared.push(dir.to_path_buf());
            }
        }
        planned.push(Planned {
            given: path.to_path_buf(),
            flag: (*flag).to_string(),
            target,
            id,
        });
    }
    with(|t| t.planned.extend(planned));
    Ok(())
}

/// Stages the output `path` (planned): `write` writes its whole content into the temporary
/// path it is given (which keeps `path`'s extension); the output replaces `path` at [`commit`].
pub(crate) fn stage(
    path: &Path,
    write: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let planned = with(|t| {
        t.planned
            .iter()
            .find(|p| p.given == path)
            .map(|p| (p.target.clone(), p.flag.clone()))
    });
    let (target, flag) = match planned {
        Some(p) => p,
        None => (target_of(path, "output")?, "output".to_string()),
    };
    let suffix = match path.extension() {
        Some(e) => format!(".{}", e.to_string_lossy()),
        None => ".tmp".into(),
    };
    let tmp = match &target {
        Target::Regular(t) => fuzzyq_sim::io::temp_file_beside(t, &suffix),
        Target::Special(_) => tempfile::Builder::new()
            .prefix(".fuzzyq-")
            .suffix(&suffix)
            .tempfile(),
    }
    .with_context(|| format!("cannot write {flag} {}", path.display()))?
    .into_temp_path();
    write(&tmp)?;
    with(|t| {
        t.staged.push(Staged {
            target,
            flag,
            given: path.to_path_buf(),
            tmp,
        });
    });
    Ok(())
}

/// Stages `bytes` as the content of the output `path` ([`stage`]).
pub(crate) fn stage_bytes(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    stage(path, |tmp| {
        use std::io::Write;
        let mut f = std::fs::File::create(tmp)?;
        f.write_all(bytes)?;
        Ok(())
    })
}

/// Puts every staged output in place, in the order staged.
pub(crate) fn commit() -> anyhow::Result<()> {
    let staged = with(|t| {
        t.planned.clear();
        std::mem::take(&mut t.staged)
    });
    for s in staged {
        let shown = s.given.display();
        match &s.target {
            Target::Regular(t) => {
                std::fs::File::open(&s.tmp)
                    .and_then(|f| f.sync_all())
                    .and_then(|()| s.tmp.persist(t).map_err(|e| e.error))
                    .with_context(|| format!("cannot write {} {shown}", s.flag))?;
            }
            Target::Special(p) => {
                let copy = || -> std::io::Result<()> {
                    let mut from = std::fs::File::open(&s.tmp)?;
                    let mut to = std::fs::OpenOptions::new().write(true).open(p)?;
                    std::io::copy(&mut from, &mut to)?;
                    Ok(())
                };
                copy().with_context(|| format!("cannot write {} {shown}", s.flag))?;
            }
        }
    }
    Ok(())
}

/// Drops every staged output (their temporaries are removed): a failed command replaces no
/// file.
pub(crate) fn discard() {
    with(|t| {
        t.planned.clear();
        t.staged.clear();
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_failed_command_replaces_nothing_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.fzq"), dir.path().join("b.json"));
        std::fs::write(&a, "old a").unwrap();
        std::fs::write(&b, "old b").unwrap();
        plan(&[(Some(&a), "--out"), (Some(&b), "--json")], &[]).unwrap();
        stage_bytes(&a, b"new a").unwrap();
        // The second output fails while it is written: the first must not be in place.
        let e = stage(&b, |_| bail!("disk full")).unwrap_err();
        assert_eq!(e.to_string(), "disk full");
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        discard();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "old b");
        assert_eq!(names(dir.path()), ["a.fzq", "b.json"]);
    }

    #[test]
    fn a_successful_command_puts_every_output_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.fzq"), dir.path().join("b.json"));
        std::fs::write(&a, "old a").unwrap();
        plan(&[(Some(&a), "--out"), (Some(&b), "--json")], &[]).unwrap();
        stage_bytes(&a, b"new a").unwrap();
        stage_bytes(&b, b"new b").unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        assert!(!b.exists());
        commit().unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "new a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b");
        assert_eq!(names(dir.path()), ["a.fzq", "b.json"]);
    }

    #[test]
    fn plans_name_the_flags_in_their_refusals() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.fzq");
        let same = dir.path().join(".").join("a.fzq");
        let e = plan(&[(Some(&a), "--out"), (Some(&same), "--json")], &[])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--json ") && e.contains("and --out"), "{e}");
        std::fs::write(&a, "config").unwrap();
        let e = plan(&[(Some(&a), "--out")], &[(Some(&a), "--config")])
            .unwrap_err()
            .to_string();
        assert!(e.contains("would overwrite the --config input"), "{e}");
        let e = plan(&[(Some(Path::new("")), "--out")], &[])
            .unwrap_err()
            .to_string();
        assert_eq!(e, "--out: the path is empty");
        discard();
    }
}
