//! `magcal-batch` (issue 36): a simulated lot gives a row per board, flags the board with a magnet near, names the
//! files that failed and why, and gives the exit status `--require` asks for; a batch killed midway completes on a
//! re-run with no row twice; the recordings from physical sensors give, as a batch, the numbers `magcal-fit` gives
//! them one by one. The 200-board study of the acceptance is `#[ignore]`d (run in release by CI).

mod common;
mod lot;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use lot::{Board, Kind, LotSpec, write_lot};
use magcal_app::batch::Batch;
use magcal_app::batch::lot::median_spread;
use magcal_app::batch::row::Row;
use magcal_app::report::Report;
use serde_json::Value;

fn batch_command(args: &[&Path]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_magcal-batch"));
    cmd.args(args).arg("--quiet");
    cmd
}

fn run_batch(args: &[&Path], extra: &[&str]) -> Output {
    batch_command(args)
        .args(extra)
        .output()
        .expect("magcal-batch runs")
}

fn read_json(path: &Path) -> Batch {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The row of `board`.
fn row_of<'a>(batch: &'a Batch, board: &Board) -> &'a Row {
    batch
        .rows
        .iter()
        .find(|r| Path::new(&r.file) == board.path)
        .unwrap_or_else(|| panic!("no row for {}", board.path.display()))
}

/// Whether two JSON values are equal, numbers to a few units in the last place (serde_json's reader, without its
/// `float_roundtrip` feature, may read a number's last digit one unit off; the CSV reads back exactly).
fn same_numbers(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            (x - y).abs() <= 4.0 * f64::EPSILON * x.abs().max(y.abs())
        }
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(x, y)| same_numbers(x, y))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, v)| y.get(k).is_some_and(|w| same_numbers(v, w)))
        }
        _ => a == b,
    }
}

/// Checks every row of `batch` against the lot it was made from; returns the flagged boards' serials.
fn check_rows(batch: &Batch, boards: &[Board]) -> HashSet<String> {
    assert_eq!(batch.rows.len(), boards.len());
    for board in boards {
        let row = row_of(batch, board);
        assert_eq!(row.id, board.serial);
        assert_eq!(row.chip, lot::CHIP);
        match board.kind {
            Kind::Truncated => {
                assert_eq!(row.grade, "failed", "{row:?}");
                assert!(
                    row.reason.contains("cut off")
                        && row.reason.contains(&board.path.display().to_string()),
                    "{}",
                    row.reason
                );
            }
            Kind::NotRotated => {
                assert_eq!(row.grade, "failed", "{row:?}");
                assert!(row.reason.starts_with("cannot calibrate"), "{}", row.reason);
            }
            Kind::Normal | Kind::MagnetNear => {
                assert_eq!(row.grade, "good", "{row:?}");
                let fit = row.fit.as_ref().unwrap();
                for k in 0..3 {
                    let err = fit.offset_ut[k] - board.offset_ut[k];
                    assert!(
                        err.abs() < 5.0 * fit.offset_se_ut[k] + 0.02,
                        "{}: offset {k} off by {err} µT (SE {})",
                        board.serial,
                        fit.offset_se_ut[k]
                    );
                    let err = fit.a_diag[k] - board.truth.a[k][k];
                    assert!(
                        err.abs() < 2e-3,
                        "{}: A[{k}][{k}] off by {err}",
                        board.serial
                    );
                }
                assert!(
                    fit.effects.is_empty(),
                    "{}: {:?}",
                    board.serial,
                    fit.effects
                );
            }
        }
    }
    batch
        .lots
        .iter()
        .flat_map(|l| l.outliers.iter().map(|o| o.id.clone()))
        .collect()
}

fn serials(boards: &[Board], kind: Kind) -> HashSet<String> {
    boards
        .iter()
        .filter(|b| b.kind == kind)
        .map(|b| b.serial.clone())
        .collect()
}

