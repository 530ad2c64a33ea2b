//! Issue 34, acceptance 2: every example of a tool's output in README.md and docs/*.md is the tool's real output.
//!
//! An example is a fenced block right after a marker line:
//!
//! ```text
//! <!-- example: magcal-fit ../shared/data/real/inria-nexus5/nexus5_nodist_AR.csv -->
//! <!-- example lines=2-6: magcal-fit ../shared/data/real/inria-nexus5/nexus5_nodist_AR.csv -->
//! <!-- example stream=stderr lines=5: magcal-fit ../shared/data/flight/px4-ulog/quadrotor_local.ulg -->
//! <!-- example lines=7-8: magcal-record --device sim:lis3mdl --routine cube24 --out rec.csv && magcal-fit rec.csv -->
//! <!-- example terminal lines=3-20: magcal-record --device sim:lis3mdl --routine free --out rec.csv -->
//! <!-- example mask=seconds: magcal-sim --out a.csv && magcal-batch a.csv --jobs 2 -->
//! ```
//!
//! - The commands (one or more, joined by ` && `; arguments split at spaces, `'…'` or `"…"` keep one together) run in
//!   order in a fresh temporary directory, so nothing is written into the repository; every command but the last must
//!   succeed, the last may fail (a refusal is an example too). An argument naming a file or folder of the repository
//!   (`../shared/…`, `fixtures/…`) is given to the tool as an absolute path, and the output has it back as written.
//! - The block holds the last command's standard output (`stream=stderr`: its standard error), with the temporary
//!   directory's path taken out, and without the final line end; `lines=A-B,C` keeps only those lines (1-based, both
//!   ends included), with a line `…` where lines were skipped between two ranges.
//! - `terminal` runs the last command on a pseudo-terminal of [`COLS`] columns and [`ROWS`] rows (its controlling
//!   terminal, `TERM=xterm-256color`, nothing typed), as a person's terminal runs it: the block holds the screen a
//!   terminal emulator (vt100) shows when it has exited — both streams, a live display redrawn in place as its last
//!   frame —, each row's trailing blanks and the empty rows at the end left out.
//! - `mask=seconds` is for output that states wall time, which no two runs share: every number directly followed by
//!   ` s` (`5.9 s`) is read as `_ s` when the block and the tool's output are compared (and when two runs are), so
//!   the block keeps the time of the run that last rewrote it.
//! - `heavy` marks an example too slow for the debug build: it is checked only by the ignored test
//!   `heavy_doc_examples_match_the_tools` (CI runs it in release).
//!
//! Each example runs twice and both runs must give the same text (masked). `MAGCAL_BLESS=1 cargo test --test doc_examples`
//! rewrites the blocks that differ (with `-- --ignored` for the heavy ones).

use std::fs::File;
use std::io::Read;
use std::num::NonZeroU16;
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use nix::pty::{Winsize, openpty};

/// The `terminal` examples' screen: columns.
const COLS: u16 = 100;
/// The `terminal` examples' screen: rows (enough that nothing scrolls off).
const ROWS: u16 = 200;
/// How long a `terminal` example may run before it is stopped (and fails).
const TERMINAL_TIMEOUT: Duration = Duration::from_secs(300);

/// Held while a test checks or rewrites the documents, so two tests never rewrite one file at once.
static DOCUMENTS: Mutex<()> = Mutex::new(());

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md and every Markdown file under docs/ (sorted, so the failures come in a stable order).
fn documents() -> Vec<PathBuf> {
    let mut files = vec![root().join("README.md")];
    let mut dirs = vec![root().join("docs")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "md") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Which output of the last command the block holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stream {
    Stdout,
    Stderr,
}

/// What of an example's output is left out when it is compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mask {
    /// Numbers of seconds (`5.9 s`): wall time.
    Seconds,
}

/// What a marker line says.
#[derive(Debug)]
struct Marker {
    stream: Stream,
    /// Ranges of lines kept, 1-based, inclusive; empty: all.
    lines: Vec<(usize, usize)>,
    heavy: bool,
    /// The last command runs on a pseudo-terminal; the block is its screen.
    terminal: bool,
    mask: Option<Mask>,
    /// The commands, each a tool and its arguments.
    commands: Vec<Vec<String>>,
}

/// One marker and its block.
#[derive(Debug)]
struct Example {
    /// The marker's line, 1-based (for messages).
    marker_line: usize,
    /// The block's first line of content, 0-based index into the file's lines.
    body_start: usize,
    /// The closing fence, 0-based index into the file's lines.
    body_end: usize,
    marker: Marker,
}

