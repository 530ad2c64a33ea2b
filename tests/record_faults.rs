//! Acceptance: faults while recording, each a test, through `magcal-record` on simulated chips with injected faults
//! (bus errors, stuck outputs, magnets that saturate each chip or only change the field, an unwritable path, kill -9,
//! Ctrl-C).
//! Whatever happens, the file parses and keeps what was recorded.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use magcal_recording::Recording;

fn record(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args(args)
        .output()
        .expect("magcal-record runs")
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn last_t_s(rec: &Recording) -> f64 {
    *rec.t_s.as_ref().expect("t column").last().expect("rows")
}

#[test]
fn a_short_nack_burst_is_retried_and_the_recording_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let out = record(&[
        "--device",
        "sim:lis2mdl",
        "--routine",
        "free",
        "--sim-fault",
        "nack@5:3",
        "--out",
        path.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("coverage target reached"), "{stdout}");
    // The retries' back-off (5 + 10 + 20 ms) costs a few samples, not the recording.
    let rec = Recording::read(&path).unwrap();
    let t = rec.t_s.as_ref().unwrap();
    let largest_gap = t.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!(
        (0.035..0.06).contains(&largest_gap),
        "largest gap {largest_gap} s at 100 Hz"
    );
}

#[test]
fn nacks_beyond_the_retries_stop_with_a_clear_error_and_the_data_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    for (fault, chip) in [("nack@20:50", "lis3mdl"), ("drop@20", "mmc5983ma")] {
        let path = dir.path().join(format!("{chip}.csv"));
        let out = record(&[
            "--device",
            &format!("sim:{chip}"),
            "--routine",
            "free",
            "--sim-fault",
            fault,
            "--out",
            path.to_str().unwrap(),
        ]);
        let (stdout, stderr) = text(&out);
        assert!(!out.status.success(), "{fault}: {stdout}");
        let rec =
            Recording::read(&path).unwrap_or_else(|e| panic!("{fault}: the file must parse: {e}"));
        let kept = rec.len();
        assert!(
            stderr.contains(&format!(
                "sim:{chip}: bus error after {kept} samples, 4 attempts"
            )) && stderr.contains("NoAcknowledge")
                && stderr.contains(&format!("keeps the {kept} samples recorded before")),
            "{fault}: {stderr}"
        );
        // The fault came 20 s after the chip started; the file holds everything up to it.
        let t = last_t_s(&rec);
        assert!((19.0..20.0).contains(&t), "{fault}: last sample at {t} s");
    }
}

#[test]
fn stuck_outputs_stop_the_recording_naming_the_device() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let out = record(&[
        "--device",
        "sim:qmc5883l",
        "--routine",
        "free",
        "--sim-fault",
        "stuck@10",
        "--out",
        path.to_str().unwrap(),
    ]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(
        stderr.contains("sim:qmc5883l: the output is stuck at")
            && stderr.contains("identical samples in a row"),
        "{stderr}"
    );
    let rec = Recording::read(&path).unwrap();
    assert!(
        stderr.contains(&format!("keeps the {} samples", rec.len())),
        "{stderr}"
    );
}

#[test]
fn an_unwritable_out_path_fails_before_recording_starts() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "not a directory").unwrap();
    let path = file.join("rec.csv");
    let out = record(&["--routine", "free", "--out", path.to_str().unwrap()]);
    let (stdout, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(
        stderr.contains(&format!(
            "--out {}: {} is a file, not a folder",
            path.display(),
            file.display()
        )) && stderr.contains("nothing was recorded"),
        "{stderr}"
    );
    assert!(
        !stdout.contains("recording: t="),
        "no sample was taken: {stdout}"
    );
}