#[test]
fn a_small_lot_gives_a_row_per_board_flags_the_magnet_and_names_the_failures() {
    let dir = tempfile::tempdir().unwrap();
    let lot_dir = dir.path().join("lot");
    std::fs::create_dir(&lot_dir).unwrap();
    let spec = LotSpec {
        boards: 14,
        magnets: 1,
        truncated: 1,
        unrotated: 1,
        samples: 2400,
        seed: 7,
    };
    let boards = write_lot(&lot_dir, &spec);
    let table = dir.path().join("table.csv");
    let json = dir.path().join("table.json");
    let out = run_batch(
        &[&lot_dir],
        &[
            "--out",
            table.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
            "--require",
            "usable",
        ],
    );
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(!out.status.success(), "{stdout}\n{stderr}");
    // The failing boards are listed on screen with the reason, and named in the error.
    for board in boards
        .iter()
        .filter(|b| matches!(b.kind, Kind::Truncated | Kind::NotRotated))
    {
        assert!(stdout.contains(&board.serial), "{stdout}");
        assert!(stderr.contains(&board.serial), "{stderr}");
    }
    assert!(
        stderr.contains("--require usable: 2 of 14 boards fall short"),
        "{stderr}"
    );
    let batch = read_json(&json);
    let flagged = check_rows(&batch, &boards);
    assert_eq!(flagged, serials(&boards, Kind::MagnetNear), "{stdout}");
    assert!(stdout.contains("1 board far from the lot"), "{stdout}");
    // The CSV holds the same rows as the JSON, and the lot's marks.
    let mut reader = csv::Reader::from_path(&table).unwrap();
    let rows: Vec<Row> = reader
        .records()
        .map(|r| Row::from_csv(&r.unwrap()).unwrap())
        .collect();
    assert_eq!(rows.len(), batch.rows.len());
    for (from_csv, from_json) in rows.iter().zip(&batch.rows) {
        let from_json = Row {
            lot: None,
            ..from_json.clone()
        };
        assert!(
            same_numbers(
                &serde_json::to_value(from_csv).unwrap(),
                &serde_json::to_value(&from_json).unwrap()
            ),
            "{from_csv:?}\nvs\n{from_json:?}"
        );
    }
    let csv_text = std::fs::read_to_string(&table).unwrap();
    assert!(
        csv_text.contains(" z=+") || csv_text.contains(" z=-"),
        "{csv_text}"
    );
    // A re-run fits nothing again; the table is the batch, its failures still there.
    let again = run_batch(&[&lot_dir], &["--out", table.to_str().unwrap()]);
    assert!(again.status.success(), "{}", text(&again.stderr));
    assert!(
        text(&again.stdout).starts_with("14 recordings (0 fitted now, 14 rows kept from the table"),
        "{}",
        text(&again.stdout)
    );
    assert_eq!(read_json(&json).rows.len(), 14);
    // --require is met when only the sound boards are named.
    let sound: Vec<&Path> = boards
        .iter()
        .filter(|b| matches!(b.kind, Kind::Normal | Kind::MagnetNear))
        .map(|b| b.path.as_path())
        .collect();
    let sound_only = run_batch(&sound, &["--require", "good"]);
    assert!(sound_only.status.success(), "{}", text(&sound_only.stderr));
}

