//! Acceptance: discrete poses and small files (a jig's 24 poses, rows in random order, one averaged row per pose).
//!
//! The noise floor comes from the spread within each pose (never from the jumps between them), and the
//! errors-in-variables correction can never exceed what the residual holds, so pose data does not inflate `A`:
//! - rows in random order (the seed paper's `a`, `b`, 5000 rows of `rx,ry,rz`, 0.01 µT noise) recover `a` within
//!   2e-4 and `b` within 2e-3 µT;
//! - 24 poses × 1, 3, 10 and 50 samples (0.05 µT noise, 200 seeds each) recover `A` and `b` within 2 standard errors
//!   as often as honest uncertainties do (the uncertainty study extended to pose data: heavy, in release);
//! - one averaged row per pose of a 24-pose jig is fitted (72 equations for 12 unknowns), with a note that the
//!   diagnosis needs more samples;
//! - `magcal-record --device sim:qmc5883l --rate 10 --routine cube24` recovers the simulated truth within 3 SE.

mod common;

use std::fmt::Write as _;
use std::path::Path;

use common::{floats, magcal_fit, matrix};
use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_app::source::sim::TruthFile;
use magcal_calib::frames::{self, Mat3};
use magcal_recording::{Metadata, Recording};
use magcal_sim::{SensorTruth, stream_rng};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, UnitSphere};

/// The seed paper's vector calibration (centre position).
const PAPER_A: Mat3 = [
    [0.4116, 0.0056, 0.0002],
    [-0.0004, 1.0129, 0.0004],
    [0.0005, -0.0001, 1.1823],
];
const PAPER_B_UT: [f64; 3] = [-4.2161, -8.4722, 1.2469];

/// The 24 rotations of a cube (sensor → world): signed permutation matrices of determinant +1.
fn cube_rotations() -> Vec<Matrix3<f64>> {
    let perms = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut out = Vec::new();
    for p in perms {
        for signs in 0..8 {
            let m = Matrix3::from_fn(|r, c| {
                if c == p[r] {
                    if signs >> r & 1 == 1 { -1.0 } else { 1.0 }
                } else {
                    0.0
                }
            });
            if m.determinant() > 0.0 {
                out.push(m);
            }
        }
    }
    assert_eq!(out.len(), 24);
    out
}

/// The raw reading of a sensor with truth `a`, `b` in the field `r` (sensor axes).
fn raw_of(a: &Mat3, b: [f64; 3], r: [f64; 3]) -> Vector3<f64> {
    let a = Matrix3::from_fn(|j, k| a[j][k]);
    a.try_inverse().unwrap() * (Vector3::from(r) - Vector3::from(b))
}

fn csv_line(cols: &[f64]) -> String {
    let cells: Vec<String> = cols.iter().map(|v| format!("{v:.6}")).collect();
    cells.join(",")
}

#[test]
fn rows_in_random_order_recover_the_seed_papers_calibration() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let noise = Normal::new(0.0, 0.01).unwrap();
    let mut text = String::from("# magcal-recording v1\nmx,my,mz,rx,ry,rz\n");
    for _ in 0..5000 {
        let d: [f64; 3] = UnitSphere.sample(&mut rng);
        let r = frames::scale(d, 35.0);
        let m = raw_of(&PAPER_A, PAPER_B_UT, r).map(|v| v + noise.sample(&mut rng));
        let _ = writeln!(text, "{}", csv_line(&[m.x, m.y, m.z, r[0], r[1], r[2]]));
    }
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("shuffled.csv");
    std::fs::write(&rec, text).unwrap();
    let r = common::fit_report(&rec, &[]);
    assert_eq!(r["method"], "vector");
    let a = matrix(&r["calibration"]["A"]);
    let b = floats(&r["calibration"]["b_ut"]);
    for j in 0..3 {
        for k in 0..3 {
            assert!((a[j][k] - PAPER_A[j][k]).abs() < 2e-4, "A = {a:?}");
        }
        assert!((b[j] - PAPER_B_UT[j]).abs() < 2e-3, "b = {b:?}");
    }
    // The floor the summary compares the residual with is the residual's, not the rotation's 10⁴ µT jumps.
    let floor = r["residual"]["noise_floor_ut"].as_f64().unwrap();
    let rms = r["residual"]["rms_ut"].as_f64().unwrap();
    assert!(
        floor <= 1.25 * rms && floor > 0.0,
        "floor {floor} vs residual {rms}"
    );
    // The summary does not print that bound as the sensor's noise, nor a heading noise of nothing.
    let out = magcal_fit(&[rec.to_str().unwrap(), "--field-ned", "20,1,30"]);
    let summary = String::from_utf8_lossy(&out.stdout);
    assert!(
        summary.contains("the sensor's noise not measured")
            && summary.contains("a single reading's noise: not measured")
            && !summary.contains("(×1.00)"),
        "{summary}"
    );
}