/// Starts a paced (wall-clock) recording and waits until it reports at least `until_s` of recording time; returns
/// the child and the last progress line's time.
fn paced_recording(path: &Path, until_s: f64) -> (Child, f64) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--device",
            "sim:lis3mdl",
            "--routine",
            "free",
            "--realtime",
            "--out",
        ])
        .arg(path)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut reported_s = None;
    while Instant::now() < deadline {
        let Some(Ok(line)) = lines.next() else {
            break;
        };
        if let Some(rest) = line.strip_prefix("recording: t=") {
            let t: f64 = rest.split(' ').next().unwrap().parse().unwrap();
            if t >= until_s {
                reported_s = Some(t);
                break;
            }
        }
    }
    let Some(t) = reported_s else {
        child.kill().unwrap();
        child.wait().unwrap();
        panic!("the recorder never reported {until_s} s of recording");
    };
    // Keep the pipe open so the recorder never blocks or fails on its output.
    std::thread::spawn(move || lines.for_each(drop));
    (child, t)
}

#[test]
fn after_kill_9_the_file_parses_and_at_most_a_second_is_lost() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let (mut child, reported_s) = paced_recording(&path, 3.0);
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let rec = Recording::read(&path).expect("the file parses after kill -9");
    let t = last_t_s(&rec);
    println!(
        "progress reported {reported_s:.2} s; the file holds up to {t:.2} s ({} rows)",
        rec.len()
    );
    assert!(t >= reported_s - 1.0, "lost {:.2} s", reported_s - t);
    assert_eq!(rec.meta.routine.as_deref(), Some("free"));
}

#[test]
fn ctrl_c_stops_cleanly_and_keeps_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let (mut child, reported_s) = paced_recording(&path, 1.5);
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    assert!(
        child.wait().unwrap().success(),
        "an interrupt is a clean stop"
    );
    let rec = Recording::read(&path).unwrap();
    // Everything up to the interrupt is in the file (the writer is finished on the way out).
    assert!(
        last_t_s(&rec) >= reported_s,
        "{} < {reported_s}",
        last_t_s(&rec)
    );
}

#[test]
fn a_magnet_saturating_any_chip_is_detected_flagged_and_kept_out_of_the_file() {
    let dir = tempfile::tempdir().unwrap();
    // (chip, a field past its largest range, its output data rate at the default --rate 100)
    let cases = [
        ("lis3mdl", "magnet@10:2:3000,0,0", 80.0),
        ("lis2mdl", "magnet@10:2:0,-6000,0", 100.0),
        ("mmc5983ma", "magnet@10:2:0,0,1500", 100.0),
        ("qmc5883l", "magnet@10:2:1500,0,0", 100.0),
        ("hmc5883l", "magnet@10:2:3000,0,0", 75.0),
    ];
    for (chip, fault, rate_hz) in cases {
        let path = dir.path().join(format!("{chip}.csv"));
        let out = record(&[
            "--device",
            &format!("sim:{chip}"),
            "--routine",
            "free",
            "--sim-fault",
            fault,
            "--out",
            path.to_str().unwrap(),
        ]);
        let (stdout, stderr) = text(&out);
        assert!(out.status.success(), "{chip}: no false 'stuck': {stderr}");
        assert!(
            stdout.contains("saturated so far (field out of the chip's range"),
            "{chip}: said live: {stdout}"
        );
        let n: f64 = stdout
            .lines()
            .find_map(|l| l.strip_prefix("saturated samples (not recorded): "))
            .unwrap_or_else(|| panic!("{chip}: a count of saturated samples: {stdout}"))
            .parse()
            .unwrap();
        assert!(
            (n - 2.0 * rate_hz).abs() <= 0.05 * 2.0 * rate_hz,
            "{chip}: {n} saturated samples"
        );
        let rec = Recording::read(&path).unwrap();
        let t = rec.t_s.as_ref().unwrap();
        assert!(
            t.windows(2).any(|w| w[1] - w[0] > 1.9),
            "{chip}: the saturated stretch is a gap in the file"
        );
        let largest = rec
            .mag_ut
            .iter()
            .map(|m| m.iter().fold(0.0f64, |a, v| a.max(v.abs())))
            .fold(0.0, f64::max);
        assert!(
            largest < 200.0,
            "{chip}: a clipped value reached the file: {largest} µT"
        );
    }
}

