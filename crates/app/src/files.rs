//! Output files: written atomically (a temporary file in the same directory, synced, then renamed over the target,
//! so a reader sees the old file or the new one, never half of one, and an error leaves the old one untouched), with
//! the usual permissions, and never over the input they were made from nor over a recording.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` atomically. A new file gets the mode the user's umask gives (as any program's new file);
/// a replaced file keeps its permissions.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".magcal-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        // tempfile's default is 0600; 0666 is narrowed by the umask when the file is created.
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(dir)?;
    if let Ok(existing) = std::fs::metadata(path) {
        tmp.as_file().set_permissions(existing.permissions())?;
    }
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// An output that would destroy the input, or two outputs that would write one file.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum OutputConflict {
    /// The output is the input file (the same path, a link to it, or the same file under another name).
    #[error(
        "{flag} {} is the input {}: an output never overwrites the input; nothing was written (choose another path)",
        output.display(),
        input.display()
    )]
    IsInput {
        /// The option that names the output, e.g. `--out`.
        flag: String,
        /// The output path as given.
        output: PathBuf,
        /// The input path as given.
        input: PathBuf,
    },
    /// The output's folder is missing, or a file.
    #[error(
        "{flag} {}: {} {}; nothing was written (create the folder, or choose another path)",
        output.display(),
        folder.display(),
        if *exists { "is a file, not a folder" } else { "does not exist" }
    )]
    NoFolder {
        /// The option that names the output.
        flag: String,
        /// The output path as given.
        output: PathBuf,
        /// Its folder.
        folder: PathBuf,
        /// Whether the folder's path exists (as a file).
        exists: bool,
    },
    /// The output names a folder.
    #[error(
        "{flag} {} is a folder: name a file in it; nothing was written",
        output.display()
    )]
    IsFolder {
        /// The option that names the output.
        flag: String,
        /// The output path as given.
        output: PathBuf,
    },
    /// The output would replace a recording.
    #[error(
        "{flag} {} holds a recording: an output never replaces one (readings cannot be recorded again); nothing was \
         written (choose another path)",
        output.display()
    )]
    IsRecording {
        /// The option that names the output.
        flag: String,
        /// The output path as given.
        output: PathBuf,
    },
    /// Two outputs name the same file.
    #[error(
        "{first} and {second} both name {}: one would overwrite the other; nothing was written",
        path.display()
    )]
    SameOutput {
        /// The first option.
        first: String,
        /// The second option.
        second: String,
        /// The path, as the second option gives it.
        path: PathBuf,
    },
}

/// Checks, before anything is written, that the file an option (`flag`) names can be made: its folder exists and is
/// a folder, it is not itself a folder (otherwise the work would be done and then lost on the write, with only the
/// system's word for why), and it is no recording (parameters, reports and exports never replace one).
pub fn check_file_output(flag: &str, path: &Path) -> Result<(), OutputConflict> {
    check_output(flag, path, None)
}

/// [`check_file_output`] for an output that is itself a recording, which may replace a recording whose metadata has
/// the key `remakes` (`simulated` for magcal-sim, `calibrated_with` for magcal-apply's calibrated copy): one the tool
/// made before, and can make again.
pub fn check_recording_output(
    flag: &str,
    path: &Path,
    remakes: &str,
) -> Result<(), OutputConflict> {
    check_output(flag, path, Some(remakes))
}

fn check_output(flag: &str, path: &Path, remakes: Option<&str>) -> Result<(), OutputConflict> {
    let folder = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        return Err(OutputConflict::NoFolder {
            flag: flag.to_owned(),
            output: path.to_owned(),
            folder: folder.to_owned(),
            exists: folder.exists(),
        });
    }
    if path.is_dir() {
        return Err(OutputConflict::IsFolder {
            flag: flag.to_owned(),
            output: path.to_owned(),
        });
    }
    if holds_recording(path, remakes) {
        return Err(OutputConflict::IsRecording {
            flag: flag.to_owned(),
            output: path.to_owned(),
        });
    }
    Ok(())
}

/// Bytes of a file's start read to tell whether it is a recording: the metadata block and the header.
const RECORDING_PROBE_BYTES: u64 = 64 << 10;