/// A jig recording: 24 poses × `per_pose` samples of a random sensor, 0.05 µT noise, `rx,ry,rz` per sample.
fn jig(per_pose: usize, seed: u64) -> (Recording, SensorTruth) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let truth = SensorTruth::random(0.1, 40.0, 3.0, &mut stream_rng(seed, 16));
    let field = frames::field_from_angles(
        rng.random_range(-15.0..15.0),
        rng.random_range(-70.0..75.0),
        rng.random_range(25.0..65.0),
    );
    let noise = Normal::new(0.0, 0.05).unwrap();
    let (mut mag, mut reference) = (Vec::new(), Vec::new());
    for rot in cube_rotations() {
        let r = rot.transpose() * Vector3::from(field);
        let r = [r.x, r.y, r.z];
        let m = raw_of(&truth.a, truth.b_ut, r);
        for _ in 0..per_pose {
            mag.push([m.x, m.y, m.z].map(|v| v + noise.sample(&mut rng)));
            reference.push(r);
        }
    }
    let rec = Recording {
        meta: Metadata::default(),
        t_s: None,
        mag_ut: mag,
        temp_c: None,
        quat: None,
        ref_ut: Some(reference),
        gyro_rad_s: None,
        currents: Vec::new(),
        extra: Vec::new(),
    };
    (rec, truth)
}

#[test]
#[ignore = "statistics over 800 jig recordings: run in release (CI does)"]
fn pose_data_recovers_a_and_b_within_honest_standard_errors() {
    println!("| samples per pose | fits | within 2 SE | mean error/SE | SD of error/SE |");
    println!("|---|---|---|---|---|");
    for per_pose in [1, 3, 10, 50] {
        let mut z = Vec::new();
        for seed in 0..200 {
            let (rec, truth) = jig(per_pose, 1000 * per_pose as u64 + seed);
            let cal = calibrate(&rec, Method::Auto, ReferenceField::Unknown, false).unwrap();
            let (a_se, b_se) = cal.standard_errors();
            let model = cal.model();
            for j in 0..3 {
                for k in 0..3 {
                    z.push((model.a[j][k] - truth.a[j][k]) / a_se[j][k]);
                }
                z.push((model.b_ut[j] - truth.b_ut[j]) / b_se[j]);
            }
        }
        let n = z.len() as f64;
        let within = z.iter().filter(|v| v.abs() <= 2.0).count() as f64 / n;
        let mean = z.iter().sum::<f64>() / n;
        let sd = (z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        println!(
            "| {per_pose} | 200 | {:.1} % | {mean:+.3} | {sd:.3} |",
            100.0 * within
        );
        // Honest: about 95 % within 2 SE (t with 20 degrees of freedom for one row per pose: 94 %).
        assert!(within >= 0.92, "{per_pose} per pose: {within} within 2 SE");
        assert!((0.8..=1.25).contains(&sd), "{per_pose} per pose: SD {sd}");
        assert!(mean.abs() < 0.15, "{per_pose} per pose: mean {mean}");
    }
}

/// Writes a recording with one averaged row per pose of a 24-pose jig: quaternions (with the world field in the
/// metadata) or `rx,ry,rz`.
fn averaged_jig(dir: &Path, quaternions: bool) -> (std::path::PathBuf, SensorTruth) {
    let truth = SensorTruth::random(0.1, 30.0, 2.0, &mut stream_rng(9, 16));
    let field = [19.8, 1.2, 45.3];
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let noise = Normal::new(0.0, 0.02).unwrap();
    let mut text = String::from("# magcal-recording v1\n");
    if quaternions {
        text += "# field_ned_ut: 19.8, 1.2, 45.3\nmx,my,mz,qw,qx,qy,qz\n";
    } else {
        text += "mx,my,mz,rx,ry,rz\n";
    }
    for rot in cube_rotations() {
        let r = rot.transpose() * Vector3::from(field);
        let m = raw_of(&truth.a, truth.b_ut, [r.x, r.y, r.z]).map(|v| v + noise.sample(&mut rng));
        let extra: Vec<f64> = if quaternions {
            let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot));
            vec![q.w, q.i, q.j, q.k]
        } else {
            vec![r.x, r.y, r.z]
        };
        let mut cols = vec![m.x, m.y, m.z];
        cols.extend(extra);
        let _ = writeln!(text, "{}", csv_line(&cols));
    }
    let path = dir.join(if quaternions {
        "jig_q.csv"
    } else {
        "jig_r.csv"
    });
    std::fs::write(&path, text).unwrap();
    (path, truth)
}

