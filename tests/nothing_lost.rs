//! Acceptance (issue 33, "Nothing lost, second round"): one test per row of the table, each table-driven over
//! its cases, each failing on the tools before the fix. The recorder's rows run through the simulated chips
//! (`--sim-fault`), the serial rows through the pseudo-terminal firmware twin.
//!
//! `MAGCAL_TEST_BIN_DIR` runs the tests against the tools in another folder (the release build of the commit before
//! the fix, say) instead of this build's.

mod pty;

use std::io::{BufRead, BufReader, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use magcal_app::source::sim::bench_config;
use magcal_driver::ChipKind;
use magcal_mockhw::firmware::{BoardFault, FirmwareConfig, Output as BoardOutput};
use magcal_recording::Recording;

/// A tool of this build, or of `MAGCAL_TEST_BIN_DIR`.
fn bin(tool: &str) -> PathBuf {
    if let Some(dir) = std::env::var_os("MAGCAL_TEST_BIN_DIR") {
        return Path::new(&dir).join(tool);
    }
    PathBuf::from(match tool {
        "magcal" => env!("CARGO_BIN_EXE_magcal"),
        "magcal-fit" => env!("CARGO_BIN_EXE_magcal-fit"),
        "magcal-apply" => env!("CARGO_BIN_EXE_magcal-apply"),
        "magcal-record" => env!("CARGO_BIN_EXE_magcal-record"),
        "magcal-sim" => env!("CARGO_BIN_EXE_magcal-sim"),
        "magcal-paper" => env!("CARGO_BIN_EXE_magcal-paper"),
        _ => panic!("no tool {tool}"),
    })
}

/// Runs `tool args` to its end, at most `limit_s`, in a shell with these limits (`ulimit …; `), stdin closed.
fn run_limited(limits: &str, tool: &str, args: &[&str], limit_s: f64) -> Output {
    let mut script = format!("{limits} exec '{}'", bin(tool).display());
    for a in args {
        script += &format!(" '{}'", a.replace('\'', "'\\''"));
    }
    let child = Command::new("bash")
        .args(["-c", &script])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    finish_within(child, limit_s)
}

/// Runs `tool args` to its end (at most two minutes).
fn run(tool: &str, args: &[&str]) -> Output {
    run_limited("", tool, args, 120.0)
}

/// Waits for `child` at most `limit_s`, killing it then (a tool that hangs fails its test instead of hanging it).
fn finish_within(mut child: Child, limit_s: f64) -> Output {
    let deadline = Instant::now() + Duration::from_secs_f64(limit_s);
    let drain = |r: Option<Box<dyn std::io::Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut r) = r {
                let _ = r.read_to_end(&mut bytes);
            }
            bytes
        })
    };
    let stdout = drain(child.stdout.take().map(|s| Box::new(s) as _));
    let stderr = drain(child.stderr.take().map(|s| Box::new(s) as _));
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            child.kill().unwrap();
            break child.wait().unwrap();
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Output {
        status,
        stdout: stdout.join().unwrap(),
        stderr: stderr.join().unwrap(),
    }
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A recording as the recorder writes one (a real chip's: no key a tool may remake it by).
const RECORDING: &str = "# magcal-recording v1\n# sensor: lis3mdl\n# device: i2c:/dev/i2c-1:lis3mdl\nt,mx,my,mz\n\
                         0.00,12.3,-3.2,40.1\n0.01,12.4,-3.1,40.0\n";
/// A parameters file, as magcal-fit writes one (shortened).
const PARAMS: &str = "# magcal calibration parameters\nformat = \"magcal-params v1\"\n";

/// `text` in gzip, stored uncompressed (a valid file `gunzip` reads).
fn gzip(text: &[u8]) -> Vec<u8> {
    let crc = text.iter().fold(!0u32, |mut c, b| {
        c ^= u32::from(*b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
        c
    }) ^ !0;
    let mut out = vec![0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3];
    let len = text.len() as u16;
    out.push(1);
    out.extend(len.to_le_bytes());
    out.extend((!len).to_le_bytes());
    out.extend(text);
    out.extend(crc.to_le_bytes());
    out.extend((text.len() as u32).to_le_bytes());
    out
}

/// `text` in UTF-16 (little-endian, with its byte order mark), as a Windows editor saves it.
fn utf16(text: &str) -> Vec<u8> {
    let mut out = vec![0xff, 0xfe];
    out.extend(text.encode_utf16().flat_map(u16::to_le_bytes));
    out
}

/// A simulated recording, `seconds` long, made with magcal-sim (its own: magcal-sim may make it again).
fn simulated(dir: &Path, name: &str, seconds: &str) -> PathBuf {
    let path = dir.join(name);
    let out = run(
        "magcal-sim",
        &["--duration", seconds, "--out", path.to_str().unwrap()],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    path
}

/// A parameters file fitted to `rec`.
fn fitted(rec: &Path, dir: &Path) -> PathBuf {
    let params = dir.join("fitted.toml");
    let out = run(
        "magcal-fit",
        &[
            rec.to_str().unwrap(),
            "--no-diagnose",
            "--out",
            params.to_str().unwrap(),
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    params
}

/// The files in `dir` whose names end `.tmp` (temporary files left behind).
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect()
}

/// Row 1: `magcal-record --truth` goes through the one guard: never a recording or a parameters file without
/// `--force`, never the recording's own path.
#[test]
fn row01_every_output_of_the_recorder_goes_through_the_guard() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_owned();
    std::fs::write(p("rec.csv"), RECORDING).unwrap();
    std::fs::write(p("params.toml"), PARAMS).unwrap();
    // (the options, what stderr says, whether it may succeed, the file that must keep its bytes)
    let cases: [(Vec<String>, &str, bool, &str); 5] = [
        (
            vec![
                "--out".into(),
                p("new1.csv"),
                "--truth".into(),
                p("rec.csv"),
            ],
            "--truth",
            false,
            "rec.csv",
        ),
        (
            vec![
                "--out".into(),
                p("new2.csv"),
                "--truth".into(),
                p("params.toml"),
            ],
            "add --force",
            false,
            "params.toml",
        ),
        (
            vec![
                "--out".into(),
                p("new3.csv"),
                "--truth".into(),
                p("rec.csv"),
                "--force".into(),
            ],
            "holds a recording",
            false,
            "rec.csv",
        ),
        (
            vec!["--out".into(), p("x.csv"), "--truth".into(), p("x.csv")],
            "both name",
            false,
            "rec.csv",
        ),
        (
            vec![
                "--out".into(),
                p("new4.csv"),
                "--truth".into(),
                p("params.toml"),
                "--force".into(),
            ],
            "",
            true,
            "rec.csv",
        ),
    ];
    for (options, says, succeeds, kept) in cases {
        let before = std::fs::read(p(kept)).unwrap();
        let mut args = vec!["--routine", "free", "--max-duration", "2"];
        args.extend(options.iter().map(String::as_str));
        let out = run("magcal-record", &args);
        let err = text(&out.stderr);
        assert_eq!(out.status.success(), succeeds, "{options:?}: {err}");
        assert!(err.contains(says), "{options:?}: {err}");
        assert_eq!(std::fs::read(p(kept)).unwrap(), before, "{options:?}");
        if !succeeds {
            assert!(
                !Path::new(&options[1]).exists(),
                "{options:?}: the recording was started"
            );
        }
    }
    assert!(
        !Path::new(&p("x.csv")).exists(),
        "nothing was written first"
    );
    let truth = std::fs::read_to_string(p("params.toml")).unwrap();
    assert!(
        truth.starts_with("format = \"magcal-sim-truth v1\""),
        "--force replaced it: {truth}"
    );
}

/// Row 2: plots never write through a link in their folder, never over a recording (the input among them).
#[test]
fn row02_plots_are_written_atomically_never_through_a_link() {
    let base = tempfile::tempdir().unwrap();
    let source = simulated(base.path(), "source.csv", "40");
    let notes = base.path().join("notes.txt");
    // (what is at DIR/readings.svg, whether the fit may write its plots)
    let cases = [
        "symbolic link to the input",
        "hard link to the input",
        "the input itself",
        "symbolic link to notes",
    ];
    for case in cases {
        let dir = tempfile::tempdir().unwrap();
        let plots = dir.path();
        let readings = plots.join("readings.svg");
        let input = if case == "the input itself" {
            std::fs::copy(&source, &readings).unwrap();
            readings.clone()
        } else {
            let input = plots.join("rec.csv");
            std::fs::copy(&source, &input).unwrap();
            match case {
                "symbolic link to the input" => {
                    std::os::unix::fs::symlink(&input, &readings).unwrap()
                }
                "hard link to the input" => std::fs::hard_link(&input, &readings).unwrap(),
                _ => {
                    std::fs::write(&notes, "mine").unwrap();
                    std::os::unix::fs::symlink(&notes, &readings).unwrap();
                }
            }
            input
        };
        let before = std::fs::read(&input).unwrap();
        let out = run(
            "magcal-fit",
            &[
                input.to_str().unwrap(),
                "--no-diagnose",
                "--plots",
                plots.to_str().unwrap(),
            ],
        );
        let err = text(&out.stderr);
        assert_eq!(
            std::fs::read(&input).unwrap(),
            before,
            "{case}: the input changed"
        );
        if case == "symbolic link to notes" {
            assert!(out.status.success(), "{case}: {err}");
            assert_eq!(std::fs::read_to_string(&notes).unwrap(), "mine", "{case}");
            let svg = std::fs::read_to_string(&readings).unwrap();
            assert!(svg.starts_with("<svg"), "{case}");
            assert!(
                !std::fs::symlink_metadata(&readings).unwrap().is_symlink(),
                "{case}"
            );
        } else {
            assert!(!out.status.success(), "{case}: accepted: {err}");
            assert!(err.contains("--plots"), "{case}: {err}");
        }
        assert!(temporaries(plots).is_empty(), "{case}");
    }
}

/// Row 3: a recording magcal can read, however it was saved (a long metadata block, gzip, UTF-16), is never
/// replaced by `--out`, `--report`, `magcal-sim --out` or `magcal-apply --out`.
#[test]
fn row03_a_recording_however_saved_is_never_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let source = simulated(dir.path(), "source.csv", "40");
    let params = fitted(&source, dir.path());
    let long = format!(
        "# magcal-recording v1\n{}t,mx,my,mz\n0,1,2,3\n",
        "# note: a long metadata block, as a logger writes one\n".repeat(1500)
    );
    assert!(long.len() > 64 << 10);
    let saved: [(&str, Vec<u8>); 3] = [
        ("long.csv", long.into_bytes()),
        ("rec.csv.gz", gzip(RECORDING.as_bytes())),
        ("utf16.csv", utf16(RECORDING)),
    ];
    for (name, bytes) in saved {
        let target = dir.path().join(name);
        std::fs::write(&target, &bytes).unwrap();
        let t = target.to_str().unwrap();
        let s = source.to_str().unwrap();
        let p = params.to_str().unwrap();
        let runs: [(&str, Vec<&str>); 4] = [
            ("magcal-fit", vec![s, "--no-diagnose", "--out", t]),
            ("magcal-fit", vec![s, "--no-diagnose", "--report", t]),
            ("magcal-sim", vec!["--duration", "10", "--out", t]),
            ("magcal-apply", vec![p, s, "--out", t]),
        ];
        for (tool, args) in runs {
            let out = run(tool, &args);
            assert!(!out.status.success(), "{tool} {args:?} replaced {name}");
            assert!(
                text(&out.stderr).contains("holds a recording"),
                "{}",
                text(&out.stderr)
            );
            assert_eq!(std::fs::read(&target).unwrap(), bytes, "{tool} {args:?}");
        }
    }
}

/// A recorder writing `path` in real time until `max_s`, once it reports progress.
fn recording_in_progress(path: &Path, max_s: &str) -> Child {
    let mut child = Command::new(bin("magcal-record"))
        .args([
            "--routine",
            "free",
            "--realtime",
            "--max-duration",
            max_s,
            "--out",
        ])
        .arg(path)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    assert!(
        lines.any(|l| l.unwrap().starts_with("recording: t=")),
        "the recorder started"
    );
    std::thread::spawn(move || lines.for_each(drop));
    child
}

/// Row 4: the recorder's lock is honoured by every tool's output.
#[test]
fn row04_a_recorders_lock_is_honoured_by_every_tool() {
    let dir = tempfile::tempdir().unwrap();
    let source = simulated(dir.path(), "source.csv", "40");
    let params = fitted(&source, dir.path());
    let two = dir.path().join("two.csv");
    let mut recorder = recording_in_progress(&two, "4");
    let (t, s, p) = (
        two.to_str().unwrap(),
        source.to_str().unwrap(),
        params.to_str().unwrap(),
    );
    let runs: [(&str, Vec<&str>); 5] = [
        ("magcal-sim", vec!["--duration", "10", "--out", t]),
        ("magcal-fit", vec![s, "--no-diagnose", "--report", t]),
        ("magcal-apply", vec![p, s, "--out", t]),
        (
            "magcal-record",
            vec!["--routine", "free", "--force", "--out", t],
        ),
        (
            "magcal-sim",
            vec!["--duration", "10", "--out", s, "--truth", t],
        ),
    ];
    for (tool, args) in runs {
        let out = run(tool, &args);
        let err = text(&out.stderr);
        assert!(
            !out.status.success(),
            "{tool} {args:?} wrote over the recording"
        );
        assert!(
            err.contains("being written by another recorder"),
            "{tool} {args:?}: {err}"
        );
    }
    assert!(recorder.wait().unwrap().success());
    let rec = Recording::read(&two).expect("the recording parses");
    let last_s = *rec.t_s.as_ref().unwrap().last().unwrap();
    assert!(last_s > 3.5, "the recorder wrote to the end: {last_s} s");
}

/// Row 5: `--force` replaces the path it names, never what a link there points to, nor the file's other names.
#[test]
fn row05_force_replaces_the_named_path_not_what_it_points_to() {
    for link in ["symbolic", "hard"] {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("target.csv");
        std::fs::write(&target, RECORDING).unwrap();
        let named = dir.path().join("link.csv");
        if link == "symbolic" {
            std::os::unix::fs::symlink(&target, &named).unwrap();
        } else {
            std::fs::hard_link(&target, &named).unwrap();
        }
        let out = run(
            "magcal-record",
            &[
                "--routine",
                "free",
                "--max-duration",
                "2",
                "--force",
                "--out",
                named.to_str().unwrap(),
            ],
        );
        assert!(out.status.success(), "{link}: {}", text(&out.stderr));
        assert_eq!(
            std::fs::read_to_string(&target).unwrap(),
            RECORDING,
            "{link}"
        );
        assert!(
            !std::fs::symlink_metadata(&named).unwrap().is_symlink(),
            "{link}"
        );
        assert!(Recording::read(&named).unwrap().len() > 100, "{link}");
    }
}

/// Row 6: a file size limit (`ulimit -f`, SIGXFSZ) is handled as a full disk: a message, whole lines, no temporary.
#[test]
fn row06_a_file_size_limit_is_a_clear_error_and_leaves_no_temporary() {
    let dir = tempfile::tempdir().unwrap();
    let source = simulated(dir.path(), "source.csv", "60");
    let params = fitted(&source, dir.path());
    let out_dir = tempfile::tempdir().unwrap();
    let o = |n: &str| out_dir.path().join(n).to_str().unwrap().to_owned();
    let (s, p) = (source.to_str().unwrap(), params.to_str().unwrap());
    // (limit in 1024-byte blocks, tool, options, the file that must not be left torn)
    let cases: [(u32, &str, Vec<String>, String); 3] = [
        (
            64,
            "magcal-record",
            vec![
                "--routine".into(),
                "free".into(),
                "--out".into(),
                o("rec.csv"),
            ],
            o("rec.csv"),
        ),
        (
            2,
            "magcal-fit",
            vec![
                s.into(),
                "--no-diagnose".into(),
                "--report".into(),
                o("report.json"),
            ],
            o("report.json"),
        ),
        (
            64,
            "magcal-apply",
            vec![p.into(), s.into(), "--out".into(), o("cal.csv")],
            o("cal.csv"),
        ),
    ];
    for (blocks, tool, options, file) in cases {
        let args: Vec<&str> = options.iter().map(String::as_str).collect();
        let out = run_limited(&format!("ulimit -f {blocks};"), tool, &args, 120.0);
        let err = text(&out.stderr);
        assert_eq!(
            out.status.code(),
            Some(1),
            "{tool}: killed by the signal? {err}"
        );
        assert!(
            err.contains("File too large")
                && (err.contains("ulimit -f") || err.contains("whole lines")),
            "{tool}: {err}"
        );
        assert!(
            temporaries(out_dir.path()).is_empty(),
            "{tool}: {:?}",
            temporaries(out_dir.path())
        );
        if tool == "magcal-record" {
            let bytes = std::fs::read(&file).unwrap();
            assert!(bytes.ends_with(b"\n"), "a torn last line");
            Recording::read(Path::new(&file)).expect("the recording parses");
        } else {
            assert!(!Path::new(&file).exists(), "{tool}: a partial {file}");
        }
    }
}

/// Row 7: a chip saturated for a long time never holds the recorder: `--max-duration` and Ctrl-C are heeded, the
/// screen says it, and every row before is on disk.
#[test]
fn row07_a_saturated_chip_never_holds_the_recorder() {
    let dir = tempfile::tempdir().unwrap();
    // (device, how it ends: max-duration, or Ctrl-C after this many seconds)
    let cases = [
        ("sim:lis3mdl", None),
        ("sim:mmc5983ma", None),
        ("sim:lis3mdl", Some(2.0)),
    ];
    for (k, (device, interrupt_after_s)) in cases.into_iter().enumerate() {
        let path = dir.path().join(format!("{k}.csv"));
        let mut args = vec![
            "--device",
            device,
            "--routine",
            "free",
            "--sim-fault",
            "magnet@1:1e30:3000,0,0",
        ];
        args.extend(["--max-duration", "5", "--out", path.to_str().unwrap()]);
        if interrupt_after_s.is_some() {
            args.push("--realtime");
        }
        let child = Command::new(bin("magcal-record"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let pid = child.id();
        let stop = std::thread::spawn(move || {
            let after_s = interrupt_after_s?;
            std::thread::sleep(Duration::from_secs_f64(after_s));
            let sent = Instant::now();
            Command::new("kill")
                .args(["-INT", &pid.to_string()])
                .status()
                .unwrap();
            Some(sent)
        });
        let out = finish_within(child, 20.0);
        let ended = Instant::now();
        let sent = stop.join().unwrap();
        let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
        assert!(
            out.status.success(),
            "{device} {interrupt_after_s:?}: {stdout}\n{stderr}"
        );
        if let Some(sent) = sent {
            let took_s = (ended - sent).as_secs_f64();
            println!("Ctrl-C to exit: {took_s:.3} s");
            assert!(took_s < 0.5, "Ctrl-C took {took_s:.2} s");
            assert!(stdout.contains("(interrupted)"), "{stdout}");
        } else {
            assert!(stdout.contains("(longest duration reached)"), "{stdout}");
        }
        assert!(
            stdout.contains("saturated so far"),
            "{device}: said on screen: {stdout}"
        );
        let rec = Recording::read(&path).expect("the rows before the magnet are on disk");
        let last_s = *rec.t_s.as_ref().unwrap().last().unwrap();
        assert!(
            (0.9..1.05).contains(&last_s),
            "{device}: rows up to the magnet: {last_s} s"
        );
    }
}

/// The tests here time a recorder against a board in real time: one at a time.
fn one_at_a_time() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Records from the firmware twin `config` on a pseudo-terminal (`serial:PTY:115200:PROTOCOL`) with `options` until
/// the board unplugs itself (or after 30 s); returns the recorder's output.
fn serial_record(protocol: &str, config: FirmwareConfig, path: &Path, options: &[&str]) -> Output {
    let pty = pty::open();
    let device = format!("serial:{}:115200:{protocol}", pty.slave_path);
    let mut child = Command::new(bin("magcal-record"))
        .args([
            "--device",
            &device,
            "--routine",
            "free",
            "--coverage",
            "1",
            "--out",
        ])
        .arg(path)
        .args(options)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    stdout.read_line(&mut first).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let board = pty::firmware(pty.master, config, stop.clone());
    let mut rest = Vec::new();
    let reader = std::thread::spawn(move || {
        let _ = std::io::Read::read_to_end(&mut stdout, &mut rest);
        rest
    });
    let mut out = finish_within(child, 30.0);
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    board.join().unwrap();
    out.stdout = [first.into_bytes(), reader.join().unwrap()].concat();
    out
}

/// Row 8 (serial): a line that lost bytes and reads as −4.2·10⁶ µT is skipped and counted as garbage, and the
/// message says where; the recording goes on.
#[test]
fn row08_a_serial_line_out_of_range_is_skipped_and_placed() {
    let _serial = one_at_a_time();
    for (protocol, output) in [
        ("motioncal", BoardOutput::MotionCal),
        ("csv", BoardOutput::Csv),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("serial.csv");
        let mut config = FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 5));
        config.output = output;
        config.raw_lines = Some(600);
        config.lines_per_wall_s = 3000.0;
        config.fault = Some(BoardFault::CorruptedAt(300));
        let out = serial_record(protocol, config, &path, &[]);
        let err = text(&out.stderr);
        assert!(
            err.contains("disconnected after 599 samples") && err.contains("out_of_range 1"),
            "{protocol}: the recording went on to the unplug: {err}"
        );
        assert!(
            err.contains("came after sample ") && err.contains("300 (out_of_range)"),
            "{protocol}: {err}"
        );
        let rec = Recording::read(&path).unwrap();
        assert_eq!(rec.len(), 599, "{protocol}");
        assert!(rec.mag_ut.iter().all(|m| m[0].abs() < 1000.0), "{protocol}");
    }
}

/// Row 9: magcal-sim's currents are checked before anything is allocated (a mean switching time of zero took 18.7 GB
/// in a minute; a nanosecond, an allocation abort). Run under a 4 GB address-space limit, so a regression fails
/// rather than takes the machine's memory.
#[test]
fn row09_sim_currents_are_validated_before_anything_is_allocated() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("sim.csv");
    for current in ["m:1,0,0", "m:1,1e-9,1e-9", "m:NaN,1,1", "m:1,-1,5"] {
        let started = Instant::now();
        let out = run_limited(
            "ulimit -v 4000000;",
            "magcal-sim",
            &["--current", current, "--out", out_path.to_str().unwrap()],
            20.0,
        );
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{current}: {err}");
        assert!(err.contains("--current \"i_m\""), "{current}: {err}");
        assert!(started.elapsed() < Duration::from_secs(5), "{current}");
        assert!(!out_path.exists());
    }
}

/// Row 10: `magcal-sim --errors` with NaN or infinity in any position is a clear message, not a panic.
#[test]
fn row10_sim_errors_not_numbers_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("sim.csv");
    for (errors, says) in [
        ("NaN,1,1", "--errors SOFT NaN"),
        ("0.1,inf,1", "--errors HARD inf"),
        ("0.1,1,-inf", "--errors MOUNT -inf"),
        ("inf,NaN,1", "--errors SOFT inf"),
    ] {
        let out = run(
            "magcal-sim",
            &["--errors", errors, "--out", out_path.to_str().unwrap()],
        );
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{errors}: {err}");
        assert!(
            err.contains(says) && !err.contains("panicked"),
            "{errors}: {err}"
        );
        assert!(!out_path.exists());
    }
}

