//! Acceptance: the recording file is never lost. An existing `--out` is refused without `--force` (before the device
//! opens), two recorders on one file cannot both write it, options are checked before anything is opened, a full
//! disk leaves whole lines and a message that counts them, and files get the user's usual mode.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Output, Stdio};

use magcal_recording::Recording;

fn record(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args(args)
        .output()
        .expect("magcal-record runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn an_existing_recording_is_never_replaced_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let p = path.to_str().unwrap();
    std::fs::write(&path, "precious\n").unwrap();
    // (device, options, what stderr says): the refusal comes before the device is opened, so a device that cannot
    // be opened, or fails at once, changes nothing.
    let refused = [
        (
            "sim:lis3mdl",
            vec![],
            "rec.csv exists: a recording is never replaced",
        ),
        (
            "sim:lis3mdl",
            vec!["--sim-fault", "nack@0.5:1000"],
            "add --force to replace it",
        ),
        (
            "i2c:/dev/no-such-bus:lis3mdl",
            vec![],
            "(nothing was recorded)",
        ),
        ("serial:/dev/no-such-port", vec![], "rec.csv exists"),
    ];
    for (device, options, says) in refused {
        let mut args = vec!["--device", device, "--routine", "free", "--out", p];
        args.extend(options);
        let out = record(&args);
        assert!(!out.status.success(), "{device}");
        assert!(stderr(&out).contains(says), "{device}: {}", stderr(&out));
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "precious\n",
            "{device}"
        );
    }
    let out = record(&["--routine", "free", "--out", p, "--force"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(Recording::read(&path).unwrap().len() > 1000);
}

#[test]
fn a_reader_that_goes_away_does_not_stop_the_recording() {
    // `magcal-record … | head`: progress lines and the summary have no reader; the recording goes on to its end.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let mut child = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args(["--routine", "free", "--out", path.to_str().unwrap()])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("panicked"), "{}", stderr(&out));
    assert!(Recording::read(&path).unwrap().len() > 1000);
}

#[test]
fn a_second_recorder_on_the_same_file_is_refused_and_the_first_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let mut first = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--routine",
            "free",
            "--realtime",
            "--max-duration",
            "3",
            "--out",
        ])
        .arg(&path)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(first.stdout.take().unwrap()).lines();
    // The first is recording once it reports progress.
    assert!(
        lines.any(|l| l.unwrap().starts_with("recording: t=")),
        "the first recorder started"
    );
    for force in [false, true] {
        let mut args = vec!["--routine", "free", "--out", path.to_str().unwrap()];
        if force {
            args.push("--force");
        }
        let out = record(&args);
        assert!(!out.status.success(), "force {force}");
        assert!(
            stderr(&out).contains("is being written by another recorder"),
            "force {force}: {}",
            stderr(&out)
        );
    }
    std::thread::spawn(move || lines.for_each(drop));
    assert!(first.wait().unwrap().success());
    let rec = Recording::read(&path).expect("the first recorder's file parses");
    let t = rec.t_s.as_ref().unwrap();
    assert!(
        t[t.len() - 1] > 2.5,
        "the first recorded to the end: {} s",
        t[t.len() - 1]
    );
}