/// Splits a command line at spaces; `'…'` and `"…"` keep spaces inside one argument.
fn split_args(text: &str) -> Result<Vec<String>, String> {
    let mut args = Vec::new();
    let mut current = String::new();
    let mut in_arg = false;
    let mut quote: Option<char> = None;
    for c in text.chars() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => current.push(c),
            None if c == '\'' || c == '"' => {
                quote = Some(c);
                in_arg = true;
            }
            None if c.is_whitespace() => {
                if in_arg {
                    args.push(std::mem::take(&mut current));
                    in_arg = false;
                }
            }
            None => {
                current.push(c);
                in_arg = true;
            }
        }
    }
    if quote.is_some() {
        return Err(format!("an unclosed quote in {text:?}"));
    }
    if in_arg {
        args.push(current);
    }
    Ok(args)
}

/// `1-6,9` → `[(1, 6), (9, 9)]`.
fn parse_lines(text: &str) -> Result<Vec<(usize, usize)>, String> {
    let mut ranges = Vec::new();
    for part in text.split(',') {
        let (a, b) = part.split_once('-').unwrap_or((part, part));
        let a: usize = a.parse().map_err(|_| format!("lines={text}: {a:?}"))?;
        let b: usize = b.parse().map_err(|_| format!("lines={text}: {b:?}"))?;
        if a == 0 || b < a || ranges.last().is_some_and(|&(_, end)| a <= end) {
            return Err(format!(
                "lines={text}: ranges are 1-based, increasing and apart"
            ));
        }
        ranges.push((a, b));
    }
    Ok(ranges)
}

/// Parses one marker's content (between `<!-- example` and `-->`).
fn parse_marker(content: &str) -> Result<Marker, String> {
    let (options, command) = content
        .split_once(": ")
        .ok_or("no ': ' before the command")?;
    let mut stream = Stream::Stdout;
    let mut lines = Vec::new();
    let mut heavy = false;
    let mut terminal = false;
    let mut mask = None;
    for option in options.split_whitespace() {
        match option.split_once('=') {
            Some(("stream", "stdout")) => stream = Stream::Stdout,
            Some(("stream", "stderr")) => stream = Stream::Stderr,
            Some(("lines", ranges)) => lines = parse_lines(ranges)?,
            Some(("mask", "seconds")) => mask = Some(Mask::Seconds),
            None if option == "heavy" => heavy = true,
            None if option == "terminal" => terminal = true,
            _ => {
                return Err(format!(
                    "unknown option {option:?} (known: stream=stdout|stderr, lines=A-B,C, heavy, terminal, \
                     mask=seconds)"
                ));
            }
        }
    }
    if terminal && stream == Stream::Stderr {
        return Err("stream=stderr with terminal: a terminal shows both streams".into());
    }
    let mut commands = vec![Vec::new()];
    for arg in split_args(command)? {
        if arg == "&&" {
            commands.push(Vec::new());
        } else {
            commands.last_mut().unwrap().push(arg);
        }
    }
    if commands.iter().any(Vec::is_empty) {
        return Err("an empty command".into());
    }
    Ok(Marker {
        stream,
        lines,
        heavy,
        terminal,
        mask,
        commands,
    })
}

/// The examples of one document's text; an error names the line.
fn examples(text: &str) -> Result<Vec<Example>, String> {
    let lines: Vec<&str> = text.split('\n').collect();
    let mut found = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim();
        let Some(content) = line.strip_prefix("<!-- example") else {
            i += 1;
            continue;
        };
        let at = |message: String| format!("line {}: {message}", i + 1);
        let content = content
            .strip_suffix("-->")
            .ok_or_else(|| at("the marker does not end with --> on its line".into()))?;
        let marker = parse_marker(content.trim()).map_err(at)?;
        if !lines.get(i + 1).is_some_and(|l| l.starts_with("```")) {
            return Err(at("no fenced block (```) right after the marker".into()));
        }
        let end = (i + 2..lines.len())
            .find(|&j| lines[j].trim_end() == "```")
            .ok_or_else(|| at("the block after the marker is never closed".into()))?;
        found.push(Example {
            marker_line: i + 1,
            body_start: i + 2,
            body_end: end,
            marker,
        });
        i = end + 1;
    }
    Ok(found)
}