#[test]
fn a_batch_killed_midway_completes_on_a_rerun_without_a_row_twice() {
    let dir = tempfile::tempdir().unwrap();
    let lot_dir = dir.path().join("lot");
    std::fs::create_dir(&lot_dir).unwrap();
    let spec = LotSpec {
        boards: 10,
        magnets: 0,
        truncated: 1,
        unrotated: 0,
        samples: 1600,
        seed: 11,
    };
    write_lot(&lot_dir, &spec);
    let table = dir.path().join("table.csv");
    let rows_in = |path: &Path| {
        std::fs::read_to_string(path)
            .map(|t| t.lines().count().saturating_sub(1))
            .unwrap_or(0)
    };
    let mut child = batch_command(&[&lot_dir])
        .args(["--jobs", "1", "--no-diagnose", "--out"])
        .arg(&table)
        .spawn()
        .unwrap();
    let start = Instant::now();
    while rows_in(&table) < 3 && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL: no chance to tidy up.
    child.wait().unwrap();
    let left = rows_in(&table);
    assert!(
        (3..10).contains(&left),
        "killed with {left} rows in the table"
    );
    let out = run_batch(
        &[&lot_dir],
        &["--no-diagnose", "--out", table.to_str().unwrap()],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains(&format!("{} fitted now", 10 - left)),
        "{}",
        text(&out.stdout)
    );
    // The table is complete, each recording once, and as an uninterrupted batch makes it.
    let whole = dir.path().join("whole.csv");
    let out = run_batch(
        &[&lot_dir],
        &["--no-diagnose", "--out", whole.to_str().unwrap()],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(&table).unwrap(),
        std::fs::read_to_string(&whole).unwrap()
    );
    // Options other than the table's are refused, not mixed in.
    let out = run_batch(&[&lot_dir], &["--out", table.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--no-diagnose"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn the_serial_magcal_record_writes_names_the_board_in_the_table() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--device",
            "sim",
            "--routine",
            "free",
            "--serial",
            "SN-0042 rev B",
            "--out",
        ])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        std::fs::read_to_string(&rec)
            .unwrap()
            .contains("\n# serial: SN-0042 rev B\n")
    );
    let json = dir.path().join("t.json");
    let out = run_batch(
        &[&rec],
        &["--no-diagnose", "--json", json.to_str().unwrap()],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let batch = read_json(&json);
    assert_eq!(batch.rows[0].id, "SN-0042 rev B");
    assert_eq!(batch.rows[0].chip, "lis3mdl");
    let bad = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--device",
            "sim",
            "--routine",
            "free",
            "--serial",
            " x",
            "--out",
        ])
        .arg(dir.path().join("bad.csv"))
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(
        text(&bad.stderr).contains("--serial"),
        "{}",
        text(&bad.stderr)
    );
}

