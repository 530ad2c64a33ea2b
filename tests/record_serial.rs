//! Acceptance, over a pseudo-terminal: a simulated MotionCal-style board streams `Raw:` lines (or native CSV) with
//! garbage mixed in, then is unplugged; `magcal-record --device serial:…` records every sample, counts the garbage,
//! and leaves a valid file. A board that goes silent, runs at another baud rate or speaks the other protocol is a
//! clear error after `--idle-timeout`; Ctrl-C always ends the recording; a board that resets starts a new segment
//! of true time, noted in the metadata, whatever header it prints.

mod pty;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, MutexGuard};

use magcal_app::source::sim::bench_config;
use magcal_driver::ChipKind;
use magcal_mockhw::firmware::FirmwareConfig;
use magcal_recording::Recording;

/// The tests here time a recorder against a board in real time: one at a time, so that on a 2-core machine they do
/// not slow each other down past the timeouts they check.
fn one_at_a_time() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

#[test]
fn every_raw_line_is_recorded_garbage_is_counted_and_an_unplug_leaves_a_valid_file() {
    let _serial = one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("serial.csv");
    let pty = pty::open();
    let device = format!("serial:{}:115200:motioncal", pty.slave_path);
    let mut child = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--device",
            &device,
            "--routine",
            "free",
            "--coverage",
            "1",
            "--out",
        ])
        .arg(&path)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The board starts streaming once the recorder has the port open.
    let mut stdout = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = stdout.next().unwrap().unwrap();
    assert!(first.starts_with(&format!("recording {device}")), "{first}");
    let drain = std::thread::spawn(move || stdout.map(Result::unwrap).collect::<Vec<String>>());

    let mut config = FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 5));
    config.raw_lines = Some(1500);
    config.garbage_every = Some(37);
    config.lines_per_wall_s = 3000.0;
    let report = pty::firmware(pty.master, config, Arc::new(AtomicBool::new(false)))
        .join()
        .unwrap();
    assert_eq!((report.raw_lines, report.garbage_lines), (1500, 40));

    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = drain.join().unwrap().join("\n");
    assert!(
        !out.status.success(),
        "an unplug mid-routine is an error: {stdout}"
    );
    assert!(
        stderr.contains(&format!("{device}: disconnected after 1500 samples"))
            && stderr.contains("keeps the 1500 samples recorded before")
            && stderr.contains("garbage lines skipped: 40 (binary 10, field_count 10, bad_number 10, unrecognized 10)"),
        "{stderr}"
    );
    let rec = Recording::read(&path).expect("the file is valid after the unplug");
    assert_eq!(rec.len(), 1500);
    assert_eq!(rec.meta.routine.as_deref(), Some("free"));
    // The samples are the bench's field through the simulated sensor: about the world's magnitude, offset by the
    // hard iron, and quantised to MotionCal's 0.1 µT.
    for m in &rec.mag_ut {
        let norm = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        assert!((5.0..130.0).contains(&norm), "{m:?}");
        assert!(
            m.iter()
                .all(|v| ((v * 10.0) - (v * 10.0).round()).abs() < 1e-6),
            "{m:?}"
        );
    }
}

/// What a recording from the simulated board gave.
struct SerialRun {
    success: bool,
    stdout: String,
    stderr: String,
    report: magcal_mockhw::firmware::FirmwareReport,
    path: std::path::PathBuf,
    /// How long the recorder ran after the board started, s.
    ran_s: f64,
    _dir: tempfile::TempDir,
}

