//! Files replaced whole: written to a temporary file beside the target (`.NAME.PID.N.tmp`, in the same folder),
//! then renamed over it, so that a reader sees the old file or the new one, never half of one, an error leaves the
//! old one untouched, and a link at the target's path is replaced itself (the file it points to, and the file's
//! other names, keep their bytes).
//!
//! A temporary file is locked while its process writes it, and keeps the mode of the file it replaces (a new one
//! gets the umask's). A target another process holds the lock of (a recorder writing it) is never replaced.
//! [`clean_stale`] removes the temporary files a killed process left behind.

use std::fs::{self, File, OpenOptions, TryLockError};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Distinguishes the temporary files of one process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The folder a file at `path` is in (`.` for a bare name).
pub fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Whether another process holds the lock of the regular file at `path` (a recorder writing it). A missing file,
/// or one that is no regular file, is not locked.
pub fn locked_by_another(path: &Path) -> bool {
    if !fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return false;
    }
    let Ok(file) = File::open(path) else {
        return false;
    };
    matches!(file.try_lock(), Err(TryLockError::WouldBlock))
}

/// The error for a target another process holds the lock of.
pub(crate) fn busy(path: &Path) -> io::Error {
    io::Error::new(
        io::ErrorKind::WouldBlock,
        format!(
            "{} is being written by another process (it holds the file's lock)",
            path.display()
        ),
    )
}

/// A temporary file beside its target, removed on drop unless [`Temp::persist`]ed.
#[derive(Debug)]
pub struct Temp {
    file: File,
    staged: Staged,
}

/// Where a temporary file is and what it will replace: renames it over its target ([`Staged::persist`]), or removes
/// it when dropped.
#[derive(Debug)]
pub struct Staged {
    path: Option<PathBuf>,
    target: PathBuf,
}

impl Drop for Staged {
    fn drop(&mut self) {
        if let Some(path) = &self.path {
            let _ = fs::remove_file(path);
        }
    }
}

impl Temp {
    /// A new temporary file in `target`'s folder, locked, with the mode of the file at `target` if there is one.
    pub fn beside(target: &Path) -> io::Result<Temp> {
        let name = target
            .file_name()
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "the path names no file"))?;
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let path = folder_of(target).join(format!(
            ".{}.{}.{n}.tmp",
            name.to_string_lossy(),
            std::process::id()
        ));
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)?;
        let temp = Temp {
            file,
            staged: Staged {
                path: Some(path),
                target: target.to_owned(),
            },
        };
        // Some file systems have no locks: the temporary file is then just not protected from a cleaner.
        let _ = temp.file.try_lock();
        if let Ok(existing) = fs::metadata(target) {
            temp.file.set_permissions(existing.permissions())?;
        }
        Ok(temp)
    }

    /// The open temporary file.
    pub fn file(&mut self) -> &mut File {
        &mut self.file
    }

    /// The open file and what renames it: for a caller that goes on writing the file after the rename.
    pub fn into_parts(self) -> (File, Staged) {
        (self.file, self.staged)
    }

    /// Renames the temporary file over its target and returns it, still open and locked (see [`Staged::persist`]).
    pub fn persist(self, held: Option<File>) -> io::Result<File> {
        self.staged.persist(held)?;
        Ok(self.file)
    }
}

impl Staged {
    /// Renames the temporary file over its target. Refused (kind [`io::ErrorKind::WouldBlock`], the temporary file
    /// removed) if another process holds the target's lock; `held` is a lock on the target the caller holds itself,
    /// released once the target is replaced.
    pub fn persist(mut self, held: Option<File>) -> io::Result<()> {
        self.persist_inner(held)
    }

    fn persist_inner(&mut self, held: Option<File>) -> io::Result<()> {
        if held.is_none() && locked_by_another(&self.target) {
            return Err(busy(&self.target));
        }
        if let Some(path) = &self.path {
            fs::rename(path, &self.target)?;
        }
        self.path = None;
        drop(held);
        // Make the rename itself durable; folders cannot be opened for this on every platform.
        if let Ok(d) = File::open(folder_of(&self.target)) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// [`Staged::persist`], except that a temporary file that could not be renamed is kept (its rows are not
    /// lost: the caller names it, [`Staged::temp_path`]).
    pub fn persist_or_keep(mut self, held: Option<File>) -> io::Result<()> {
        let result = self.persist_inner(held);
        if result.is_err() {
            self.path = None;
        }
        result
    }

    /// Where the temporary file is, until it is renamed.
    pub fn temp_path(&self) -> Option<&Path> {
        self.path.as_deref()
    }
}

/// Replaces `target` with what `write` puts in a new file, atomically (see the [module docs](self)), synced. On
/// error the target is left as it was and no temporary file remains; a full disk or a reached file size limit
/// (`ulimit -f`) is said in the error's message.
pub fn replace(target: &Path, write: impl FnOnce(&mut File) -> io::Result<()>) -> io::Result<()> {
    let mut temp = Temp::beside(target)?;
    write(temp.file())
        .and_then(|()| temp.file().sync_all())
        .map_err(|e| explained(e, target))?;
    temp.persist(None)?;
    Ok(())
}

/// What a failed write's error means when it is a full disk or a reached file size limit (`ulimit -f`).
pub fn storage_reason(e: &io::Error) -> Option<&'static str> {
    match e.kind() {
        io::ErrorKind::StorageFull | io::ErrorKind::QuotaExceeded => Some("the disk is full"),
        io::ErrorKind::FileTooLarge => Some("the file size limit (ulimit -f) was reached"),
        _ => None,
    }
}