#[test]
fn a_magnet_that_does_not_saturate_is_said_live_and_kept_out_of_the_coverage() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let clean = dir.path().join("clean.csv");
    let run = |path: &Path, faults: &[&str]| {
        let mut args = vec![
            "--device",
            "sim:lis3mdl",
            "--routine",
            "free",
            "--out",
            path.to_str().unwrap(),
        ];
        for f in faults {
            args.extend(["--sim-fault", f]);
        }
        record(&args)
    };
    let out = run(&path, &["magnet@20:5:150,0,0"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    // Said when it happens, between the progress lines of its seconds, and when it ends.
    let lines: Vec<&str> = stdout.lines().collect();
    let said = lines
        .iter()
        .position(|l| {
            l.starts_with("t = 20.")
                && l.contains("the field magnitude is")
                && l.contains("a magnet")
        })
        .unwrap_or_else(|| panic!("no live notice: {stdout}"));
    assert!(
        lines[said - 1].starts_with("recording: t=20."),
        "{}",
        lines[said - 1]
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("t = 25.")
                && l.contains("back to the rest's (disturbed for 5.0 s)")),
        "{stdout}"
    );
    let n: u64 = stdout
        .lines()
        .find_map(|l| {
            l.rsplit_once("kept out of the coverage map): ")
                .map(|(_, n)| n)
        })
        .expect("the summary counts them")
        .parse()
        .unwrap();
    assert!(
        (390..=400).contains(&n),
        "{n} disturbed samples (5 s at 80 Hz)"
    );
    // Nothing lost: the disturbed samples are in the file; and the coverage was not spoiled: the run stops where
    // an undisturbed one does, give or take the 5 s kept out.
    let rec = Recording::read(&path).unwrap();
    assert!(run(&clean, &[]).status.success());
    let undisturbed = Recording::read(&clean).unwrap();
    let duration = |r: &Recording| *r.t_s.as_ref().unwrap().last().unwrap();
    assert!(
        duration(&rec) < duration(&undisturbed) + 6.0,
        "{} s with the magnet, {} s without",
        duration(&rec),
        duration(&undisturbed)
    );
    let magnitudes_in_file = rec
        .mag_ut
        .iter()
        .filter(|m| m.iter().map(|v| v * v).sum::<f64>().sqrt() > 110.0)
        .count();
    assert!(
        magnitudes_in_file > 100,
        "the disturbed samples are recorded: {magnitudes_in_file}"
    );
    // No false alarm on an undisturbed bench, whatever the chip and the sensor's errors.
    for chip in ["lis3mdl", "lis2mdl", "qmc5883l", "hmc5883l", "mmc5983ma"] {
        for seed in ["1", "2", "3"] {
            let path = dir.path().join(format!("{chip}-{seed}.csv"));
            let out = record(&[
                "--device",
                &format!("sim:{chip}"),
                "--sim-seed",
                seed,
                "--routine",
                "free",
                "--out",
                path.to_str().unwrap(),
            ]);
            let (stdout, _) = text(&out);
            assert!(
                out.status.success() && !stdout.contains("the field magnitude is"),
                "{chip} {seed}: {stdout}"
            );
        }
    }
}

#[test]
fn the_cube_routine_counts_only_the_disturbed_samples_it_recorded() {
    // Between two cube poses readings are looked at and not written: a magnet across a pose change once counted
    // 400 "recorded" samples for the 80 rows the file held.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cube.csv");
    let out = record(&[
        "--device",
        "sim:lis3mdl",
        "--routine",
        "cube24",
        "--sim-fault",
        "magnet@20:5:150,0,0",
        "--out",
        path.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let n: usize = stdout
        .lines()
        .find_map(|l| {
            l.rsplit_once("kept out of the coverage map): ")
                .map(|(_, n)| n)
        })
        .unwrap_or_else(|| panic!("the summary counts them: {stdout}"))
        .parse()
        .unwrap();
    let rec = Recording::read(&path).unwrap();
    let t = rec.t_s.as_ref().unwrap();
    let in_file = (0..t.len())
        .filter(|&i| (20.0..25.0).contains(&t[i]))
        .filter(|&i| rec.mag_ut[i].iter().map(|v| v * v).sum::<f64>().sqrt() > 110.0)
        .count();
    assert!(
        n > 0 && n <= in_file,
        "{n} counted, {in_file} disturbed rows in the file"
    );
}