/// The built binary of a tool.
fn tool(name: &str) -> Option<&'static str> {
    Some(match name {
        "magcal" => env!("CARGO_BIN_EXE_magcal"),
        "magcal-fit" => env!("CARGO_BIN_EXE_magcal-fit"),
        "magcal-apply" => env!("CARGO_BIN_EXE_magcal-apply"),
        "magcal-sim" => env!("CARGO_BIN_EXE_magcal-sim"),
        "magcal-record" => env!("CARGO_BIN_EXE_magcal-record"),
        "magcal-batch" => env!("CARGO_BIN_EXE_magcal-batch"),
        "magcal-paper" => env!("CARGO_BIN_EXE_magcal-paper"),
        _ => return None,
    })
}

/// Runs an example's commands in a fresh temporary directory and returns the text its block should hold.
fn run(example: &Marker) -> Result<String, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let mut replacements: Vec<(String, String)> = Vec::new();
    let mut last = None;
    for (n, command) in example.commands.iter().enumerate() {
        let program =
            tool(&command[0]).ok_or_else(|| format!("{:?} is not one of the tools", command[0]))?;
        let args: Vec<String> = command[1..]
            .iter()
            .map(|arg| {
                let in_repo = root().join(arg);
                if arg.contains('/') && !arg.starts_with('/') && in_repo.exists() {
                    let absolute = in_repo.to_string_lossy().into_owned();
                    replacements.push((absolute.clone(), arg.clone()));
                    absolute
                } else {
                    arg.clone()
                }
            })
            .collect();
        let last_one = n + 1 == example.commands.len();
        let out = if example.terminal && last_one {
            on_terminal(program, &args, dir.path())
        } else {
            Command::new(program)
                .args(&args)
                .current_dir(dir.path())
                .env_remove("MAGCAL_BLESS")
                .output()
                .map_err(|e| e.to_string())
        }
        .map_err(|e| format!("{} does not run: {e}", command[0]))?;
        if n + 1 < example.commands.len() && !out.status.success() {
            return Err(format!(
                "{} failed:\n{}",
                command.join(" "),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        last = Some(out);
    }
    let out = last.expect("at least one command");
    let bytes = match example.stream {
        Stream::Stdout => out.stdout,
        Stream::Stderr => out.stderr,
    };
    let mut text = String::from_utf8_lossy(&bytes).into_owned();
    // The longest paths first, so that one path inside another is put back whole.
    replacements.sort_by_key(|(absolute, _)| std::cmp::Reverse(absolute.len()));
    for (absolute, written) in &replacements {
        text = text.replace(absolute.as_str(), written);
    }
    for temp in [
        Some(dir.path().to_path_buf()),
        dir.path().canonicalize().ok(),
    ]
    .into_iter()
    .flatten()
    {
        let temp = temp.to_string_lossy().into_owned();
        text = text.replace(&format!("{temp}/"), "").replace(&temp, ".");
    }
    let all: Vec<&str> = text
        .strip_suffix('\n')
        .unwrap_or(&text)
        .split('\n')
        .collect();
    if example.lines.is_empty() {
        return Ok(all.join("\n"));
    }
    let mut kept: Vec<&str> = Vec::new();
    for (k, &(a, b)) in example.lines.iter().enumerate() {
        if b > all.len() {
            return Err(format!(
                "lines {a}-{b} asked for, the output has {} lines:\n{text}",
                all.len()
            ));
        }
        if k > 0 && example.lines[k - 1].1 + 1 < a {
            kept.push("…");
        }
        kept.extend_from_slice(&all[a - 1..b]);
    }
    Ok(kept.join("\n"))
}

/// Runs `program ARGS` in `dir` on a new pseudo-terminal (its controlling terminal, through `setsid -c`) until it
/// exits, and returns its status with the screen a terminal emulator shows then as its standard output.
fn on_terminal(program: &str, args: &[String], dir: &Path) -> Result<Output, String> {
    let size = Winsize {
        ws_row: ROWS,
        ws_col: COLS,
        ws_xpixel: 0,
        ws_ypixel: 0,
    };
    let pty = openpty(Some(&size), None).map_err(|e| format!("openpty: {e}"))?;
    let slave = |pty: &OwnedFd| pty.try_clone().map(Stdio::from).map_err(|e| e.to_string());
    let mut child = Command::new("setsid")
        .arg("-c")
        .arg(program)
        .args(args)
        .current_dir(dir)
        .env_remove("MAGCAL_BLESS")
        .env("TERM", "xterm-256color")
        .stdin(slave(&pty.slave)?)
        .stdout(slave(&pty.slave)?)
        .stderr(slave(&pty.slave)?)
        .spawn()
        .map_err(|e| format!("setsid (util-linux): {e}"))?;
    drop(pty.slave);
    let mut master = File::from(pty.master);
    // Read while it runs (a full pseudo-terminal would block it); ends with an error (EIO) once its side is closed.
    let reader = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let mut buf = [0u8; 4096];
        while let Ok(n) = master.read(&mut buf) {
            if n == 0 {
                break;
            }
            bytes.extend_from_slice(&buf[..n]);
        }
        bytes
    });
    let deadline = Instant::now() + TERMINAL_TIMEOUT;
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("still running after {TERMINAL_TIMEOUT:?}"));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let bytes = reader.join().map_err(|_| "the reader panicked")?;
    let cells = |n| NonZeroU16::new(n).expect("a screen of some size");
    let mut parser = vt100::Parser::new(cells(ROWS), cells(COLS), 0);
    parser.process(&bytes);
    let mut rows: Vec<String> = parser
        .screen()
        .rows(0, COLS)
        .map(|r| r.trim_end().to_owned())
        .collect();
    while rows.last().is_some_and(String::is_empty) {
        rows.pop();
    }
    Ok(Output {
        status,
        stdout: (rows.join("\n") + "\n").into_bytes(),
        stderr: Vec::new(),
    })
}