/// Records `device_protocol` lines from a board running `config` (its port opened first, as a board is plugged in
/// before recording), with `options`; Ctrl-C after `interrupt_after_s` if given. The board is stopped once the
/// recorder is done.
fn serial_run(
    device_protocol: &str,
    config: FirmwareConfig,
    options: &[&str],
    interrupt_after_s: Option<f64>,
) -> SerialRun {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("serial.csv");
    let pty = pty::open();
    let device = format!("serial:{}:115200:{device_protocol}", pty.slave_path);
    let mut child = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--device",
            &device,
            "--routine",
            "free",
            "--coverage",
            "1",
            "--out",
        ])
        .arg(&path)
        .args(options)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = stdout.next().unwrap().unwrap();
    assert!(first.starts_with(&format!("recording {device}")), "{first}");
    let drain = std::thread::spawn(move || stdout.map(Result::unwrap).collect::<Vec<String>>());
    let stop = Arc::new(AtomicBool::new(false));
    let started = std::time::Instant::now();
    let board = pty::firmware(pty.master, config, stop.clone());
    if let Some(after_s) = interrupt_after_s {
        std::thread::sleep(std::time::Duration::from_secs_f64(after_s));
        let status = Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
    }
    let out = child.wait_with_output().unwrap();
    let ran_s = started.elapsed().as_secs_f64();
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    SerialRun {
        success: out.status.success(),
        stdout: drain.join().unwrap().join("\n"),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        report: board.join().unwrap(),
        path,
        ran_s,
        _dir: dir,
    }
}

fn board(f: impl FnOnce(&mut FirmwareConfig)) -> FirmwareConfig {
    let mut config = FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 5));
    config.lines_per_wall_s = 1000.0;
    f(&mut config);
    config
}

#[test]
fn a_silent_misconfigured_or_mute_board_is_a_clear_error_after_the_idle_timeout() {
    let _serial = one_at_a_time();
    use magcal_mockhw::firmware::{BoardFault, Output};
    // (what, the device's protocol, the board, the samples the file keeps, what the error says)
    let cases: Vec<(&str, &str, FirmwareConfig, usize, &str)> = vec![
        (
            "goes silent",
            "motioncal",
            board(|c| c.fault = Some(BoardFault::SilentAfter(300))),
            300,
            "no sample for 1.0 s after 300 samples: the board stopped sending samples",
        ),
        (
            "says nothing",
            "motioncal",
            board(|c| c.fault = Some(BoardFault::SilentAfter(0))),
            0,
            "nothing at all was received: is the board running and streaming, on this port?",
        ),
        (
            "wrong baud rate",
            "motioncal",
            board(|c| c.fault = Some(BoardFault::WrongBaud)),
            0,
            "bytes received but no readable line: wrong baud rate?",
        ),
        (
            "wrong protocol (CSV read as MotionCal)",
            "motioncal",
            board(|c| c.output = Output::Csv),
            0,
            "none a motioncal sample (the last: \"",
        ),
        (
            "wrong protocol (MotionCal read as CSV)",
            "csv",
            board(|_| {}),
            0,
            "none a csv sample (the last: \"Raw:",
        ),
    ];
    let runs: Vec<_> = cases
        .into_iter()
        .map(|(what, protocol, config, kept, says)| {
            let handle = std::thread::spawn(move || {
                serial_run(protocol, config, &["--idle-timeout", "1"], None)
            });
            (what, kept, says, handle)
        })
        .collect();
    for (what, kept, says, handle) in runs {
        let run = handle.join().unwrap();
        assert!(!run.success, "{what}: {}", run.stdout);
        assert!(run.stderr.contains(says), "{what}: {}", run.stderr);
        assert!(
            run.stderr
                .contains(&format!("keeps the {kept} samples recorded before")),
            "{what}: {}",
            run.stderr
        );
        assert!(run.ran_s < 4.0, "{what}: gave up after {:.1} s", run.ran_s);
        match Recording::read(&run.path) {
            Ok(rec) => assert_eq!(rec.len(), kept, "{what}"),
            Err(e) => assert!(
                kept == 0 && e.to_string().ends_with("no data rows"),
                "{what}: {e}"
            ),
        }
    }
}

