//! Acceptance (issue 33, items 2 and 3): every option of every tool that names a path is known to the one output
//! guard (`magcal_app::outputs::OPTIONS`), read from each tool's `--help`, so that a new option cannot bypass it;
//! each output, aimed at a recording, is refused; and, for random combinations of tool, output option, link
//! (none, hard, symbolic, through `..`) and what the file holds (a recording, parameters, a compressed recording,
//! other text), no recording's bytes change unless `--force` names that exact path.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use magcal_app::outputs::{OPTIONS, Role};
use proptest::prelude::*;

/// Each tool and its binary.
const TOOLS: [(&str, &str); 7] = [
    ("magcal", env!("CARGO_BIN_EXE_magcal")),
    ("magcal-batch", env!("CARGO_BIN_EXE_magcal-batch")),
    ("magcal-fit", env!("CARGO_BIN_EXE_magcal-fit")),
    ("magcal-apply", env!("CARGO_BIN_EXE_magcal-apply")),
    ("magcal-record", env!("CARGO_BIN_EXE_magcal-record")),
    ("magcal-sim", env!("CARGO_BIN_EXE_magcal-sim")),
    ("magcal-paper", env!("CARGO_BIN_EXE_magcal-paper")),
];

/// Value names (as `--help` shows them) of what is no file: numbers, lists of them, choices, devices, specs.
const NOT_PATHS: [&str; 31] = [
    "DEV",
    "ID",
    "KIND",
    "ROUTINE",
    "N,E,D",
    "LAT,LON,ALT",
    "YYYY-MM-DD",
    "N",
    "METHOD",
    "UT",
    "EXPORT",
    "GRADE",
    "FRACTION",
    "S",
    "HZ",
    "FAULT",
    "CHIP",
    "DURATION",
    "RATE",
    "SEED",
    "NOISE",
    "SOFT,HARD,MOUNT",
    "REFERENCE",
    "GYRO_NOISE",
    "START,RISE,TAU,WOBBLE,PERIOD",
    "NAME:ON_A,MEAN_ON_S,MEAN_OFF_S",
    "SPEC",
    "ID:SIZE_UT",
    "MOUNT_DEG",
    "CHIP[:SETTING]",
    "DEG",
];

fn binary(tool: &str) -> &'static str {
    TOOLS.iter().find(|(t, _)| *t == tool).unwrap().1
}

fn run(tool: &str, args: &[&str]) -> Output {
    Command::new(binary(tool))
        .args(args)
        .output()
        .expect("the tool runs")
}