/// `text` as it is compared under `mask`: with `Seconds`, every number directly followed by ` s` (and no letter
/// after it) reads `_ s`.
fn masked(text: &str, mask: Option<Mask>) -> String {
    let Some(Mask::Seconds) = mask else {
        return text.to_owned();
    };
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < chars.len() {
        let number_starts =
            chars[i].is_ascii_digit() && (i == 0 || !chars[i - 1].is_alphanumeric());
        if number_starts {
            let mut j = i;
            while j < chars.len() && (chars[j].is_ascii_digit() || chars[j] == '.') {
                j += 1;
            }
            let seconds = chars.get(j) == Some(&' ')
                && chars.get(j + 1) == Some(&'s')
                && !chars.get(j + 2).is_some_and(|c| c.is_alphanumeric());
            if seconds {
                out.push('_');
            } else {
                out.extend(&chars[i..j]);
            }
            i = j;
        } else if chars[i].is_alphanumeric() {
            // A word (`v2.5`) is kept whole: a number inside it is no number of seconds.
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '.') {
                out.push(chars[i]);
                i += 1;
            }
        } else {
            out.push(chars[i]);
            i += 1;
        }
    }
    out
}

/// A line diff of `expected` (the block) against `actual` (the tool's), by their longest common subsequence.
fn diff(expected: &str, actual: &str) -> String {
    let a: Vec<&str> = expected.split('\n').collect();
    let b: Vec<&str> = actual.split('\n').collect();
    let mut common = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for i in (0..a.len()).rev() {
        for j in (0..b.len()).rev() {
            common[i][j] = if a[i] == b[j] {
                common[i + 1][j + 1] + 1
            } else {
                common[i + 1][j].max(common[i][j + 1])
            };
        }
    }
    let (mut i, mut j) = (0, 0);
    let mut out = String::new();
    while i < a.len() || j < b.len() {
        if i < a.len() && j < b.len() && a[i] == b[j] {
            out += &format!("   {}\n", a[i]);
            i += 1;
            j += 1;
        } else if i < a.len() && (j == b.len() || common[i + 1][j] >= common[i][j + 1]) {
            out += &format!(" - {}\n", a[i]);
            i += 1;
        } else {
            out += &format!(" + {}\n", b[j]);
            j += 1;
        }
    }
    out
}

