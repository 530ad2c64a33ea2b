//! The one guard every output of every tool goes through, before anything is read, opened or written
//! ([`Guard::check`]). An output never lands
//!
//! - on an input: the same path, a link to it, or the same file under another name (a hard link);
//! - on another output of the same run;
//! - on a recording, however it was saved (compressed, UTF-16, a metadata block of any length:
//!   [`magcal_recording::probe`]), unless `--force` names that path for the recorder ([`Replace::Recording`]) or
//!   the recording is one the tool made and can make again ([`Replace::Remakes`]);
//! - on a file a recorder is writing (it holds the file's lock);
//! - on what is no regular file (a device, a pipe): outputs are written to a temporary file renamed into place;
//! - for the tools that record, on any existing file without `--force` ([`Replace::New`]).
//!
//! [`OPTIONS`] lists every option of every tool that names a path, as input or output; `tests/output_guard.rs`
//! checks each tool's `--help` against it and aims each output at a recording.
//!
//! Checking also readies the process to write: SIGXFSZ is blocked, so that a file size limit (`ulimit -f`) fails
//! the write (EFBIG), handled as a full disk is, instead of killing the process mid-line; and the temporary files a
//! killed run left beside the outputs are removed and named.

use std::fs;
use std::path::{Path, PathBuf};

use magcal_recording::atomic::{self, folder_of, locked_by_another};
use magcal_recording::probe::{Holds, probe};

use crate::files::same_file;

/// What an output may replace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Replace {
    /// Any file that holds no recording: parameters, reports, exports, plots, truths (each run makes them again).
    Products,
    /// Any file that holds no recording, and a recording whose metadata has this key with a value that starts so:
    /// one the tool made and can make again (`simulated: magcal-sim…` for magcal-sim, `calibrated_with` for
    /// magcal-apply's calibrated copies).
    Remakes(&'static str, &'static str),
    /// Nothing that exists, unless `--force`; with it, any file that holds no recording.
    New,
    /// The recording being recorded: nothing that exists, unless `--force`; with it, whatever the path names (the
    /// path itself is replaced: a link there, not the file it points to).
    Recording,
}

/// Whether an option names a file the tool reads or one it writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Read.
    Input,
    /// Written (through [`Guard`]).
    Output,
}

/// Every option of every tool that names a path: tool, option (a positional argument by its value name, as
/// `--help` shows it), role.
pub const OPTIONS: &[(&str, &str, Role)] = &[
    ("magcal", "--out-dir", Role::Output),
    ("magcal-fit", "<RECORDING>", Role::Input),
    ("magcal-fit", "--out", Role::Output),
    ("magcal-fit", "--report", Role::Output),
    ("magcal-fit", "--export-out", Role::Output),
    ("magcal-fit", "--plots", Role::Output),
    ("magcal-fit", "--undo-out", Role::Output),
    ("magcal-fit", "--params", Role::Input),
    ("magcal-apply", "<PARAMS>", Role::Input),
    ("magcal-apply", "<RECORDING>", Role::Input),
    ("magcal-apply", "--out", Role::Output),
    ("magcal-record", "--out", Role::Output),
    ("magcal-record", "--truth", Role::Output),
    ("magcal-sim", "--out", Role::Output),
    ("magcal-sim", "--truth", Role::Output),
    ("magcal-batch", "<DIR|FILE|GLOB>...", Role::Input),
    ("magcal-batch", "--out", Role::Output),
    ("magcal-batch", "--json", Role::Output),
];

/// The tools whose refusals say that nothing was recorded.
const RECORDERS: [&str; 2] = ["magcal", "magcal-record"];

/// Why an output was refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Why {
    /// It is an input (named by its option or value name, and its path).
    IsInput(String, PathBuf),
    /// Its folder is missing (`false`) or is a file (`true`).
    NoFolder(PathBuf, bool),
    /// It names a folder.
    IsFolder,
    /// A folder output names a file.
    FolderIsFile,
    /// It is no regular file.
    NotAFile,
    /// It holds a recording: how it was saved, when not plain text; whether `--force` would replace it.
    HoldsRecording(Option<String>, bool),
    /// An earlier option names the same file.
    SameAs(&'static str),
    /// Another process holds its lock.
    Busy,
    /// It exists and `--force` was not given; whether the output is a recording.
    Exists(bool),
}

/// An output refused, before anything was written.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}", self.message())]
pub struct Refused {
    /// The option that names it.
    pub option: &'static str,
    /// The path, as given.
    pub path: PathBuf,
    /// Why.
    pub why: Why,
    /// What was not done: "nothing was written" or "nothing was recorded".
    pub nothing: &'static str,
}