/// The options of a tool's `--help` that take a value, with the value's name, and its positional arguments (by
/// their value name, e.g. `<RECORDING>`, with none).
fn value_options(tool: &str) -> Vec<(String, Option<String>)> {
    let help = String::from_utf8(run(tool, &["--help"]).stdout).unwrap();
    let mut found = Vec::new();
    let mut in_section = false;
    for line in help.lines() {
        if matches!(line, "Arguments:" | "Options:") {
            in_section = true;
            continue;
        }
        if !line.is_empty() && !line.starts_with(' ') {
            in_section = false;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        if !in_section || words.is_empty() {
            continue;
        }
        if words[0].starts_with('<') {
            found.push((words[0].to_owned(), None));
            continue;
        }
        let at = usize::from(words[0].starts_with("-") && !words[0].starts_with("--"));
        let (Some(option), Some(value)) = (words.get(at), words.get(at + 1)) else {
            continue;
        };
        if option.starts_with("--") && value.starts_with('<') {
            let name = value.trim_start_matches('<').trim_end_matches('>');
            found.push(((*option).to_owned(), Some(name.to_owned())));
        }
    }
    found
}

#[test]
fn every_option_of_every_tool_that_takes_a_path_is_known_to_the_guard() {
    for (tool, _) in TOOLS {
        let options = value_options(tool);
        assert!(
            !options.is_empty() || tool == "magcal-paper",
            "{tool}: no options read from --help"
        );
        for (option, value) in &options {
            let is_path = value.as_deref().is_none_or(|v| !NOT_PATHS.contains(&v));
            if is_path {
                assert!(
                    OPTIONS.iter().any(|(t, o, _)| *t == tool && o == option),
                    "{tool} {option} <{value:?}> names a path and is not in magcal_app::outputs::OPTIONS: route it \
                     through the guard (or, if it names no file, add its value name to NOT_PATHS)"
                );
            }
        }
        for (t, option, _) in OPTIONS.iter().filter(|(t, _, _)| *t == tool) {
            assert!(
                options.iter().any(|(o, _)| o == option),
                "{t} {option} is in OPTIONS but not in its --help"
            );
        }
    }
}

/// A recording as a recorder writes one (no key a tool may remake it by).
const RECORDING: &str =
    "# magcal-recording v1\n# sensor: lis3mdl\nt,mx,my,mz\n0.00,12.3,-3.2,40.1\n";

/// The inputs the tools that fit and apply read: a simulated recording, and parameters fitted to it.
struct Inputs {
    dir: tempfile::TempDir,
    rec: PathBuf,
    params: PathBuf,
}

impl Inputs {
    fn new() -> Inputs {
        let dir = tempfile::tempdir().unwrap();
        let rec = dir.path().join("input.csv");
        let out = run(
            "magcal-sim",
            &["--duration", "30", "--out", rec.to_str().unwrap()],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let params = dir.path().join("input.toml");
        let out = run(
            "magcal-fit",
            &[
                rec.to_str().unwrap(),
                "--no-diagnose",
                "--out",
                params.to_str().unwrap(),
            ],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        Inputs { dir, rec, params }
    }

    /// The bytes of the inputs, to check that no run changed them.
    fn bytes(&self) -> (Vec<u8>, Vec<u8>) {
        (
            std::fs::read(&self.rec).unwrap(),
            std::fs::read(&self.params).unwrap(),
        )
    }
}

/// The file an output option writes when given `path` (for a folder option: which of its files is aimed at).
fn aimed(tool: &str, option: &str) -> Option<&'static str> {
    match (tool, option) {
        ("magcal", "--out-dir") => Some("params.toml"),
        ("magcal-fit", "--plots") => Some("readings.svg"),
        _ => None,
    }
}

/// The arguments of a run of `tool` with the output `option` given `value` (and `--force`), the rest minimal;
/// `fresh` is a folder for the other outputs a run needs.
fn arguments(
    tool: &str,
    option: &str,
    value: &str,
    force: bool,
    inputs: &Inputs,
    fresh: &Path,
) -> Vec<String> {
    let rec = inputs.rec.to_str().unwrap().to_owned();
    let params = inputs.params.to_str().unwrap().to_owned();
    let other = |name: &str| fresh.join(name).to_str().unwrap().to_owned();
    let mut args: Vec<String> = match (tool, option) {
        ("magcal", "--out-dir") => vec![],
        ("magcal-fit", "--export-out") => vec![
            rec,
            "--no-diagnose".into(),
            "--export".into(),
            "json".into(),
        ],
        ("magcal-fit", "--undo-out") => vec![
            rec,
            "--no-diagnose".into(),
            "--write-to".into(),
            "mavlink:/dev/null".into(),
        ],
        ("magcal-fit", _) => vec![rec, "--no-diagnose".into()],
        ("magcal-apply", "--out") => vec![params, rec],
        ("magcal-batch", _) => vec![rec, "--no-diagnose".into()],
        ("magcal-record", "--out") => vec![
            "--routine".into(),
            "free".into(),
            "--max-duration".into(),
            "1".into(),
        ],
        ("magcal-record", "--truth") => {
            let mut a: Vec<String> = ["--routine", "free", "--max-duration", "1", "--out"]
                .map(String::from)
                .into();
            a.push(other("new.csv"));
            a
        }
        ("magcal-sim", "--out") => vec!["--duration".into(), "2".into()],
        ("magcal-sim", "--truth") => vec![
            "--duration".into(),
            "2".into(),
            "--out".into(),
            other("new.csv"),
        ],
        _ => panic!("{tool} {option}: an output this test does not know how to run: add it here"),
    };
    args.extend([option.to_owned(), value.to_owned()]);
    if force && matches!(tool, "magcal" | "magcal-record") {
        args.push("--force".into());
    }
    args
}

/// The outputs the guard knows.
fn outputs() -> Vec<(&'static str, &'static str)> {
    OPTIONS
        .iter()
        .filter(|(_, _, role)| *role == Role::Output)
        .map(|(t, o, _)| (*t, *o))
        .collect()
}

#[test]
fn every_output_aimed_at_a_recording_is_refused() {
    let inputs = Inputs::new();
    let before = inputs.bytes();
    for (tool, option) in outputs() {
        for force in [false, true] {
            let dir = tempfile::tempdir().unwrap();
            let (value, target) = match aimed(tool, option) {
                Some(name) => (dir.path().to_owned(), dir.path().join(name)),
                None => (dir.path().join("rec.csv"), dir.path().join("rec.csv")),
            };
            std::fs::write(&target, RECORDING).unwrap();
            let args = arguments(
                tool,
                option,
                value.to_str().unwrap(),
                force,
                &inputs,
                dir.path(),
            );
            let out = Command::new(binary(tool)).args(&args).output().unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            let replaced_on_request = force && tool == "magcal-record" && option == "--out";
            assert_eq!(
                out.status.success(),
                replaced_on_request,
                "{tool} {args:?}: {err}"
            );
            if replaced_on_request {
                continue;
            }
            assert!(
                err.contains("holds a recording") && err.contains(option),
                "{tool} {args:?}: {err}"
            );
            assert_eq!(
                std::fs::read_to_string(&target).unwrap(),
                RECORDING,
                "{tool} {args:?}"
            );
        }
    }
    assert_eq!(inputs.bytes(), before, "an input changed");
}

/// How the output's path reaches the existing file.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Link {
    /// It is the file's own path.
    None,
    /// Another name of the file.
    Hard,
    /// A symbolic link to it.
    Symbolic,
    /// Its own path, through a folder and `..`.
    DotDot,
}

/// What the existing file holds.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Content {
    Recording,
    Params,
    CompressedRecording,
    Other,
}