#[test]
fn options_out_of_range_are_refused_before_anything_is_opened_or_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let truth = dir.path().join("truth.toml");
    let p = path.to_str().unwrap();
    let t = truth.to_str().unwrap();
    let cases: [(&[&str], &str); 10] = [
        (
            &["--dwell", "1e30"],
            "--dwell 1e30 s: must be a number from 0.1 to 60 s",
        ),
        (
            &["--dwell", "1e7"],
            "--dwell 10000000 s: must be a number from 0.1 to 60 s",
        ),
        (
            &["--rate", "1e12"],
            "--rate 1000000000000 Hz: must be a number > 0 and at most 10000 Hz",
        ),
        (&["--rate", "0"], "--rate 0 Hz"),
        (
            &["--device", "sim:hmc5883l", "--rate", "5000"],
            "the hmc5883l runs at 0.75–75 Hz",
        ),
        (&["--max-duration", "NaN"], "--max-duration NaN"),
        (&["--still-ut=-1"], "--still-ut -1"),
        // A negative number after a space is the option's value, not a flag (clap took it for one).
        (
            &["--coverage", "-0.1"],
            "--coverage -0.1: must be a fraction",
        ),
        (&["--max-duration", "-5"], "--max-duration -5 s"),
        (
            &["--device", "serial:/dev/ttyUSB0", "--idle-timeout", "0"],
            "--idle-timeout 0 s",
        ),
    ];
    for (options, says) in cases {
        let mut args = vec!["--routine", "cube24", "--out", p];
        if !options.contains(&"serial:/dev/ttyUSB0") {
            args.extend(["--truth", t]);
        }
        args.extend(options);
        let out = record(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{options:?}: {err}");
        assert!(err.contains(says), "{options:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            !path.exists() && !truth.exists(),
            "{options:?}: something was written"
        );
    }
}

#[test]
fn a_full_disk_leaves_whole_lines_and_the_message_counts_what_the_file_holds() {
    let dir = tempfile::tempdir().unwrap();
    // A file size limit stands for a full disk: writes past it fail (EFBIG; SIGXFSZ is ignored so that the
    // recorder sees the error, as it sees ENOSPC). bash counts 1024-byte blocks: 64 KiB, about a thousand rows.
    for routine in ["free", "cube24"] {
        let path = dir.path().join(format!("{routine}.csv"));
        let script = format!(
            "trap '' XFSZ; ulimit -f 64; exec '{}' --routine {routine} --out '{}'",
            env!("CARGO_BIN_EXE_magcal-record"),
            path.display()
        );
        let out = Command::new("bash").args(["-c", &script]).output().unwrap();
        let err = stderr(&out);
        assert!(!out.status.success(), "{routine}: {err}");
        let rec = Recording::read(&path)
            .unwrap_or_else(|e| panic!("{routine}: the file must parse after a full disk: {e}"));
        let bytes = std::fs::metadata(&path).unwrap().len();
        assert!(
            bytes <= 64 * 1024 && bytes > 60_000,
            "{routine}: {bytes} bytes"
        );
        assert!(
            std::fs::read(&path).unwrap().ends_with(b"\n"),
            "{routine}: a torn last line"
        );
        assert!(
            err.contains("File too large")
                && err.contains(&format!(
                    "the file keeps the {} samples written before (whole lines: it parses)",
                    rec.len()
                )),
            "{routine}: {} rows; {err}",
            rec.len()
        );
    }
}

/// The mode bits of a file.
fn mode(path: &Path) -> u32 {
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::metadata(path).unwrap().permissions().mode() & 0o777
}

#[test]
fn files_get_the_usual_mode_for_the_umask() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.csv");
    for (umask, expected) in [("022", 0o644), ("027", 0o640)] {
        let files = [
            "rec.csv",
            "truth.toml",
            "params.toml",
            "report.json",
            "ardupilot.param",
        ];
        for f in files {
            let _ = std::fs::remove_file(dir.path().join(f));
        }
        let script = format!(
            "umask {umask} && cd '{}' && '{}' --routine cube24 --out rec.csv --truth truth.toml >/dev/null && \
             '{}' rec.csv --out params.toml --report report.json --export ardupilot --export-out ardupilot.param \
             --no-diagnose >/dev/null",
            dir.path().display(),
            env!("CARGO_BIN_EXE_magcal-record"),
            env!("CARGO_BIN_EXE_magcal-fit"),
        );
        let out = Command::new("bash").args(["-c", &script]).output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        for f in files {
            assert_eq!(
                mode(&dir.path().join(f)),
                expected,
                "umask {umask}: {f} is {:o}",
                mode(&dir.path().join(f))
            );
        }
    }
    assert!(rec.exists());
}