#[test]
fn ctrl_c_ends_the_recording_with_the_data_saved_whatever_the_board_does() {
    let _serial = one_at_a_time();
    use magcal_mockhw::firmware::BoardFault;
    let cases = [
        ("silent after 200 lines", BoardFault::SilentAfter(200), 200),
        ("wrong baud rate", BoardFault::WrongBaud, 0),
    ];
    for (what, fault, kept) in cases {
        let run = serial_run(
            "motioncal",
            board(|c| c.fault = Some(fault)),
            &["--idle-timeout", "60"],
            Some(1.5),
        );
        assert!(
            run.success,
            "{what}: an interrupt is a clean stop: {}",
            run.stderr
        );
        assert!(
            run.ran_s < 3.0,
            "{what}: Ctrl-C took effect after {:.1} s",
            run.ran_s
        );
        assert!(
            run.stdout.contains(&format!("recorded {kept} samples")),
            "{what}: {}",
            run.stdout
        );
        assert!(
            run.stdout.contains("(interrupted)"),
            "{what}: {}",
            run.stdout
        );
        if kept > 0 {
            assert_eq!(Recording::read(&run.path).unwrap().len(), kept, "{what}");
        }
    }
}

#[test]
fn a_board_reset_starts_a_noted_segment_and_time_stays_true_whatever_header_it_prints() {
    let _serial = one_at_a_time();
    use magcal_mockhw::firmware::{BOOT_S, BoardFault, Output};
    for new_header in [false, true] {
        // Real time: the board's clock and the host's agree, so the bridge over the reset can be checked.
        let config = board(|c| {
            c.output = Output::Csv;
            c.lines_per_wall_s = 100.0;
            c.raw_lines = Some(500);
            c.fault = Some(BoardFault::ResetAfter {
                lines: 250,
                new_header,
            });
        });
        let run = serial_run("csv", config, &[], None);
        let what = format!("new header {new_header}");
        assert!(
            run.stderr.contains("disconnected after 500 samples"),
            "{what}: every line understood: {}",
            run.stderr
        );
        // Said live, at the board's time to the host's timing of the reset (as every row's time below).
        let said_s: Option<f64> = run
            .stdout
            .split_once("the device's clock restarted (a reset?) at t = ")
            .and_then(|(_, rest)| rest.split_once(' '))
            .and_then(|(t, _)| t.parse().ok());
        assert!(
            said_s.is_some_and(|t| (t - run.report.sample_times_s[250]).abs() < 0.1),
            "{what}: said live: {}",
            run.stdout
        );
        let rec = Recording::read(&run.path).unwrap();
        assert_eq!(rec.len(), 500, "{what}");
        let t = rec.t_s.as_ref().unwrap();
        assert!(
            t.windows(2).all(|w| w[1] > w[0]),
            "{what}: time never stands still"
        );
        // True: each row's time is the board's bench time, to the host's timing of the reset.
        let truth = &run.report.sample_times_s;
        let worst = t
            .iter()
            .zip(truth)
            .map(|(t, truth)| (t - truth).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.1, "{what}: {worst} s off the board's time");
        assert!(
            truth[250] - truth[249] > BOOT_S,
            "the board took its boot time"
        );
        let segments = rec
            .meta
            .other
            .iter()
            .find(|(k, _)| k == "segments")
            .map(|(_, v)| v.as_str());
        // At the host's timing of the reset, like every row's time (3.0 s give or take its jitter: 2.999 once).
        let restarted_s: Option<f64> = segments
            .and_then(|s| s.strip_prefix("2 (the device's clock restarted at t = "))
            .and_then(|rest| rest.split_once(' '))
            .and_then(|(t, _)| t.parse().ok());
        assert!(
            restarted_s.is_some_and(|t| (t - truth[250]).abs() < 0.1),
            "{what}: {segments:?}"
        );
        assert!(
            rec.temp_c.as_ref().unwrap().iter().all(|c| c.is_finite()),
            "{what}: the temperature column is read by name"
        );
    }
}

