//! Issue 37, acceptance 3: a cube jig whose edge is not on true north. `magcal-record --device sim:CHIP --routine
//! cube24 --sim-jig-heading DEG` (the virtual hand takes the 24 poses against the turned edge) then `magcal-fit`:
//! for each of the five chips and the edge turned by 5°, 10°, 30° and 90° (and onto magnetic north, as with a
//! compass), the verdict is the one with the edge on north, the angle is named within 0.5°, and the calibration
//! (what the parameters file and the exports hold) is the aligned one within the standard errors.
//!
//! The sensor and the noise are drawn from the same seed for every angle, but the sensor sees the field from other
//! directions at each pose, so the fits differ by their own errors: each parameter's difference is checked against
//! the two standard errors combined, within [`MAX_Z`]; 5 chips × 5 angles × 15 parameters are 375 such ratios.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_app::verdict::assess;
use magcal_sim::{ChipModel, Scenario, SensorTruth, Trajectory, simulate, stream_rng};
use rand::RngExt;
use serde_json::Value;

const CHIPS: [&str; 5] = ["lis3mdl", "lis2mdl", "qmc5883l", "hmc5883l", "mmc5983ma"];
/// The edge's headings tried, degrees east of true north.
const HEADINGS_DEG: [f64; 4] = [5.0, 10.0, 30.0, 90.0];
/// The declination of the simulated bench's field (19.8, 1.2, 45.3 µT NED), degrees: an edge lined up with a compass.
fn compass_deg() -> f64 {
    1.2f64.atan2(19.8).to_degrees()
}
/// The largest difference from the aligned calibration, in combined standard errors (at 4, an honest set of 375
/// normal ratios has one outside 2 % of the time).
const MAX_Z: f64 = 4.0;
/// How close the angle named must be, degrees.
const ANGLE_DEG: f64 = 0.5;

/// Records `sim:CHIP` on the cube jig with its edge turned by `heading_deg`.
fn record(dir: &Path, chip: &str, seed: u64, heading_deg: f64) -> PathBuf {
    let rec = dir.join(format!("{chip}-{heading_deg}.csv"));
    let out = Command::new(env!("CARGO_BIN_EXE_magcal-record"))
        .args(["--device", &format!("sim:{chip}"), "--routine", "cube24"])
        .args(["--sim-seed", &seed.to_string()])
        .args(["--sim-jig-heading", &heading_deg.to_string()])
        .arg("--out")
        .arg(&rec)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    rec
}