/// Whether `path` holds a recording ([`looks_like_recording`]) whose metadata lacks the key `remakes`.
fn holds_recording(path: &Path, remakes: Option<&str>) -> bool {
    use std::io::Read as _;
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let mut start = Vec::new();
    if file
        .take(RECORDING_PROBE_BYTES)
        .read_to_end(&mut start)
        .is_err()
    {
        return false;
    }
    let text = String::from_utf8_lossy(&start);
    let remade = remakes.is_some_and(|key| {
        text.lines()
            .take_while(|l| l.starts_with('#'))
            .filter_map(|l| l.trim_start_matches('#').trim_start().split_once(':'))
            .any(|(k, _)| k.trim() == key)
    });
    looks_like_recording(&text) && !remade
}

/// Whether `text` starts as a recording does: with a `# magcal-recording` line, or with a header row (after any `#`
/// lines) that names `mx` among fields separated by commas, `;` or tabs.
pub fn looks_like_recording(text: &str) -> bool {
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let Some(first) = lines.next() else {
        return false;
    };
    if first.starts_with("# magcal-recording") {
        return true;
    }
    let header = std::iter::once(first)
        .chain(lines)
        .find(|l| !l.starts_with('#'));
    let separators = [',', ';', '\t'];
    header.is_some_and(|h| {
        h.contains(separators)
            && h.split(separators)
                .any(|field| field.trim().eq_ignore_ascii_case("mx"))
    })
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

/// Checks, before anything is written, that no output (`(option, path)`) is the input file and that no two outputs
/// name the same file.
pub fn check_outputs(input: &Path, outputs: &[(&str, &Path)]) -> Result<(), OutputConflict> {
    for (i, &(flag, output)) in outputs.iter().enumerate() {
        if same_file(output, input) {
            return Err(OutputConflict::IsInput {
                flag: flag.to_owned(),
                output: output.to_owned(),
                input: input.to_owned(),
            });
        }
        if let Some(&(first, _)) = outputs[..i].iter().find(|(_, p)| same_file(p, output)) {
            return Err(OutputConflict::SameOutput {
                first: first.to_owned(),
                second: flag.to_owned(),
                path: output.to_owned(),
            });
        }
    }
    Ok(())
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
    fn an_output_in_a_missing_folder_or_a_file_or_naming_a_folder_is_refused_first() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("afile");
        std::fs::write(&file, b"x").unwrap();
        let e = check_file_output("--out", &file.join("p.toml")).unwrap_err();
        assert!(e.to_string().contains("is a file, not a folder"), "{e}");
        let e = check_file_output("--out", &dir.path().join("no/p.toml")).unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
        let e = check_file_output("--report", dir.path()).unwrap_err();
        assert!(e.to_string().starts_with("--report") && e.to_string().contains("is a folder"));
        assert_eq!(
            check_file_output("--out", &dir.path().join("p.toml")),
            Ok(())
        );
        assert_eq!(check_file_output("--out", Path::new("p.toml")), Ok(()));
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

    #[test]
    fn outputs_onto_the_input_or_onto_each_other_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("rec.csv");
        std::fs::write(&input, "t,mx,my,mz\n").unwrap();
        let other = dir.path().join("params.toml");
        let via_dots = dir.path().join(".").join("rec.csv");
        assert!(check_outputs(&input, &[("--out", &other)]).is_ok());
        let e = check_outputs(&input, &[("--out", &other), ("--report", &via_dots)]).unwrap_err();
        assert!(
            matches!(&e, OutputConflict::IsInput { flag, .. } if flag == "--report"),
            "{e}"
        );
        let e = check_outputs(&input, &[("--out", &other), ("--report", &other)]).unwrap_err();
        assert!(matches!(e, OutputConflict::SameOutput { .. }), "{e}");
        #[cfg(unix)]
        {
            let link = dir.path().join("link.csv");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            let hard = dir.path().join("hard.csv");
            std::fs::hard_link(&input, &hard).unwrap();
            for p in [&link, &hard] {
                assert!(
                    matches!(
                        check_outputs(&input, &[("--out", p)]),
                        Err(OutputConflict::IsInput { .. })
                    ),
                    "{}",
                    p.display()
                );
            }
        }
    }
}