impl Refused {
    fn message(&self) -> String {
        let (o, p, nothing) = (self.option, self.path.display(), self.nothing);
        match &self.why {
            Why::IsInput(input, path) => format!(
                "{o} {p} is the input {input} {}: an output never overwrites the input; {nothing} (choose another \
                 path)",
                path.display()
            ),
            Why::NoFolder(folder, is_file) => format!(
                "{o} {p}: {} {}; {nothing} (create the folder, or choose another path)",
                folder.display(),
                if *is_file {
                    "is a file, not a folder"
                } else {
                    "does not exist"
                }
            ),
            Why::IsFolder => format!("{o} {p} is a folder: name a file in it; {nothing}"),
            Why::FolderIsFile => format!(
                "{o} {p}: a file is there, and {o} names a directory (a folder, made if missing, that the outputs \
                 are written into); {nothing}"
            ),
            Why::NotAFile => format!(
                "{o} {p} is not a regular file (a device, a pipe?): outputs are written to a new file and renamed \
                 into place; {nothing} (name a file)"
            ),
            Why::HoldsRecording(how, forceable) => format!(
                "{o} {p} holds a recording{}: {} (readings cannot be recorded again); {nothing} (choose another \
                 path{})",
                how.as_deref()
                    .map(|h| format!(" ({h})"))
                    .unwrap_or_default(),
                if *forceable {
                    "it is never replaced unasked"
                } else {
                    "an output never replaces one"
                },
                if *forceable {
                    ", or add --force to replace it"
                } else {
                    ""
                }
            ),
            Why::SameAs(first) => {
                format!("{first} and {o} both name {p}: one would overwrite the other; {nothing}")
            }
            Why::Busy => format!(
                "{p} is being written by another recorder (it holds the file's lock): choose another {o} \
                 ({nothing})"
            ),
            Why::Exists(recording) => format!(
                "{p} exists: {}; choose another {o}, or add --force to replace it ({nothing})",
                if *recording {
                    "a recording is never replaced"
                } else {
                    "a file is never replaced unasked"
                }
            ),
        }
    }
}

/// One output to check.
#[derive(Clone, Debug)]
struct Output {
    option: &'static str,
    path: PathBuf,
    replace: Replace,
}