/// Fits `rec` with `extra` options, writing the parameters file; returns the report and the summary.
fn fit(rec: &Path, extra: &[&str]) -> (Value, String) {
    let tag = extra.concat();
    let report = rec.with_extension(format!("{tag}.json"));
    let params = rec.with_extension(format!("{tag}.toml"));
    let mut args = vec![
        rec.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--out",
        params.to_str().unwrap(),
    ];
    args.extend(extra);
    let out = common::magcal_fit(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    (r, String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The calibration's A, b and offset with their standard errors, as (value, SE) pairs.
fn parameters(r: &Value) -> Vec<(f64, f64)> {
    let c = &r["calibration"];
    let pairs = |v: &str, se: &str| -> Vec<(f64, f64)> {
        common::floats(&c[v])
            .into_iter()
            .zip(common::floats(&c[se]))
            .collect()
    };
    let (a, a_se) = (common::matrix(&c["A"]), common::matrix(&c["A_se"]));
    let mut all: Vec<(f64, f64)> = a
        .iter()
        .flatten()
        .copied()
        .zip(a_se.iter().flatten().copied())
        .collect();
    all.extend(pairs("b_ut", "b_se_ut"));
    all.extend(pairs("offset_ut", "offset_se_ut"));
    all
}

/// The verdict's grade and what to do (its reason quotes the figures, which differ by their errors).
fn verdict(r: &Value) -> (String, String) {
    let v = &r["verdict"];
    (v["grade"].to_string(), v["todo"].to_string())
}

#[test]
fn a_jig_turned_from_true_north_is_named_and_changes_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let mut worst_z = 0.0f64;
    for (i, chip) in CHIPS.iter().enumerate() {
        let seed = 40 + i as u64;
        let (aligned, text) = fit(&record(dir.path(), chip, seed, 0.0), &[]);
        assert!(aligned.get("reference_heading").is_none(), "{chip}: {text}");
        assert!(!text.contains("reference:"), "{chip}: {text}");
        assert_eq!(aligned["verdict"]["grade"], "good", "{chip}: {text}");
        let want = parameters(&aligned);
        for heading_deg in HEADINGS_DEG.into_iter().chain([compass_deg()]) {
            let what = format!("{chip}, edge {heading_deg:.2}° east");
            let rec = record(dir.path(), chip, seed, heading_deg);
            let (r, text) = fit(&rec, &[]);
            let h = &r["reference_heading"];
            let found = h["heading_deg"]
                .as_f64()
                .unwrap_or_else(|| panic!("{what}: {text}"));
            assert!((found - heading_deg).abs() <= ANGLE_DEG, "{what}: {found}");
            assert_eq!(verdict(&r), verdict(&aligned), "{what}: {text}");
            assert!(
                text.contains(&format!(
                    "the jig's edge points {found:.2}° east of true north"
                )) && text.contains("the calibration does not depend on it"),
                "{what}: {text}"
            );
            let compass = heading_deg == compass_deg();
            assert_eq!(h["magnetic_north"].as_bool(), Some(compass), "{what}");
            assert_eq!(text.contains("a compass"), compass, "{what}: {text}");
            // Nothing of another convention, a clock or the local field.
            assert!(
                !text.contains("convention") && !text.contains("mind the local field"),
                "{what}: {text}"
            );
            let mut case_z = 0.0f64;
            for (k, ((a, se_a), (b, se_b))) in want.iter().zip(parameters(&r)).enumerate() {
                let z = (b - a) / se_a.hypot(se_b);
                case_z = case_z.max(z.abs());
                assert!(
                    z.abs() <= MAX_Z,
                    "{what}: parameter {k} {a} → {b}: {z:.2} SE"
                );
            }
            worst_z = worst_z.max(case_z);
            println!(
                "| {chip} | {heading_deg:.2} | {found:.3} ± {:.3} | {} / {} | {case_z:.2} |",
                h["se_deg"].as_f64().unwrap(),
                aligned["verdict"]["grade"].as_str().unwrap(),
                r["verdict"]["grade"].as_str().unwrap()
            );
            // Without the diagnosis the quaternions are turned into the expected field as they are read: the fit,
            // off by the turn, is made again with them, and finds the same heading.
            let (quick, text) = fit(&rec, &["--no-diagnose"]);
            let again = quick["reference_heading"]["heading_deg"].as_f64();
            assert!(
                again.is_some_and(|a| (a - found).abs() < 0.05),
                "{what}: {text}"
            );
            assert_eq!(quick["verdict"]["grade"], "good", "{what}: {text}");
        }
    }
    println!("the largest difference from the aligned calibration: {worst_z:.2} combined SE");
}

/// One simulated recording of `chip` on `trajectory` with the reference's north `heading_deg` east of true north,
/// calibrated and graded: the heading found (degrees, SE) and the grade, and whether another convention or clock
/// was named.
fn heading_found(
    chip: &str,
    trajectory: Trajectory,
    seed: u64,
    heading_deg: f64,
) -> (Option<(f64, f64)>, String, bool) {
    let chip = ChipModel::by_name(chip).unwrap();
    let mut s = Scenario::new(&chip, trajectory, seed);
    s.sensor = SensorTruth::random(0.1, 30.0, 3.0, &mut stream_rng(seed, 0));
    s.reference_heading_deg = heading_deg;
    let run = simulate(&s).unwrap();
    let field = ReferenceField::Vector {
        field_ned_ut: s.field_ned_ut,
        source: "test".into(),
    };
    let cal = calibrate(&run.recording, Method::Vector, field, true).unwrap();
    let grade = assess(&cal, &run.recording, false)
        .verdict
        .grade
        .name()
        .to_owned();
    let found = cal
        .reference_heading
        .as_ref()
        .map(|h| (h.estimate.heading_deg, h.estimate.se_deg));
    (found, grade, cal.reference.is_some())
}

/// The study behind acceptance 3 (`cargo test --release -- --ignored`): 40 seeds per chip on the cube jig and 40 per
/// chip of a hand-held tumble against a capture volume, each with its north 1°–180° east or west: every heading
/// is found within 0.5°, the verdict is good, no other convention is named, and the errors over their standard
/// errors have an RMS of 0.5–1.6 (honest standard errors) and none beyond 4.5.
#[test]
#[ignore = "a study of 400 recordings: run in release"]
fn every_heading_is_found_within_its_standard_error() {
    let z = std::sync::Mutex::new(Vec::new());
    for trajectory in [
        Trajectory::Cube24 {
            dwell_s: 2.0,
            transition_s: 3.0,
        },
        Trajectory::Tumble {
            duration_s: 60.0,
            rate_rad_s: 1.0,
        },
    ] {
        for chip in CHIPS {
            common::for_each_seed(40, |seed| {
                let mut rng = stream_rng(seed, 99);
                let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                let heading_deg: f64 = sign * rng.random_range(1.0..180.0);
                let what = format!(
                    "{chip} {} seed {seed}, {heading_deg:.2}°",
                    trajectory.routine()
                );
                let (found, grade, doubt) =
                    heading_found(chip, trajectory.clone(), seed, heading_deg);
                let (got, se) = found.unwrap_or_else(|| panic!("{what}: not found"));
                let err = (got - heading_deg + 540.0).rem_euclid(360.0) - 180.0;
                assert!(err.abs() <= ANGLE_DEG, "{what}: found {got}");
                assert_eq!(grade, "good", "{what}");
                assert!(!doubt, "{what}: another convention or clock named");
                z.lock().unwrap().push((err / se, what));
            });
        }
    }
    let z = z.into_inner().unwrap();
    let rms = (z.iter().map(|(v, _)| v * v).sum::<f64>() / z.len() as f64).sqrt();
    let (worst, what) = z
        .iter()
        .max_by(|a, b| a.0.abs().total_cmp(&b.0.abs()))
        .unwrap();
    println!(
        "{} headings: RMS error/SE {rms:.2}, worst {worst:.2} ({what})",
        z.len()
    );
    assert!((0.5..=1.6).contains(&rms), "RMS error/SE {rms:.2}");
    assert!(worst.abs() <= 4.5, "{what}: {worst:.2} SE");
}
