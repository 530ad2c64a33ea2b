//! Output files: written atomically ([`magcal_recording::atomic`]: a temporary file in the same folder, synced, then
//! renamed over the target, so a reader sees the old file or the new one, never half of one, an error leaves the old
//! one untouched, and a link at the target is replaced itself), with the usual permissions. Which outputs may be
//! written at all is [`crate::outputs`]'s to say.

use std::io::Write;
use std::path::{Path, PathBuf};

use magcal_recording::probe::{Holds, probe_reader};

/// Writes `bytes` to `path` atomically. A new file gets the mode the user's umask gives (as any program's new file);
/// a replaced file keeps its permissions; a file another process holds the lock of (a recorder writing it) is not
/// replaced.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    magcal_recording::atomic::replace(path, |file| file.write_all(bytes))
}

/// Whether `text` holds a recording ([`magcal_recording::probe`]): a `# magcal-recording` line in its metadata
/// block, or a header row (after any `#` lines) that names `mx` among fields separated by commas, `;` or tabs.
pub fn looks_like_recording(text: &str) -> bool {
    matches!(probe_reader(text.as_bytes()), Ok(Holds::Recording { .. }))
}

/// Where `path` leads: the file itself if it exists (links followed), else its directory's real path joined with
/// its name (the place a new file would take); `None` if not even the directory exists.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Some(p);
    }
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    Some(std::fs::canonicalize(dir).ok()?.join(name))
}

/// Whether two paths are one file: the same place, or (Unix) the same file under two names (hard links).
pub fn same_file(a: &Path, b: &Path) -> bool {
    if let (Some(x), Some(y)) = (resolved(a), resolved(b))
        && x == y
    {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_the_file_and_leaves_no_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("params.toml");
        write_atomic(&path, b"old").unwrap();
        write_atomic(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_missing_directory_is_an_error_and_writes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        assert!(write_atomic(&dir.path().join("no/such/dir/p.toml"), b"x").is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[cfg(unix)]
    #[test]
    fn new_files_get_the_umask_mode_and_replaced_ones_keep_theirs() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("params.toml");
        write_atomic(&path, b"x").unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        // Whatever the umask, a new file is readable by its group or others unless the umask says otherwise:
        // compare with a file the standard library creates.
        let plain = dir.path().join("plain");
        std::fs::File::create(&plain).unwrap();
        let expected = std::fs::metadata(&plain).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, expected, "{mode:o} vs {expected:o}");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_atomic(&path, b"y").unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640);
    }

    #[cfg(unix)]
    #[test]
    fn the_same_file_under_any_name_is_the_same_file() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("rec.csv");
        std::fs::write(&input, "t,mx,my,mz\n").unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let via_dots = dir.path().join("sub/../rec.csv");
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let hard = dir.path().join("hard.csv");
        std::fs::hard_link(&input, &hard).unwrap();
        for p in [&via_dots, &link, &hard] {
            assert!(same_file(p, &input), "{}", p.display());
        }
        assert!(!same_file(&dir.path().join("other.csv"), &input));
        assert!(looks_like_recording("# note\nt,MX,my,mz\n"));
        assert!(!looks_like_recording("format = 1\n"));
    }
}