/// Fits each recording with `magcal-fit --report` and compares its figures with the batch's row of it: the same to
/// the digit; a file magcal-fit refuses is a failed row with magcal-fit's reason.
fn same_as_magcal_fit(files: &[PathBuf]) {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("batch.json");
    let out = run_batch(
        &files.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
        &["--json", json.to_str().unwrap()],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let batch = read_json(&json);
    assert_eq!(batch.rows.len(), files.len());
    for (file, row) in files.iter().zip(&batch.rows) {
        assert_eq!(Path::new(&row.file), file);
        let report_path = dir.path().join("report.json");
        let _ = std::fs::remove_file(&report_path);
        let fit = Command::new(env!("CARGO_BIN_EXE_magcal-fit"))
            .arg(file)
            .arg("--report")
            .arg(&report_path)
            .output()
            .unwrap();
        let Some(f) = &row.fit else {
            assert!(!fit.status.success(), "{}", file.display());
            let said = text(&fit.stderr);
            let reason = row.reason.strip_prefix("not read: ").unwrap_or(&row.reason);
            assert!(said.contains(reason), "{said}\nvs\n{reason}");
            continue;
        };
        assert!(fit.status.success(), "{}", text(&fit.stderr));
        let report: Report =
            serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
        let name = file.display();
        let verdict = report.verdict.as_ref().unwrap();
        assert_eq!(row.grade, verdict.grade, "{name}");
        assert_eq!(row.reason, verdict.reason, "{name}");
        assert_eq!(f.method, report.method, "{name}");
        assert_eq!(f.offset_ut, report.calibration.offset_ut, "{name}");
        assert_eq!(f.offset_se_ut, report.calibration.offset_se_ut, "{name}");
        let a = report.calibration.a;
        assert_eq!(f.a_diag, [a[0][0], a[1][1], a[2][2]], "{name}");
        assert_eq!(f.rms_ut, report.residual.rms_ut, "{name}");
        assert_eq!(f.noise_floor_ut, report.residual.noise_floor_ut, "{name}");
        assert_eq!(f.sphere_fraction, report.coverage.sphere_fraction, "{name}");
        assert_eq!(
            f.left_worst_deg,
            report.heading.as_ref().map(|h| h.left_worst_deg),
            "{name}"
        );
        let ids: Vec<String> = report
            .diagnosis
            .as_ref()
            .map(|d| d.effects.iter().map(|e| e.id.clone()).collect())
            .unwrap_or_default();
        assert_eq!(f.effects, ids, "{name}");
    }
}

#[test]
fn physical_recordings_as_a_batch_give_magcal_fits_numbers() {
    same_as_magcal_fit(&[
        common::real("hmc5883l/set2_full_sphere.csv"),
        common::real("inria-nexus5/nexus5_nodist_AR.csv"),
        common::real("inria-nexus5/nexus5_calib_dance_android_hardiron.csv"),
    ]);
}

/// Every recording of the shared folder, as the acceptance 4 asks.
#[test]
#[ignore = "every physical recording with the diagnosis, twice: run in release"]
fn every_physical_recording_as_a_batch_gives_magcal_fits_numbers() {
    let mut files = Vec::new();
    let root = common::real("");
    for dir in std::fs::read_dir(&root).unwrap() {
        let dir = dir.unwrap().path();
        if dir.is_dir() {
            for f in std::fs::read_dir(&dir).unwrap() {
                let f = f.unwrap().path();
                if f.extension().is_some_and(|e| e == "csv") {
                    files.push(f);
                }
            }
        }
    }
    files.sort();
    assert!(files.len() >= 10, "{files:?}");
    same_as_magcal_fit(&files);
}

/// The acceptance 1: 200 simulated boards of one chip kind — hard and soft iron and noise spread, 5 with a
/// magnet near, 3 files cut off, 2 boards not rotated enough.
#[test]
#[ignore = "200 recordings of 6000 samples with the diagnosis: run in release"]
fn a_lot_of_200_boards() {
    let dir = tempfile::tempdir().unwrap();
    let lot_dir = dir.path().join("lot");
    std::fs::create_dir(&lot_dir).unwrap();
    let spec = LotSpec {
        boards: 200,
        magnets: 5,
        truncated: 3,
        unrotated: 2,
        samples: 6000,
        seed: 36,
    };
    let boards = write_lot(&lot_dir, &spec);
    let json = dir.path().join("lot.json");
    let start = Instant::now();
    let out = run_batch(&[&lot_dir], &["--json", json.to_str().unwrap()]);
    let elapsed_s = start.elapsed().as_secs_f64();
    let stdout = text(&out.stdout);
    println!("{stdout}");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let batch = read_json(&json);
    let flagged = check_rows(&batch, &boards);
    assert_eq!(flagged, serials(&boards, Kind::MagnetNear));
    // The lot's spread against the simulated boards' own, by the same estimator, over the boards fitted.
    let lot = &batch.lots[0];
    assert_eq!(lot.boards, 195);
    let fitted: Vec<&Board> = boards
        .iter()
        .filter(|b| matches!(b.kind, Kind::Normal | Kind::MagnetNear))
        .collect();
    println!(
        "parameter       lot median   lot spread   simulated median   simulated spread   ratio"
    );
    for (stats, p) in lot
        .parameters
        .iter()
        .zip(&magcal_app::batch::lot::PARAMETERS)
    {
        let name = p.name;
        let truth: Vec<f64> = fitted.iter().map(|b| true_parameter(b, name)).collect();
        let (median, spread) = median_spread(&truth);
        let ratio = stats.spread / spread;
        println!(
            "{name:<14} {:>11.4} {:>12.4} {median:>18.4} {spread:>18.4} {ratio:>7.3}",
            stats.median, stats.spread
        );
        assert!(
            (ratio - 1.0).abs() < 0.1,
            "{name}: spread {} vs {spread}",
            stats.spread
        );
    }
    println!("200 boards in {elapsed_s:.1} s");
}

/// A board's true value of the lot parameter `name`.
fn true_parameter(board: &Board, name: &str) -> f64 {
    let a = board.truth.a;
    let off = || (0..3).flat_map(|j| (0..3).filter(move |&k| k != j).map(move |k| a[j][k]));
    match name {
        "offset_ut.x" => board.offset_ut[0],
        "offset_ut.y" => board.offset_ut[1],
        "offset_ut.z" => board.offset_ut[2],
        "A.xx" => a[0][0],
        "A.yy" => a[1][1],
        "A.zz" => a[2][2],
        "A_offdiag_min" => off().fold(f64::INFINITY, f64::min),
        "A_offdiag_max" => off().fold(f64::NEG_INFINITY, f64::max),
        _ => panic!("unknown parameter {name}"),
    }
}