/// Row 11: `magcal-paper` with noise or misalignment out of range is a clear message, not a panic.
#[test]
fn row11_paper_settings_out_of_range_are_refused() {
    for (option, value, says) in [
        (
            "--noise",
            "1e6",
            "--noise 1000000 µT: must be a number from 0 to 10 µT",
        ),
        ("--noise", "NaN", "--noise NaN"),
        ("--noise", "inf", "--noise inf"),
        ("--mount-deg", "NaN", "--mount-deg NaN"),
    ] {
        let out = run("magcal-paper", &[option, value]);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{option} {value}: {err}");
        assert!(
            err.contains(says) && !err.contains("panicked"),
            "{option} {value}: {err}"
        );
    }
}

/// Row 12: numbers outside the range that makes sense are refused, naming it, before anything is written.
#[test]
fn row12_numbers_outside_their_sensible_range_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.csv");
    let p = path.to_str().unwrap();
    let cases: [(&str, Vec<&str>, &str); 6] = [
        (
            "magcal-record",
            vec!["--routine", "cube24", "--dwell", "1e-30"],
            "--dwell 1e-30 s: must be a number from 0.1 to 60 s",
        ),
        (
            "magcal-record",
            vec![
                "--device",
                "sim:hmc5883l",
                "--routine",
                "cube24",
                "--dwell",
                "0.1",
            ],
            "--dwell 0.1 s holds 8 samples at the 75 Hz the device gives",
        ),
        (
            "magcal-sim",
            vec!["--rate", "1e-300"],
            "--rate must be a number of Hz from 0.1 to 10000, got 1e-300",
        ),
        (
            "magcal-sim",
            vec!["--duration", "1e-300"],
            "samples: at least 100",
        ),
        (
            "magcal-sim",
            vec!["--noise=-1"],
            "--noise -1 µT: must be a number from 0 to 100 µT",
        ),
        (
            "magcal-sim",
            vec!["--gyro-noise=-1"],
            "--gyro-noise -1 rad/s",
        ),
    ];
    for (tool, mut args, says) in cases {
        args.extend(["--out", p]);
        let out = run(tool, &args);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(!path.exists(), "{args:?}: written");
    }
}