#[test]
fn one_averaged_row_per_pose_is_fitted_not_refused() {
    let dir = tempfile::tempdir().unwrap();
    for quaternions in [true, false] {
        let (path, truth) = averaged_jig(dir.path(), quaternions);
        let params = dir.path().join("p.toml");
        let out = magcal_fit(&[path.to_str().unwrap(), "--out", params.to_str().unwrap()]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{}{}",
            stdout,
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(stdout.contains("vector calibration"), "{stdout}");
        assert!(stdout.contains("not diagnosed"), "{stdout}");
        let r = common::fit_report(&path, &[]);
        let a = matrix(&r["calibration"]["A"]);
        let a_se = matrix(&r["calibration"]["A_se"]);
        let b = floats(&r["calibration"]["b_ut"]);
        let b_se = floats(&r["calibration"]["b_se_ut"]);
        for j in 0..3 {
            for k in 0..3 {
                assert!(
                    (a[j][k] - truth.a[j][k]).abs() < 4.0 * a_se[j][k],
                    "A = {a:?}"
                );
            }
            assert!((b[j] - truth.b_ut[j]).abs() < 4.0 * b_se[j], "b = {b:?}");
        }
    }
}

#[test]
fn the_recorders_cube24_at_10_hz_recovers_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("c24.csv");
    let truth = dir.path().join("truth.toml");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args([
            "--device",
            "sim:qmc5883l",
            "--rate",
            "10",
            "--routine",
            "cube24",
            "--field-ned",
            "19.8,1.2,45.3",
            "--out",
        ])
        .arg(&rec)
        .arg("--truth")
        .arg(&truth)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let truth = TruthFile::read(&truth).unwrap();
    let r = common::fit_report(&rec, &["--no-diagnose"]);
    let a = matrix(&r["calibration"]["A"]);
    let a_se = matrix(&r["calibration"]["A_se"]);
    let b = floats(&r["calibration"]["b_ut"]);
    let b_se = floats(&r["calibration"]["b_se_ut"]);
    for j in 0..3 {
        for k in 0..3 {
            let z = (a[j][k] - truth.a[j][k]) / a_se[j][k];
            assert!(z.abs() < 3.0, "A[{j}][{k}] {z:.1} SE off: {a:?}");
        }
        let z = (b[j] - truth.b_ut[j]) / b_se[j];
        assert!(z.abs() < 3.0, "b[{j}] {z:.1} SE off: {b:?}");
    }
    assert!(
        r["noise"]["source"].as_str().unwrap().contains("poses"),
        "{}",
        r["noise"]
    );
}