/// Checks (or, with `MAGCAL_BLESS=1`, rewrites) every example that is `heavy` or not as asked; returns how many it
/// ran.
fn check(heavy: bool) -> usize {
    let _documents = DOCUMENTS.lock().unwrap_or_else(|e| e.into_inner());
    let bless = std::env::var("MAGCAL_BLESS").is_ok_and(|v| v == "1");
    let mut failures = Vec::new();
    let mut ran = 0;
    for file in documents() {
        let name = file.strip_prefix(root()).unwrap().display().to_string();
        let text = std::fs::read_to_string(&file).unwrap();
        let found = examples(&text).unwrap_or_else(|e| panic!("{name}:{e}"));
        let mut lines: Vec<String> = text.split('\n').map(str::to_owned).collect();
        let mut changed = false;
        // From the last, so that a rewritten block does not move the ones before it.
        for example in found.iter().rev().filter(|e| e.marker.heavy == heavy) {
            ran += 1;
            let place = format!("{name}:{}", example.marker_line);
            let actual = match run(&example.marker) {
                Ok(actual) => actual,
                Err(e) => {
                    failures.push(format!("{place}: {e}"));
                    continue;
                }
            };
            let mask = example.marker.mask;
            match run(&example.marker) {
                Ok(again) if masked(&again, mask) == masked(&actual, mask) => {}
                Ok(again) => {
                    failures.push(format!(
                        "{place}: two runs differ (the example must be deterministic):\n{}",
                        diff(&actual, &again)
                    ));
                    continue;
                }
                Err(e) => {
                    failures.push(format!("{place}: the second run: {e}"));
                    continue;
                }
            }
            let block = lines[example.body_start..example.body_end].join("\n");
            if masked(&block, mask) == masked(&actual, mask) {
                continue;
            }
            if bless {
                lines.splice(
                    example.body_start..example.body_end,
                    actual.split('\n').map(str::to_owned),
                );
                changed = true;
            } else {
                failures.push(format!(
                    "{place}: the block differs from the tool's output (- the block, + the tool; \
                     MAGCAL_BLESS=1 cargo test --test doc_examples rewrites it):\n{}",
                    diff(&block, &actual)
                ));
            }
        }
        if changed {
            std::fs::write(&file, lines.join("\n")).unwrap();
        }
    }
    assert!(
        failures.is_empty(),
        "{} example(s) in the docs do not match:\n\n{}",
        failures.len(),
        failures.join("\n")
    );
    ran
}

#[test]
fn doc_examples_match_the_tools() {
    let ran = check(false);
    assert!(ran >= 6, "only {ran} examples found in README.md and docs/");
}

#[test]
#[ignore = "the examples marked heavy: run in release"]
fn heavy_doc_examples_match_the_tools() {
    check(true);
}

#[test]
fn markers_are_read_as_documented() {
    let text = "a\n<!-- example stream=stderr lines=1-2,5: magcal-fit '../a b.csv' --x && magcal-apply p.toml r.csv -->\n```text\nold\n```\n";
    let found = examples(text).unwrap();
    assert_eq!(found.len(), 1);
    let e = &found[0];
    let m = &e.marker;
    assert_eq!((e.marker_line, e.body_start, e.body_end), (2, 3, 4));
    assert_eq!(m.stream, Stream::Stderr);
    assert_eq!(m.lines, [(1, 2), (5, 5)]);
    assert!(!m.heavy && !m.terminal && m.mask.is_none());
    assert_eq!(
        m.commands,
        [
            vec!["magcal-fit", "../a b.csv", "--x"],
            vec!["magcal-apply", "p.toml", "r.csv"]
        ]
    );
    for (bad, says) in [
        ("<!-- example: magcal-fit x -->\ntext\n", "no fenced block"),
        ("<!-- example: magcal-fit x -->\n```\nx\n", "never closed"),
        (
            "<!-- example lines=3-1: magcal-fit x -->\n```\n```\n",
            "1-based",
        ),
        (
            "<!-- example fast: magcal-fit x -->\n```\n```\n",
            "unknown option",
        ),
        ("<!-- example magcal-fit x -->\n```\n```\n", "no ': '"),
        (
            "<!-- example mask=minutes: magcal-fit x -->\n```\n```\n",
            "unknown option",
        ),
        (
            "<!-- example terminal stream=stderr: magcal-fit x -->\n```\n```\n",
            "both streams",
        ),
    ] {
        let error = examples(bad).unwrap_err();
        assert!(
            error.starts_with("line 1: ") && error.contains(says),
            "{error}"
        );
    }
}

#[test]
fn terminal_and_masked_markers_are_read_and_seconds_masked() {
    let text =
        "<!-- example terminal mask=seconds lines=2-4: magcal-record --out r.csv -->\n```\n```\n";
    let m = &examples(text).unwrap()[0].marker;
    assert!(m.terminal && m.mask == Some(Mask::Seconds));
    assert_eq!(
        masked(
            "(2 at a time, 5.9 s): 12 boards; 64.2 s, 5135 samples; 3 sensors, v2.5 s",
            Some(Mask::Seconds)
        ),
        "(2 at a time, _ s): 12 boards; _ s, 5135 samples; 3 sensors, v2.5 s"
    );
    assert_eq!(masked("5.9 s", None), "5.9 s");
}

#[test]
fn a_difference_is_shown_line_by_line() {
    assert_eq!(diff("a\nb\nc", "a\nB\nc"), "   a\n - b\n + B\n   c\n");
}