/// The recording's rows against what the board printed: every sample, in µT, within the print's resolution.
fn assert_rows_are_the_boards_field(
    what: &str,
    rec: &Recording,
    truth_ut: &[[f64; 3]],
    within_ut: f64,
) {
    assert_eq!(rec.len(), truth_ut.len(), "{what}: every line recorded");
    let worst = rec
        .mag_ut
        .iter()
        .zip(truth_ut)
        .flat_map(|(m, t)| (0..3).map(move |k| (m[k] - t[k]).abs()))
        .fold(0.0, f64::max);
    assert!(
        worst <= within_ut,
        "{what}: {worst} µT off the board's field"
    );
}

#[test]
fn any_line_format_is_read_in_its_unit_adafruit_xyz_counts_and_a_pattern_in_gauss() {
    let _serial = one_at_a_time();
    use magcal_mockhw::firmware::Output;
    const LINES: u64 = 400;
    const HMC5883L_UT_PER_COUNT: f64 = 100.0 / 1090.0;
    let pattern = r"^t=(?P<t_ms>\d+)ms mag=\[(?P<mx>\S+) (?P<my>\S+) (?P<mz>\S+)\] G temp=(?P<temp>\S+)C q=\[(?P<qw>\S+) (?P<qx>\S+) (?P<qy>\S+) (?P<qz>\S+)\]$";
    // (what, the device string's format, what the board prints, the resolution of its print in µT, garbage lines)
    let cases: Vec<(&str, String, Output, f64, u64)> = vec![
        // Adafruit's example prints two decimals of µT after a banner of sensor details (7 lines, none a sample).
        ("adafruit", "adafruit".into(), Output::Adafruit, 0.005, 7),
        (
            "xyz counts",
            format!("xyz:scale={HMC5883L_UT_PER_COUNT}"),
            Output::XyzCounts(HMC5883L_UT_PER_COUNT),
            HMC5883L_UT_PER_COUNT / 2.0,
            0,
        ),
        // Five decimals of gauss are 0.001 µT.
        (
            "pattern in gauss",
            format!("unit=gauss:pattern={pattern}"),
            Output::Gauss,
            0.0005,
            0,
        ),
    ];
    let runs: Vec<_> = cases
        .into_iter()
        .map(|(what, format, output, resolution_ut, garbage)| {
            let config = board(|c| {
                c.output = output;
                c.raw_lines = Some(LINES);
                c.lines_per_wall_s = 2000.0;
            });
            let handle = std::thread::spawn(move || serial_run(&format, config, &[], None));
            (what, resolution_ut, garbage, handle)
        })
        .collect();
    for (what, resolution_ut, garbage, handle) in runs {
        let run = handle.join().unwrap();
        assert!(
            run.stderr
                .contains(&format!("disconnected after {LINES} samples")),
            "{what}: every line understood: {}",
            run.stderr
        );
        let skipped = if garbage > 0 {
            format!("garbage lines skipped: {garbage} (unrecognized {garbage})")
        } else {
            "garbage lines skipped: 0".to_owned()
        };
        assert!(run.stderr.contains(&skipped), "{what}: {}", run.stderr);
        let rec = Recording::read(&run.path).unwrap();
        assert_rows_are_the_boards_field(
            what,
            &rec,
            &run.report.sample_mag_ut,
            resolution_ut + 1e-9,
        );
        if what == "pattern in gauss" {
            // The board's clock (ms), its temperature and its attitude (printed to 1e-5, normalised by the
            // reader) are read by their groups.
            let t = rec.t_s.as_ref().unwrap();
            for (t, truth) in t.iter().zip(&run.report.sample_times_s) {
                assert!(
                    (t - truth).abs() < 6e-4,
                    "{t} s against the board's {truth} s"
                );
            }
            assert!(rec.temp_c.as_ref().unwrap().iter().all(|c| c.is_finite()));
            let quat = rec.quat.as_ref().expect("the board's attitude is recorded");
            for (q, truth) in quat.iter().zip(&run.report.sample_quat) {
                assert!(
                    (0..4).all(|k| (q[k] - truth[k]).abs() < 2e-5),
                    "{q:?} against {truth:?}"
                );
            }
        } else {
            assert!(rec.quat.is_none(), "{what}: no attitude column");
        }
    }
}