/// Row 13: errors quote a short, escaped excerpt of an argument, never all of a long one, and a number in a few
/// characters.
#[test]
fn row13_errors_quote_a_short_escaped_excerpt() {
    let long = format!("{}\u{1b}[2J", "x".repeat(100_000));
    let cases: [(&str, Vec<&str>); 8] = [
        ("magcal-fit", vec!["--method", &long, "r.csv"]),
        ("magcal-fit", vec!["r.csv", "--field-ned", &long]),
        ("magcal-sim", vec!["--out", "o.csv", "--chip", &long]),
        ("magcal-sim", vec!["--out", "o.csv", "--current", &long]),
        ("magcal-sim", vec!["--out", "o.csv", "--effect-rms", &long]),
        (
            "magcal-record",
            vec!["--routine", "free", "--device", &long],
        ),
        (
            "magcal-record",
            vec!["--routine", "free", "--sim-fault", &long],
        ),
        ("magcal-sim", vec!["--out", "o.csv", "--rate", "1e-300"]),
    ];
    for (tool, args) in cases {
        let out = run(tool, &args);
        let err = text(&out.stderr);
        let shown: Vec<&str> = args
            .iter()
            .map(|a| if a.len() > 50 { "LONG" } else { a })
            .collect();
        assert!(!out.status.success(), "{tool} {shown:?}");
        assert!(err.len() < 1000, "{tool} {shown:?}: {} bytes", err.len());
        assert!(
            !err.contains('\u{1b}'),
            "{tool} {shown:?}: a raw escape sequence"
        );
        assert!(!err.contains("00000000000"), "{tool} {shown:?}: {err}");
    }
}