impl Content {
    fn bytes(self) -> Vec<u8> {
        match self {
            Content::Recording => RECORDING.as_bytes().to_vec(),
            Content::Params => b"format = \"magcal-params v1\"\n".to_vec(),
            // A gzip member's header and a stored block of the recording (what the probe looks at is the magic).
            Content::CompressedRecording => {
                let mut b = vec![0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3, 1];
                let n = RECORDING.len() as u16;
                b.extend(n.to_le_bytes());
                b.extend((!n).to_le_bytes());
                b.extend(RECORDING.as_bytes());
                b
            }
            Content::Other => b"notes of the bench\n".to_vec(),
        }
    }

    fn is_recording(self) -> bool {
        matches!(self, Content::Recording | Content::CompressedRecording)
    }
}

/// Lays out one case in `dir`: the existing file with `content`, and the path the option is given so that it reaches
/// it by `link`. Returns the option's value and the existing file's path.
fn lay_out(
    dir: &Path,
    tool: &str,
    option: &str,
    link: Link,
    content: Content,
) -> (PathBuf, PathBuf) {
    let elsewhere = dir.join("existing");
    let (folder, name) = match aimed(tool, option) {
        Some(name) => (dir.join("out"), name),
        None => (dir.to_owned(), "out.csv"),
    };
    std::fs::create_dir_all(folder.join("sub")).unwrap();
    let named = folder.join(name);
    let existing = match link {
        Link::None | Link::DotDot => named.clone(),
        Link::Hard | Link::Symbolic => elsewhere,
    };
    std::fs::write(&existing, content.bytes()).unwrap();
    match link {
        Link::Hard => std::fs::hard_link(&existing, &named).unwrap(),
        Link::Symbolic => std::os::unix::fs::symlink(&existing, &named).unwrap(),
        Link::None | Link::DotDot => {}
    }
    let value = match (aimed(tool, option), link) {
        (Some(_), Link::DotDot) => folder.join("sub/.."),
        (Some(_), _) => folder,
        (None, Link::DotDot) => folder.join("sub/..").join(name),
        (None, _) => named,
    };
    (value, existing)
}

fn link() -> impl Strategy<Value = Link> {
    prop_oneof![
        Just(Link::None),
        Just(Link::Hard),
        Just(Link::Symbolic),
        Just(Link::DotDot)
    ]
}

fn content() -> impl Strategy<Value = Content> {
    prop_oneof![
        Just(Content::Recording),
        Just(Content::Params),
        Just(Content::CompressedRecording),
        Just(Content::Other)
    ]
}

proptest! {
    // Each case runs a tool: a few dozen keep `cargo test` fast.
    #![proptest_config(ProptestConfig { cases: 40, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn no_recording_changes_unless_force_names_its_exact_path(
        which in 0..outputs().len(),
        link in link(),
        content in content(),
        force in any::<bool>(),
    ) {
        let inputs = Inputs::new();
        let before = inputs.bytes();
        let (tool, option) = outputs()[which];
        let dir = tempfile::tempdir().unwrap();
        let (value, existing) = lay_out(dir.path(), tool, option, link, content);
        let fresh = tempfile::tempdir().unwrap();
        let args = arguments(tool, option, value.to_str().unwrap(), force, &inputs, fresh.path());
        let out = Command::new(binary(tool)).args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        prop_assert!(!err.contains("panicked"), "{}", err);
        // --force names the recording's path for the recorder's own output only: its --out, magcal's recording.csv.
        let forced_here = force
            && matches!((tool, option), ("magcal-record", "--out"))
            && matches!(link, Link::None | Link::DotDot);
        if content.is_recording() && !forced_here {
            prop_assert_eq!(
                std::fs::read(&existing).unwrap(),
                content.bytes(),
                "{} {:?} changed a recording: {}", tool, args, err
            );
        }
        prop_assert_eq!(inputs.bytes(), before, "an input changed");
        drop(inputs.dir);
    }
}