/// The inputs and outputs of one run of a tool, checked together ([`Guard::check`]).
#[derive(Clone, Debug)]
pub struct Guard {
    tool: &'static str,
    force: bool,
    inputs: Vec<(&'static str, PathBuf)>,
    outputs: Vec<Output>,
    /// Folders the tool makes if missing and writes outputs into.
    folders: Vec<(&'static str, PathBuf)>,
}

impl Guard {
    /// The guard of a run of `tool` (its name as in [`OPTIONS`]).
    pub fn new(tool: &'static str) -> Guard {
        Guard {
            tool,
            force: false,
            inputs: Vec::new(),
            outputs: Vec::new(),
            folders: Vec::new(),
        }
    }

    /// Whether `--force` was given.
    pub fn force(mut self, force: bool) -> Guard {
        self.force = force;
        self
    }

    /// A file the run reads, named by `option` (a value name for a positional argument).
    pub fn input(mut self, option: &'static str, path: &Path) -> Guard {
        self.registered(option, Role::Input);
        self.inputs.push((option, path.to_owned()));
        self
    }

    /// A file the run writes, if `path` is given.
    pub fn file(mut self, option: &'static str, path: Option<&Path>, replace: Replace) -> Guard {
        self.registered(option, Role::Output);
        if let Some(path) = path {
            self.outputs.push(Output {
                option,
                path: path.to_owned(),
                replace,
            });
        }
        self
    }

    /// A folder the run makes if missing and writes the files `names` into, if `dir` is given.
    pub fn folder(
        mut self,
        option: &'static str,
        dir: Option<&Path>,
        names: &[&str],
        replace: Replace,
    ) -> Guard {
        self.registered(option, Role::Output);
        if let Some(dir) = dir {
            self.folders.push((option, dir.to_owned()));
            for name in names {
                self.outputs.push(Output {
                    option,
                    path: dir.join(name),
                    replace,
                });
            }
        }
        self
    }

    /// Every option is in [`OPTIONS`], so that the test of every tool's `--help` covers it.
    fn registered(&self, option: &str, role: Role) {
        debug_assert!(
            OPTIONS.contains(&(self.tool, option, role)),
            "{} {option} is missing from outputs::OPTIONS",
            self.tool
        );
    }

    /// Checks every output (see the [module docs](self)), in the order given, before anything is written; then
    /// readies the process to write and removes the temporary files a killed run left beside the outputs, naming
    /// them on standard error.
    pub fn check(self) -> Result<(), Refused> {
        let nothing = if RECORDERS.contains(&self.tool) {
            "nothing was recorded"
        } else {
            "nothing was written"
        };
        let refuse = |option: &'static str, path: &Path, why: Why| Refused {
            option,
            path: path.to_owned(),
            why,
            nothing,
        };
        for (option, dir) in &self.folders {
            if dir.exists() && !dir.is_dir() {
                return Err(refuse(option, dir, Why::FolderIsFile));
            }
        }
        for (i, out) in self.outputs.iter().enumerate() {
            if let Some(why) = self.why_not(i, out) {
                return Err(refuse(out.option, &out.path, why));
            }
        }
        block_file_size_signal();
        self.clean_stale();
        Ok(())
    }

    /// Why output `i` may not be written, if it may not.
    fn why_not(&self, i: usize, out: &Output) -> Option<Why> {
        let path = &out.path;
        let folder = folder_of(path);
        let made = self
            .folders
            .iter()
            .any(|(_, d)| d.as_path() == folder && !d.exists());
        if made {
            return None;
        }
        if !folder.is_dir() {
            return Some(Why::NoFolder(folder.to_owned(), folder.exists()));
        }
        if path.is_dir() {
            return Some(Why::IsFolder);
        }
        if fs::metadata(path).is_ok_and(|m| !m.is_file()) {
            return Some(Why::NotAFile);
        }
        if let Some((name, input)) = self.inputs.iter().find(|(_, p)| same_file(path, p)) {
            return Some(Why::IsInput((*name).to_owned(), input.clone()));
        }
        if let Some(first) = self.outputs[..i].iter().find(|o| same_file(&o.path, path)) {
            return Some(Why::SameAs(first.option));
        }
        if locked_by_another(path) {
            return Some(Why::Busy);
        }
        let forced = self.force && out.replace == Replace::Recording;
        let how = match probe(path) {
            Holds::Other => None,
            Holds::Recording { pairs, encoding } => match out.replace {
                Replace::Remakes(key, value)
                    if pairs.iter().any(|(k, v)| k == key && v.starts_with(value)) =>
                {
                    None
                }
                _ => Some(encoding.map(|e| format!("encoded as {e}"))),
            },
            Holds::Compressed(format) => {
                Some(Some(format!("compressed with {format}: it may hold one")))
            }
        };
        if let Some(how) = how
            && !forced
        {
            return Some(Why::HoldsRecording(how, out.replace == Replace::Recording));
        }
        let asks = matches!(out.replace, Replace::New | Replace::Recording);
        if asks && !self.force && fs::symlink_metadata(path).is_ok() {
            return Some(Why::Exists(out.replace == Replace::Recording));
        }
        None
    }

    /// Removes the temporary files of ended runs in the outputs' folders, naming them.
    fn clean_stale(&self) {
        let mut folders: Vec<&Path> = self.outputs.iter().map(|o| folder_of(&o.path)).collect();
        folders.sort();
        folders.dedup();
        for folder in folders {
            for stale in atomic::clean_stale(folder) {
                crate::tellln!(
                    "{}: removed {} ({:.1} MB), a temporary file a run that was killed while writing left behind",
                    self.tool,
                    stale.path.display(),
                    stale.bytes as f64 / 1e6
                );
            }
        }
    }
}

/// Blocks SIGXFSZ in this thread and the threads it starts afterwards: a write past the file size limit then fails
/// with EFBIG, which the writers handle as a full disk (whole lines kept, temporary files removed, a message), where
/// the signal's default action would end the process at once. (Ignoring the signal takes `unsafe`; blocking it does
/// not, and suffices: the signal is sent to the thread that writes, where it stays pending, unhandled.)
fn block_file_size_signal() {
    use nix::sys::signal::{SigSet, Signal};
    let mut set = SigSet::empty();
    set.add(Signal::SIGXFSZ);
    // Failure leaves the default action, as before.
    let _ = set.thread_block();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_refusal_names_its_option_and_why() {
        let dir = tempfile::tempdir().unwrap();
        let at = |name: &str| dir.path().join(name);
        fs::write(at("afile"), "x").unwrap();
        fs::write(at("rec.csv"), "t,mx,my,mz\n0,1,2,3\n").unwrap();
        fs::write(
            at("sim.csv"),
            "# simulated: magcal-sim, seed 1\nt,mx,my,mz\n0,1,2,3\n",
        )
        .unwrap();
        fs::write(
            at("recorded.csv"),
            "# simulated: magcal-record sim:lis3mdl, seed 1\nt,mx,my,mz\n0,1,2,3\n",
        )
        .unwrap();
        fs::write(at("params.toml"), "format = 1\n").unwrap();
        let file = |tool, option, path: &Path, replace| {
            Guard::new(tool)
                .file(option, Some(path), replace)
                .check()
                .map_err(|e| e.why)
        };
        let products = Replace::Products;
        let sim = Replace::Remakes("simulated", "magcal-sim");
        assert_eq!(
            file("magcal-fit", "--out", &at("afile/p.toml"), products),
            Err(Why::NoFolder(at("afile"), true))
        );
        assert_eq!(
            file("magcal-fit", "--out", &at("no/p.toml"), products),
            Err(Why::NoFolder(at("no"), false))
        );
        assert_eq!(
            file("magcal-fit", "--out", dir.path(), products),
            Err(Why::IsFolder)
        );
        assert_eq!(
            file("magcal-fit", "--report", Path::new("/dev/null"), products),
            Err(Why::NotAFile)
        );
        assert_eq!(
            file("magcal-fit", "--out", &at("rec.csv"), products),
            Err(Why::HoldsRecording(None, false))
        );
        assert_eq!(
            file("magcal-fit", "--out", &at("params.toml"), products),
            Ok(())
        );
        assert_eq!(file("magcal-sim", "--out", &at("sim.csv"), sim), Ok(()));
        assert_eq!(
            file("magcal-sim", "--out", &at("recorded.csv"), sim),
            Err(Why::HoldsRecording(None, false))
        );
        assert_eq!(
            file("magcal-record", "--truth", &at("params.toml"), Replace::New),
            Err(Why::Exists(false))
        );
        assert_eq!(
            file("magcal-record", "--out", &at("rec.csv"), Replace::Recording),
            Err(Why::HoldsRecording(None, true))
        );
        let forced = |option, path: &Path, replace| {
            Guard::new("magcal-record")
                .force(true)
                .file(option, Some(path), replace)
                .check()
                .map_err(|e| e.why)
        };
        assert_eq!(forced("--out", &at("rec.csv"), Replace::Recording), Ok(()));
        assert_eq!(forced("--truth", &at("params.toml"), Replace::New), Ok(()));
        assert_eq!(
            forced("--truth", &at("rec.csv"), Replace::New),
            Err(Why::HoldsRecording(None, false))
        );
        let holder = fs::File::open(at("params.toml")).unwrap();
        holder.lock().unwrap();
        assert_eq!(
            forced("--truth", &at("params.toml"), Replace::New),
            Err(Why::Busy)
        );
    }

    #[test]
    fn inputs_other_outputs_and_folders_are_checked_together() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("rec.csv");
        fs::write(&input, "t,mx,my,mz\n0,1,2,3\n").unwrap();
        let report = dir.path().join("report.json");
        fs::create_dir(dir.path().join("sub")).unwrap();
        let e = Guard::new("magcal-fit")
            .input("<RECORDING>", &input)
            .file("--out", Some(&report), Replace::Products)
            .file(
                "--report",
                Some(&dir.path().join("sub/../report.json")),
                Replace::Products,
            )
            .check()
            .unwrap_err();
        assert_eq!(e.why, Why::SameAs("--out"));
        assert!(
            e.to_string().starts_with("--out and --report both name"),
            "{e}"
        );
        let e = Guard::new("magcal-fit")
            .input("<RECORDING>", &input)
            .folder("--plots", Some(dir.path()), &["rec.csv"], Replace::Products)
            .check()
            .unwrap_err();
        assert!(matches!(e.why, Why::IsInput(..)), "{e}");
        assert!(e.to_string().contains("never overwrites the input"), "{e}");
        // A folder that does not exist yet is made: nothing in it to refuse.
        let made = dir.path().join("new/deeper");
        assert_eq!(
            Guard::new("magcal-fit")
                .folder("--plots", Some(&made), &["readings.svg"], Replace::Products)
                .check(),
            Ok(())
        );
        let e = Guard::new("magcal-fit")
            .folder(
                "--plots",
                Some(&input),
                &["readings.svg"],
                Replace::Products,
            )
            .check()
            .unwrap_err();
        assert_eq!(e.why, Why::FolderIsFile);
        assert!(e.to_string().contains("names a directory"), "{e}");
    }
}
