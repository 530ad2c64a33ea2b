//! The recordings a batch fits, from what the command line names: a folder (its `*.csv` files, in its sub-folders
//! too, by name), a file (whatever its name), or a glob pattern the shell did not expand (`'lot7/*.csv'`: a lot too
//! large for the command line). Each recording is taken once, in the order named; the batch's own outputs and
//! hidden files are left out.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use crate::files::same_file;

/// Expands `args` into the recordings to fit, leaving out the files in `outputs` (the table itself may sit in the
/// folder it is made from).
pub fn recordings(args: &[PathBuf], outputs: &[&Path]) -> anyhow::Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    for arg in args {
        let before = found.len();
        if arg.is_dir() {
            walk(arg, &mut found)
                .with_context(|| format!("{}: cannot list the folder", arg.display()))?;
            if found.len() == before {
                bail!(
                    "{}: no recording in this folder or its sub-folders (a folder's *.csv files are taken; name other \
                     files one by one)",
                    arg.display()
                );
            }
        } else if arg.is_file() {
            found.push(arg.clone());
        } else if is_pattern(arg) {
            expand(arg, &mut found)?;
            if found.len() == before {
                bail!("{}: the pattern matches no file", arg.display());
            }
        } else {
            bail!(
                "{}: no such file or folder (name recordings, folders of them, or a quoted pattern such as \
                 'lot7/*.csv')",
                arg.display()
            );
        }
    }
    let mut seen = HashSet::new();
    found.retain(|p| {
        let key = std::fs::canonicalize(p).unwrap_or_else(|_| p.clone());
        seen.insert(key) && !outputs.iter().any(|o| same_file(p, o))
    });
    Ok(found)
}

/// Whether `arg` holds a glob's special characters.
fn is_pattern(arg: &Path) -> bool {
    arg.to_string_lossy().contains(['*', '?', '['])
}

/// The files (and the recordings in the folders) a glob pattern matches, in name order.
fn expand(pattern: &Path, found: &mut Vec<PathBuf>) -> anyhow::Result<()> {
    let text = pattern.to_string_lossy();
    let paths = glob::glob(&text).with_context(|| format!("{text}: not a valid pattern"))?;
    for path in paths {
        let path = path.with_context(|| format!("{text}: cannot list what it matches"))?;
        if path.is_dir() {
            walk(&path, found)
                .with_context(|| format!("{}: cannot list the folder", path.display()))?;
        } else if !hidden(&path) {
            found.push(path);
        }
    }
    Ok(())
}

/// The `*.csv` files of `dir` and its sub-folders, by name; hidden files and folders (a `.magcal-*.tmp` being
/// written, say) left out.
fn walk(dir: &Path, found: &mut Vec<PathBuf>) -> std::io::Result<()> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()?;
    entries.sort();
    for path in entries {
        if hidden(&path) {
            continue;
        }
        if path.is_dir() {
            walk(&path, found)?;
        } else if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
        {
            found.push(path);
        }
    }
    Ok(())
}

/// Whether a file's name starts with a dot.
fn hidden(path: &Path) -> bool {
    path.file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with('.'))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_files_and_patterns_expand_once_each_without_the_outputs() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir(d.join("day2")).unwrap();
        for name in [
            "b.csv",
            "a.CSV",
            "notes.txt",
            ".hidden.csv",
            "day2/c.csv",
            "table.csv",
        ] {
            std::fs::write(d.join(name), "t,mx,my,mz\n").unwrap();
        }
        let table = d.join("table.csv");
        let got = recordings(&[d.to_owned(), d.join("b.csv")], &[&table]).unwrap();
        let names: Vec<_> = got
            .iter()
            .map(|p| p.strip_prefix(d).unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["a.CSV", "b.csv", "day2/c.csv"]);
        let got = recordings(&[d.join("*.txt")], &[]).unwrap();
        assert_eq!(got, [d.join("notes.txt")]);
        let e = recordings(&[d.join("*.json")], &[]).unwrap_err();
        assert!(e.to_string().contains("matches no file"), "{e}");
        let e = recordings(&[d.join("missing.csv")], &[]).unwrap_err();
        assert!(e.to_string().contains("no such file or folder"), "{e}");
        let empty = d.join("empty");
        std::fs::create_dir(&empty).unwrap();
        let e = recordings(&[empty], &[]).unwrap_err();
        assert!(e.to_string().contains("no recording in this folder"), "{e}");
    }
}