#[test]
fn numbers_read_in_the_wrong_unit_are_said_before_and_while_recording() {
    let _serial = one_at_a_time();
    use magcal_mockhw::firmware::Output;
    // The board prints raw counts of 0.15 µT (a LIS2MDL's); the device string names no scale, so they are taken as
    // µT: a field of some 300 "µT".
    let config = board(|c| {
        c.output = Output::XyzCounts(0.15);
        c.raw_lines = Some(3000);
        c.lines_per_wall_s = 4000.0;
    });
    let run = serial_run("xyz", config, &[], None);
    assert!(
        run.stderr.contains(
            "note: the numbers of the xyz lines are read as µT; if the board prints gauss"
        ),
        "{}",
        run.stderr
    );
    let said = run
        .stdout
        .lines()
        .find(|l| l.starts_with("the field's magnitude is 3"))
        .unwrap_or_else(|| panic!("no live word on the unit: {}", run.stdout));
    assert!(
        said.contains("the readings are not µT") && said.contains(":scale=K"),
        "{said}"
    );
}

/// Issue 34: `magcal --device …` with no `--routine`. A real device (here a board on a pseudo-terminal) gets the free
/// routine — no jig, no known heading needed — and the summary says what the cube's poses would add; the simulated
/// main job (no arguments) keeps the cube24 routine its bench has a jig for, and writes its three files.
#[test]
fn magcal_without_a_routine_turns_a_real_device_freely_and_keeps_the_simulated_jig() {
    let _serial = one_at_a_time();
    // The simulated main job, as `cargo run --release` runs it.
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_magcal"))
        .arg("--out-dir")
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("(cube24 routine, the simulated bench's jig)")
            && stdout.contains("vector calibration")
            && !stdout.contains("note: the free routine"),
        "{stdout}"
    );
    for file in ["recording.csv", "params.toml", "report.json"] {
        assert!(dir.path().join(file).exists(), "{file}");
    }

    // A board on a serial port, turned by the bench's hand.
    let dir = tempfile::tempdir().unwrap();
    let pty = pty::open();
    let device = format!("serial:{}:115200:motioncal", pty.slave_path);
    let field = magcal_app::source::sim::FIELD_NED_UT.map(|v| v.to_string());
    let mut child = Command::new(env!("CARGO_BIN_EXE_magcal"))
        .args(["--device", &device, "--field-ned", &field.join(",")])
        .arg("--out-dir")
        .arg(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = stdout.next().unwrap().unwrap();
    assert!(
        first.starts_with(&format!(
            "magcal: recording {device} (free routine, the default for a real device"
        )) && first.contains("--routine cube24 with a cube jig"),
        "{first}"
    );
    let drain = std::thread::spawn(move || stdout.map(Result::unwrap).collect::<Vec<String>>());
    let mut config = FirmwareConfig::new(bench_config(ChipKind::Lis3mdl, 5));
    // Unplugged after 5 minutes of bench time at the latest, so that a recorder that never stops fails the test.
    config.raw_lines = Some(30_000);
    config.lines_per_wall_s = 4000.0;
    let stop = Arc::new(AtomicBool::new(false));
    let board = pty::firmware(pty.master, config, stop.clone());
    let out = child.wait_with_output().unwrap();
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    board.join().unwrap();
    let stdout = drain.join().unwrap().join("\n");
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("scalar calibration (ellipsoid fit")
            && stdout.contains("note: the free routine gives the scalar calibration")
            && stdout.contains(
                "--routine cube24 gives the vector calibration, which adds that misalignment"
            ),
        "{stdout}"
    );
    let rec = Recording::read(&dir.path().join("recording.csv")).unwrap();
    assert_eq!(rec.meta.routine.as_deref(), Some("free"));
    let params = std::fs::read_to_string(dir.path().join("params.toml")).unwrap();
    assert!(params.contains("method = \"scalar\""), "{params}");
}