/// Row 14: the temporary file a killed magcal-sim or magcal-apply left is removed by the next run, which names it.
#[test]
fn row14_a_killed_runs_temporary_is_cleaned_on_the_next_run() {
    let dir = tempfile::tempdir().unwrap();
    let big = simulated(dir.path(), "big.csv", "3000");
    let params = fitted(&simulated(dir.path(), "small.csv", "40"), dir.path());
    let out_dir = tempfile::tempdir().unwrap();
    let target = out_dir.path().join("out.csv");
    let t = target.to_str().unwrap();
    let (b, p) = (big.to_str().unwrap(), params.to_str().unwrap());
    let runs: [(&str, Vec<&str>); 2] = [
        ("magcal-sim", vec!["--duration", "3000", "--out", t]),
        ("magcal-apply", vec![p, b, "--out", t]),
    ];
    for (tool, args) in runs {
        let _ = std::fs::remove_file(&target);
        // Killed while it writes: once its temporary file is there.
        let mut child = Command::new(bin(tool))
            .args(&args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(60);
        while temporaries(out_dir.path()).is_empty() && Instant::now() < deadline {
            assert!(
                child.try_wait().unwrap().is_none(),
                "{tool} ended before it was killed"
            );
            std::thread::sleep(Duration::from_micros(200));
        }
        child.kill().unwrap();
        child.wait().unwrap();
        let left = temporaries(out_dir.path());
        assert_eq!(left.len(), 1, "{tool}: {left:?}");
        // The next run of either tool into that folder removes it, and says so.
        let out = run("magcal-sim", &["--duration", "10", "--out", t]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        assert!(
            temporaries(out_dir.path()).is_empty(),
            "{tool}: left for ever"
        );
        assert!(
            text(&out.stderr).contains(&left[0]),
            "{tool}: not named: {}",
            text(&out.stderr)
        );
    }
}

/// The mode bits of a file.
fn mode(path: &Path) -> u32 {
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::metadata(path).unwrap().permissions().mode() & 0o777
}

/// Row 15: a file replaced by magcal-apply or magcal-sim keeps its mode.
#[test]
fn row15_a_replaced_file_keeps_its_mode() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = tempfile::tempdir().unwrap();
    let source = simulated(dir.path(), "source.csv", "40");
    let params = fitted(&source, dir.path());
    let (s, p) = (source.to_str().unwrap(), params.to_str().unwrap());
    for (tool, mode_bits) in [
        ("magcal-sim", 0o600),
        ("magcal-apply", 0o640),
        ("magcal-sim", 0o640),
    ] {
        let target = dir.path().join(format!("{tool}.csv"));
        let t = target.to_str().unwrap();
        let args: Vec<&str> = match tool {
            "magcal-sim" => vec!["--duration", "10", "--out", t],
            _ => vec![p, s, "--out", t],
        };
        assert!(run(tool, &args).status.success(), "{tool}: first run");
        std::fs::set_permissions(&target, std::fs::Permissions::from_mode(mode_bits)).unwrap();
        let out = run(tool, &args);
        assert!(out.status.success(), "{tool}: {}", text(&out.stderr));
        assert_eq!(mode(&target), mode_bits, "{tool}: {:o}", mode(&target));
    }
}

/// Row 16: `--force` with a device that yields no sample keeps the old file until the first sample is written (a
/// chip saturated from the start; a silent serial board).
#[test]
fn row16_force_keeps_the_old_file_until_the_first_sample() {
    let _serial = one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let good = simulated(dir.path(), "good.csv", "40");
    let bytes = std::fs::read(&good).unwrap();
    for case in ["saturated chip", "silent board"] {
        std::fs::write(&path, &bytes).unwrap();
        let out = match case {
            "saturated chip" => run(
                "magcal-record",
                &[
                    "--routine",
                    "free",
                    "--sim-fault",
                    "magnet@0:1e30:3000,0,0",
                    "--max-duration",
                    "2",
                    "--force",
                    "--out",
                    path.to_str().unwrap(),
                ],
            ),
            _ => {
                let mut config = FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 5));
                config.fault = Some(BoardFault::SilentAfter(0));
                serial_record(
                    "motioncal",
                    config,
                    &path,
                    &["--force", "--idle-timeout", "1"],
                )
            }
        };
        let said = format!("{}{}", text(&out.stdout), text(&out.stderr));
        assert!(said.contains("left as it was"), "{case}: {said}");
        assert_eq!(
            std::fs::read(&path).unwrap(),
            bytes,
            "{case}: the old file was replaced"
        );
        assert!(temporaries(dir.path()).is_empty(), "{case}");
    }
    // One sample is enough to replace it.
    let out = run(
        "magcal-record",
        &[
            "--routine",
            "free",
            "--max-duration",
            "2",
            "--force",
            "--out",
            path.to_str().unwrap(),
        ],
    );
    assert!(out.status.success());
    assert_ne!(std::fs::read(&path).unwrap(), bytes);
    std::io::stdout().flush().unwrap();
}
