//! Acceptance: faults while recording, each a test, through `magcal-record` on simulated chips with injected faults.
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
fn a_magnet_saturating_the_chip_is_counted_and_not_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let out = record(&[
        "--device",
        "sim:hmc5883l",
        "--routine",
        "free",
        "--sim-fault",
        "magnet@10:2:3000,0,0",
        "--out",
        path.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains("saturated so far (field out of the chip's range"),
        "{stdout}"
    );
    // 2 s at the HMC5883L's 75 Hz.
    let n: u64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("saturated samples (not recorded): "))
        .expect("a count of saturated samples")
        .parse()
        .unwrap();
    assert!((145..=155).contains(&n), "{n} saturated samples");
    let rec = Recording::read(&path).unwrap();
    let t = rec.t_s.as_ref().unwrap();
    assert!(
        t.windows(2).any(|w| w[1] - w[0] > 1.9),
        "the saturated stretch is a gap in the file"
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
        stderr.contains(&format!("cannot create the recording {}", path.display()))
            && stderr.contains("nothing was recorded"),
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