/// `e` with what a full disk or a reached file size limit means for `target`, if it is one of those.
fn explained(e: io::Error, target: &Path) -> io::Error {
    match storage_reason(&e) {
        Some(why) => io::Error::new(
            e.kind(),
            format!(
                "{e}: {why}; {} was left as it was (free space or raise the limit, and run again)",
                target.display()
            ),
        ),
        None => e,
    }
}

/// A temporary file a process that ended left behind, removed by [`clean_stale`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stale {
    /// Where it was.
    pub path: PathBuf,
    /// Its size, bytes.
    pub bytes: u64,
}

/// A temporary file this old whose process cannot be looked up (no `/proc`) and whose lock is free is stale.
const STALE_WITHOUT_PROC: Duration = Duration::from_secs(3600);

/// The process id in a temporary file's name (`.NAME.PID.N.tmp`), if it is one.
fn temp_pid(name: &str) -> Option<u32> {
    let inner = name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let mut parts = inner.rsplitn(3, '.');
    let n = parts.next()?;
    let pid = parts.next()?;
    let target = parts.next()?;
    if target.is_empty() || !n.bytes().all(|b| b.is_ascii_digit()) || n.is_empty() {
        return None;
    }
    pid.parse().ok()
}

/// Whether the process `pid` has ended: `Some` where `/proc` can tell.
fn ended(pid: u32) -> Option<bool> {
    Path::new("/proc/self")
        .exists()
        .then(|| !Path::new("/proc").join(pid.to_string()).exists())
}

/// Removes the temporary files in `folder` that a process that ended left (killed while it wrote: `kill -9`, a
/// power cut): those named as [`Temp`] names them, of another process that has ended (or, where that cannot be
/// looked up, an hour old), whose lock is free. Returns what it removed.
pub fn clean_stale(folder: &Path) -> Vec<Stale> {
    let Ok(entries) = fs::read_dir(folder) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(temp_pid) else {
            continue;
        };
        let Ok(meta) = entry.metadata() else {
            continue;
        };
        if pid == std::process::id() || !meta.is_file() {
            continue;
        }
        let gone = ended(pid).unwrap_or_else(|| {
            meta.modified()
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > STALE_WITHOUT_PROC)
        });
        let path = entry.path();
        let free = File::open(&path).is_ok_and(|f| f.try_lock().is_ok());
        if gone && free && fs::remove_file(&path).is_ok() {
            removed.push(Stale {
                path,
                bytes: meta.len(),
            });
        }
    }
    removed.sort_by(|a, b| a.path.cmp(&b.path));
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporary_names_are_recognised() {
        assert_eq!(temp_pid(".rec.csv.4242.7.tmp"), Some(4242));
        assert_eq!(temp_pid(".a.1.0.tmp"), Some(1));
        for not in [
            "rec.csv",
            ".rec.csv.tmp",
            "..1.2.tmp",
            ".x.y.z.tmp",
            ".x.1.z.tmp",
        ] {
            assert_eq!(temp_pid(not), None, "{not}");
        }
    }

    #[test]
    fn a_replaced_file_keeps_its_mode_and_a_link_is_replaced_itself() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.csv");
        fs::write(&target, "old").unwrap();
        fs::set_permissions(&target, fs::Permissions::from_mode(0o640)).unwrap();
        replace(&target, |f| io::Write::write_all(f, b"new")).unwrap();
        assert_eq!(fs::read(&target).unwrap(), b"new");
        let mode = fs::metadata(&target).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640);
        let kept = dir.path().join("kept.csv");
        fs::write(&kept, "kept").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&kept, &link).unwrap();
        replace(&link, |f| io::Write::write_all(f, b"new")).unwrap();
        assert_eq!(fs::read(&kept).unwrap(), b"kept");
        assert!(!fs::symlink_metadata(&link).unwrap().is_symlink());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 3);
    }

    #[test]
    fn a_failed_write_or_a_locked_target_leaves_the_target_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.csv");
        fs::write(&target, "old").unwrap();
        let e = replace(&target, |_| {
            Err(io::Error::from(io::ErrorKind::FileTooLarge))
        })
        .unwrap_err();
        assert!(e.to_string().contains("ulimit -f"), "{e}");
        let holder = File::open(&target).unwrap();
        holder.lock().unwrap();
        let e = replace(&target, |f| io::Write::write_all(f, b"new")).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::WouldBlock, "{e}");
        drop(holder);
        assert_eq!(fs::read(&target).unwrap(), b"old");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn only_the_temporaries_of_ended_processes_are_cleaned() {
        let dir = tempfile::tempdir().unwrap();
        // A process id above Linux's largest (4194304) is of no process.
        let dead = dir.path().join(".rec.csv.4999999.0.tmp");
        fs::write(&dead, vec![b'x'; 1000]).unwrap();
        let alive = dir
            .path()
            .join(format!(".rec.csv.{}.9.tmp", std::process::id()));
        fs::write(&alive, "mine").unwrap();
        let other = dir.path().join(".notes.txt");
        fs::write(&other, "not ours").unwrap();
        let removed = clean_stale(dir.path());
        assert_eq!(
            removed,
            [Stale {
                path: dead.clone(),
                bytes: 1000
            }]
        );
        assert!(!dead.exists() && alive.exists() && other.exists());
        // A live process's temporary keeps its lock: even with its name's process gone, it stays.
        let locked = dir.path().join(".rec.csv.4999998.0.tmp");
        fs::write(&locked, "busy").unwrap();
        let holder = File::open(&locked).unwrap();
        holder.lock().unwrap();
        assert!(clean_stale(dir.path()).is_empty());
        assert!(locked.exists());
    }
}
