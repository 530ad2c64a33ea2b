//! Acceptance (issue 10): on the physical recordings with real disturbances in `../shared/data/real/` the diagnosis
//! locates every gross disturbance, models or excludes it, and the final calibration lands within tolerance of the
//! truth the dataset gives; on the undisturbed ones it finds no disturbance and does not make the fit worse. The
//! three BROAD recordings are also fitted with their quaternion columns removed (the scalar method, as a hand-held
//! recording without a reference would be).

mod common;

use std::path::{Path, PathBuf};

use common::{effect_ids, fit_report, floats, magcal_apply, magcal_fit, matrix, real};
use magcal_app::params::ParamsFile;
use magcal_calib::{Inputs, frames};
use magcal_recording::Recording;
use serde_json::Value;

/// Tolerances of the issue: final A within this of I (largest element) …
const A_TOL: f64 = 0.065;
/// … and the offset within this of the truth, µT.
const OFFSET_TOL_UT: f64 = 2.9;

const BROAD_02: &str = "broad/broad_02_undisturbed_slow_rotation.csv";
const BROAD_29: &str = "broad/broad_29_disturbed_stationary_magnet_B.csv";
const BROAD_33: &str = "broad/broad_33_disturbed_attached_magnet_2cm.csv";
const NEXUS_NODIST: &str = "inria-nexus5/nexus5_nodist_AR.csv";
const NEXUS_DIST: &str = "inria-nexus5/nexus5_dist_AR.csv";

/// Largest |A − I| element.
fn a_error(a: &[[f64; 3]; 3]) -> f64 {
    (0..9)
        .map(|i| (a[i / 3][i % 3] - if i / 3 == i % 3 { 1.0 } else { 0.0 }).abs())
        .fold(0.0, f64::max)
}

fn offset(r: &Value) -> [f64; 3] {
    let o = floats(&r["calibration"]["offset_ut"]);
    [o[0], o[1], o[2]]
}

/// Checks the final calibration of report `r` against A ≈ I and `offset_ut`.
fn assert_within(r: &Value, offset_ut: [f64; 3], what: &str) {
    let a = matrix(&r["calibration"]["A"]);
    assert!(a_error(&a) <= A_TOL, "{what}: A = {a:?}");
    let o = offset(r);
    let e = frames::norm(frames::sub(o, offset_ut));
    assert!(e <= OFFSET_TOL_UT, "{what}: offset {o:?}, {e:.2} µT off");
}

/// The located spans of a report, (t0, t1) in seconds.
fn spans(r: &Value) -> Vec<(f64, f64)> {
    r["diagnosis"]["spans"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| (s["t0_s"].as_f64().unwrap(), s["t1_s"].as_f64().unwrap()))
        .collect()
}

/// Whether some span covers most of `[t0, t1]`.
fn located(spans: &[(f64, f64)], t0: f64, t1: f64) -> bool {
    spans
        .iter()
        .any(|(a, b)| (b.min(t1) - a.max(t0)).max(0.0) >= 0.5 * (t1 - t0))
}

/// Undisturbed: no gross finding, no located segment, and the final model no worse than the base on held-out data.
fn assert_undisturbed(r: &Value, what: &str) {
    let ids = effect_ids(r);
    for id in [
        "disturbance",
        "bias_window",
        "bias_step",
        "nonlinearity",
        "magnet_nearby",
    ] {
        assert!(!ids.contains(&id), "{what}: found {ids:?}");
    }
    assert!(spans(r).is_empty(), "{what}: spans {:?}", spans(r));
    assert!(!other_state_warned(r), "{what}: {}", r["warnings"]);
    let todo = r["verdict"]["todo"].as_str().unwrap();
    assert!(!todo.contains("rather than for longer"), "{what}: {todo}");
    assert!(
        r["diagnosis"]["located"]["segments"]
            .as_array()
            .unwrap()
            .is_empty(),
        "{what}: {}",
        r["diagnosis"]["located"]
    );
    let (base, fin) = (
        r["base"]["holdout_rms_ut"].as_f64().unwrap(),
        r["residual"]["holdout_rms_ut"].as_f64().unwrap(),
    );
    assert!(fin <= base, "{what}: held-out {base} → {fin} µT");
}

#[test]
fn broad_33_the_magnet_attached_to_the_board_is_a_bias_window() {
    let r = fit_report(&real(BROAD_33), &[]);
    assert_eq!(r["diagnosis"]["verdict"], "mismatch");
    let w = r["diagnosis"]["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["id"] == "bias_window")
        .unwrap_or_else(|| panic!("no bias_window in {}", r["diagnosis"]["effects"]));
    // Attached by hand around 40–42 s, taken off around 98.6 s.
    let (t0, t1) = (
        w["params"]["t0_s"].as_f64().unwrap(),
        w["params"]["t1_s"].as_f64().unwrap(),
    );
    assert!((39.0..=44.0).contains(&t0), "attached at {t0} s");
    assert!((96.6..=100.6).contains(&t1), "taken off at {t1} s");
    assert_within(&r, [0.0; 3], "broad 33");
    // A third of the recording in another state is said, with which state was calibrated.
    assert!(
        other_state_warned(&r),
        "no warning of the other offset: {}",
        r["warnings"]
    );
    // What to do is to take the magnet away, not to record for longer (as the verdict said when the fit's own
    // uncertainty dominated, its coverage cut by the 38 % left out).
    let todo = r["verdict"]["todo"].as_str().unwrap();
    assert!(
        todo.contains("magnets, metal and cables away from the sensor rather than for longer"),
        "{todo}"
    );
}

/// Issue 34: the summary's first line and the verdict say the rows left out on the same base — BROAD 33's verdict
/// said "38 % of the readings were left out" under "21513 of 24140 samples": 38 % of neither. Both now count the
/// 8343 the base fit left out of the 22048 rows with a reference. And the effects the summary leaves to the JSON
/// report are pointed to where that report is, or how to get one.
#[test]
fn broad_33_the_share_left_out_is_said_of_the_same_rows_as_the_first_line() {
    let out = magcal_fit(&[real(BROAD_33).to_str().unwrap()]);
    assert!(out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let first = stdout.lines().next().unwrap();
    // The counts of the first line: total, without a reference, the base fit's used and left out.
    let number_before = |text: &str, tail: &str| -> usize {
        let head = &text[..text
            .find(tail)
            .unwrap_or_else(|| panic!("{tail:?} in {text}"))];
        head.rsplit([' ', '(']).next().unwrap().parse().unwrap()
    };
    let total = number_before(first, " samples");
    let missing = number_before(first, " without an attitude reference");
    let excluded = number_before(first, " (38 %) as grossly off");
    let usable = total - missing;
    assert!(
        first.contains(&format!("of the other {usable}, the base fit")),
        "{first}"
    );
    let verdict = stdout.lines().find(|l| l.starts_with("verdict:")).unwrap();
    let said = format!("{excluded} of the {usable} readings with an attitude reference (38 %)");
    assert!(
        verdict.contains(&format!("the base fit left out {said}")),
        "{said:?} in {verdict}"
    );
    assert!(
        !verdict.contains("38 % of the readings"),
        "a share without its base: {verdict}"
    );
    assert!(
        stdout.contains("(which and why: add --report FILE)"),
        "{stdout}"
    );
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("r.json");
    let out = magcal_fit(&[
        real(BROAD_33).to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains(&format!("(which and why: in {})", report.display())),
        "{stdout}"
    );
}

/// Issue 32: BROAD 02's parameters checked on BROAD 33 with `magcal-apply` — the magnet attached for the middle
/// third is located as a field fixed to the sensor, left out of the check, and the rest graded: the reference's own
/// error of about 1 µT, usable, not the attitude reference blamed for the magnet's 9 µT.
#[test]
fn magcal_apply_leaves_out_the_magnet_on_the_board_and_grades_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let params = dir.path().join("params.toml");
    let out = magcal_fit(&[
        real(BROAD_02).to_str().unwrap(),
        "--out",
        params.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = magcal_apply(&params, &real(BROAD_33), &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let span = text
        .lines()
        .find(|l| l.contains("fixed to the sensor — left out of the check"))
        .unwrap_or_else(|| panic!("no span on the board left out:\n{text}"));
    // "  disturbance 40.40–98.70 s: …": attached by hand around 40–42 s, taken off around 98.6 s.
    let times: Vec<f64> = span
        .trim_start_matches("  disturbance ")
        .split(" s:")
        .next()
        .unwrap()
        .split('–')
        .map(|x| x.parse().unwrap())
        .collect();
    assert!(
        (39.0..=44.0).contains(&times[0]) && (96.6..=100.6).contains(&times[1]),
        "{span}"
    );
    let residual: f64 = text
        .split("residual RMS ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|r| r.parse().ok())
        .unwrap();
    assert!(
        residual < 1.5,
        "residual {residual} µT on the rest:\n{text}"
    );
    assert!(
        text.contains("verdict: USABLE") || text.contains("verdict: GOOD"),
        "{text}"
    );
    assert!(
        text.contains("left out of the check: the parameters were judged on the rest"),
        "{text}"
    );
}

/// Whether the report warns that part of the recording sat on another offset.
fn other_state_warned(r: &Value) -> bool {
    r["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w.as_str().unwrap().contains("sat on another offset"))
}

#[test]
fn broad_29_both_passes_by_the_magnet_are_located() {
    let r = fit_report(&real(BROAD_29), &[]);
    assert_eq!(r["diagnosis"]["verdict"], "mismatch");
    let s = spans(&r);
    assert!(located(&s, 30.5, 33.6), "30.5–33.6 s not in {s:?}");
    assert!(located(&s, 99.0, 101.0), "99–101 s not in {s:?}");
    assert_within(&r, [0.0; 3], "broad 29");
}

#[test]
fn undisturbed_recordings_have_no_gross_findings() {
    let r = fit_report(&real(BROAD_02), &[]);
    assert_undisturbed(&r, "broad 02");
    assert_within(&r, [0.0; 3], "broad 02");
    let r = fit_report(&real(NEXUS_NODIST), &[]);
    assert_undisturbed(&r, "nexus5 NoDist");
    assert_within(&r, [62.4, -54.0, 408.0], "nexus5 NoDist");
}

/// The perturbations of the Nexus 5 walk, measured independently of the diagnosis: the undisturbed trial's base fit
/// applied to this trial, samples whose field differs from the reference's by more than 15 µT (10 µT of
/// perturbation above the few µT the hard iron moves between days, the lag and the reference's error add).
fn nexus_perturbed_times(dir: &Path) -> Vec<f64> {
    let params = dir.join("nodist.toml");
    let out = magcal_fit(&[
        real(NEXUS_NODIST).to_str().unwrap(),
        "--no-diagnose",
        "--out",
        params.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let model = ParamsFile::read(&params).unwrap().model(&[]).unwrap();
    let rec = Recording::read(&real(NEXUS_DIST)).unwrap();
    let field = rec.meta.field_ned_ut.expect("the trial's field");
    let (t, q) = (rec.t_s.as_ref().unwrap(), rec.quat.as_ref().unwrap());
    rec.mag_ut
        .iter()
        .zip(q)
        .zip(t)
        .filter(|((m, q), _)| q.iter().all(|v| v.is_finite()) && m.iter().all(|v| v.is_finite()))
        .filter(|((m, q), _)| {
            let e = frames::sub(
                model.apply(**m, &Inputs::NONE),
                frames::expected_sensor_field(**q, field),
            );
            frames::norm(e) > 15.0
        })
        .map(|(_, t)| *t)
        .collect()
}

#[test]
fn nexus5_every_perturbation_above_10_ut_is_located() {
    let dir = tempfile::tempdir().unwrap();
    let perturbed = nexus_perturbed_times(dir.path());
    assert!(
        perturbed.len() > 100,
        "{} perturbed samples",
        perturbed.len()
    );
    let r = fit_report(&real(NEXUS_DIST), &[]);
    let s = spans(&r);
    let outside: Vec<f64> = perturbed
        .iter()
        .copied()
        .filter(|t| !s.iter().any(|(a, b)| (a - 0.25..=b + 0.25).contains(t)))
        .collect();
    assert!(
        outside.is_empty(),
        "{} of {} perturbed samples outside the spans {s:?}, e.g. at {:?} s",
        outside.len(),
        perturbed.len(),
        &outside[..outside.len().min(10)]
    );
    assert_within(&r, [60.0, -56.0, 408.0], "nexus5 Dist");
}

/// A field fixed to the sensor's board, added to a recording's readings: `field_ut` from `t0_s` to `t1_s`, put on
/// and taken off by hand over `RAMP_S` at each end.
struct OnBoard {
    t0_s: f64,
    t1_s: f64,
    field_ut: [f64; 3],
}

impl OnBoard {
    const RAMP_S: f64 = 2.0;

    /// The share of the field present at time `t`.
    fn at(&self, t: f64) -> f64 {
        ((t - self.t0_s).min(self.t1_s - t) / Self::RAMP_S).clamp(0.0, 1.0)
    }
}

/// `rel` with its quaternion columns removed (and, if `no_field`, the field and the place that give it too), and
/// `on_board`'s field added to the readings.
fn without_reference(rel: &str, dir: &Path, no_field: bool, on_board: Option<&OnBoard>) -> PathBuf {
    let text = std::fs::read_to_string(real(rel)).unwrap();
    let mut out = String::new();
    let mut header: Vec<&str> = Vec::new();
    for line in text.lines() {
        if line.starts_with('#') {
            let drop = no_field
                && ["# field_ned_ut", "# location", "# date"]
                    .iter()
                    .any(|k| line.starts_with(k));
            if !drop {
                out.push_str(line);
                out.push('\n');
            }
            continue;
        }
        let mut cells: Vec<String> = line.split(',').map(str::to_owned).collect();
        if header.is_empty() {
            header = line.split(',').collect();
        } else if let Some(board) = on_board {
            let column = |name: &str| header.iter().position(|c| *c == name).unwrap();
            let share = board.at(cells[column("t")].parse().unwrap());
            for (k, axis) in ["mx", "my", "mz"].into_iter().enumerate() {
                let v: f64 = cells[column(axis)].parse().unwrap();
                cells[column(axis)] = format!("{:.6}", v + share * board.field_ut[k]);
            }
        }
        let kept: Vec<&str> = cells
            .iter()
            .zip(&header)
            .filter(|(_, name)| !["qw", "qx", "qy", "qz"].contains(name))
            .map(|(c, _)| c.as_str())
            .collect();
        out.push_str(&kept.join(","));
        out.push('\n');
    }
    let path = dir.join(if no_field { "bare.csv" } else { "noquat.csv" });
    std::fs::write(&path, out).unwrap();
    path
}

/// The scalar A is symmetric: its error against I is what the tolerance bounds. Issue 37, acceptance 4: with the
/// lab field, each trial lands within its README's own tolerances (02: A within 3 % of I, the offset within 0.5 µT;
/// 29 and 33: 4 % and 1 µT; measured 0.025 / 0.30, 0.015 / 0.81, 0.029 / 0.71 µT), and BROAD 33's magnet on the board
/// is located through |B| alone (40.88–98.65 s against the vector method's 40.4–98.7 s: IoU 0.99, held to 0.8).
#[test]
fn broad_recordings_without_quaternions_calibrate_by_the_scalar_method() {
    for (rel, readme_a, readme_offset_ut) in [
        (BROAD_02, 0.03, 0.5),
        (BROAD_29, 0.04, 1.0),
        (BROAD_33, 0.04, 1.0),
    ] {
        for no_field in [false, true] {
            let dir = tempfile::tempdir().unwrap();
            let path = without_reference(rel, dir.path(), no_field, None);
            let r = fit_report(&path, &[]);
            let what = format!("{rel} without quaternions (field removed too: {no_field})");
            assert_eq!(r["method"], "scalar", "{what}");
            assert_within(&r, [0.0; 3], &what);
            if !no_field {
                let a = a_error(&matrix(&r["calibration"]["A"]));
                let o = frames::norm(offset(&r));
                assert!(
                    a <= readme_a && o <= readme_offset_ut,
                    "{what}: A {a:.4} off I, offset {o:.2} µT"
                );
            }
            if rel == BROAD_33 {
                let (t0, t1) = (40.4, 98.7);
                let iou = spans(&r)
                    .iter()
                    .map(|&(a, b)| (b.min(t1) - a.max(t0)).max(0.0) / (b.max(t1) - a.min(t0)))
                    .fold(0.0, f64::max);
                assert!(
                    iou >= 0.8,
                    "{what}: the magnet's window at IoU {iou:.2}: {:?}",
                    spans(&r)
                );
            }
            if rel == BROAD_02 {
                let ids = effect_ids(&r);
                assert!(
                    !ids.contains(&"nonlinearity") && !ids.contains(&"bias_window"),
                    "{what}: found {ids:?}"
                );
            }
        }
    }
}

/// A hand-held sensor without a reference, with something magnetic on its board for a third of the recording, a few
/// times the noise in |B| — as BROAD's trial with the magnet 3 cm from the chip would be (27 µT at 2 cm, falling as
/// the cube of the distance): broad 02 with 8–12 µT added while it turned. The robust fit's seeds on a cap of the
/// recording made a huge sphere through a band of the readings and the minute at rest at each end, which fitted
/// best, and the window was longer than a shifted window could be: every one of these was refused. The window is
/// left out and the calibration is the undisturbed one. (With 16 µT it is not yet: the fit is 5 µT off, and the
/// verdict says redo.)
#[test]
fn a_field_on_the_board_for_a_third_of_a_recording_without_reference_is_left_out() {
    for (t0_s, t1_s, field_ut) in [
        (60.0, 120.0, [3.0, -5.0, 5.5]),
        (60.0, 120.0, [-3.0, 5.0, -5.5]),
        (45.0, 105.0, [0.0, 0.0, 8.0]),
        (45.0, 105.0, [3.0, -7.0, 9.0]),
    ] {
        let board = OnBoard {
            t0_s,
            t1_s,
            field_ut,
        };
        let dir = tempfile::tempdir().unwrap();
        let path = without_reference(BROAD_02, dir.path(), false, Some(&board));
        let r = fit_report(&path, &[]);
        let what =
            format!("broad 02 without quaternions, {field_ut:?} µT on the board {t0_s}–{t1_s} s");
        assert_eq!(r["method"], "scalar", "{what}");
        assert_within(&r, [0.0; 3], &what);
        let o = frames::norm(offset(&r));
        assert!(o < 1.0, "{what}: offset {o:.2} µT off");
        let s = spans(&r);
        assert!(located(&s, t0_s, t1_s), "{what}: spans {s:?}");
    }
}

/// The table of docs/diagnosis.md: every physical recording, base and final errors against the truth the dataset
/// gives (A against I, the offset against the values above; "—" where the dataset gives none), the effects, the
/// spans and the verdict. Regenerate with
/// `cargo test --release --test real_disturbed -- --ignored --nocapture table_of_every_real_recording`.
#[test]
#[ignore = "prints the table of docs/diagnosis.md"]
fn table_of_every_real_recording() {
    let truths: [(&str, Option<[f64; 3]>); 10] = [
        (BROAD_02, Some([0.0; 3])),
        (BROAD_29, Some([0.0; 3])),
        (BROAD_33, Some([0.0; 3])),
        (NEXUS_NODIST, Some([62.4, -54.0, 408.0])),
        (NEXUS_DIST, Some([60.0, -56.0, 408.0])),
        ("inria-nexus5/nexus5_calib_dance.csv", None),
        ("hmc5883l/set2_full_sphere.csv", None),
        ("hmc5883l/set2_unmoved_x_forward_10min.csv", None),
        ("qmc5883l/qmc5883l_filtered_raw.csv", None),
        ("qmc5883l/qmc5883l_noisy_raw.csv", None),
    ];
    println!(
        "| recording | method | base A err / offset err (µT) | final A err / offset err (µT) | effects | spans (s) | verdict |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (rel, truth) in truths {
        let path = real(rel);
        let dir = tempfile::tempdir().unwrap();
        let report = dir.path().join("r.json");
        let out = magcal_fit(&[path.to_str().unwrap(), "--report", report.to_str().unwrap()]);
        if !out.status.success() {
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                err.contains(rel),
                "{rel}: an error that names no file: {err}"
            );
            println!("| `{rel}` | refused: {} | | | | | |", err.trim());
            continue;
        }
        let r: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let errs = |a: &Value, b: &Value| {
            let a = matrix(a);
            let b = floats(b);
            let o = magcal_calib::scalar::centre(&a, [b[0], b[1], b[2]]);
            match truth {
                Some(t) => format!(
                    "{:.3} / {:.2}",
                    a_error(&a),
                    frames::norm(frames::sub(o, t))
                ),
                None => "— / —".to_owned(),
            }
        };
        let base = errs(&r["base"]["A"], &r["base"]["b_ut"]);
        let fin = errs(&r["calibration"]["A"], &r["calibration"]["b_ut"]);
        let spans: Vec<String> = spans(&r)
            .iter()
            .map(|(a, b)| format!("{a:.1}–{b:.1}"))
            .collect();
        println!(
            "| `{rel}` | {} | {base} | {fin} | {} | {} | {} |",
            r["method"].as_str().unwrap(),
            effect_ids(&r).join(", "),
            spans.join(", "),
            r["diagnosis"]["verdict"].as_str().unwrap()
        );
    }
}

/// The coverage figure is that of the rows the calibration used: Nexus 5 NoDist's reference stops at 64 s, and the
/// phone turned through other directions after it, which the vector fit never saw (the figure was 68 %, the
/// recorder's over every row).
#[test]
fn the_coverage_is_of_the_rows_the_calibration_used() {
    use magcal_calib::directions::{fraction_of, recorded_fraction};
    let path = real(NEXUS_NODIST);
    let r = fit_report(&path, &[]);
    let rec = Recording::read(&path).unwrap();
    let quat = rec.quat.as_ref().unwrap();
    let with_reference = fraction_of(rec.len(), |i| {
        quat[i]
            .iter()
            .all(|q| q.is_finite())
            .then_some(rec.mag_ut[i])
    });
    let every_row = recorded_fraction(&rec.mag_ut);
    let fit = r["coverage"]["sphere_fraction"].as_f64().unwrap();
    assert!(
        (fit - with_reference).abs() < 0.03 && fit < every_row - 0.2,
        "fit {fit}, rows with a reference {with_reference}, every row {every_row}"
    );
    // BROAD 33's magnet on the board, modelled as a window: its rows count where they point without it. As read, 27
    // µT off the sphere, they pointed in directions the sensor never took (71 % counted, where the rows without the
    // magnet's offset cover 53 %).
    let path = real(BROAD_33);
    let r = fit_report(&path, &[]);
    let rec = Recording::read(&path).unwrap();
    let found = r["diagnosis"]["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["id"] == "bias_window")
        .expect("the magnet's window");
    let (t0, t1) = (
        found["params"]["t0_s"].as_f64().unwrap(),
        found["params"]["t1_s"].as_f64().unwrap(),
    );
    let a = r["calibration"]["A"].clone();
    let a = nalgebra::Matrix3::from_fn(|j, k| a[j][k].as_f64().unwrap());
    let offset = floats(&found["params"]["offset_ut"]);
    let shift = a.try_inverse().unwrap() * nalgebra::Vector3::from_column_slice(&offset);
    let t = rec.t_s.as_ref().unwrap();
    let without = fraction_of(rec.len(), |i| {
        let m = rec.mag_ut[i];
        Some(if (t0..=t1).contains(&t[i]) {
            [m[0] - shift.x, m[1] - shift.y, m[2] - shift.z]
        } else {
            m
        })
    });
    let fit = r["coverage"]["sphere_fraction"].as_f64().unwrap();
    assert!(
        (fit - without).abs() < 0.03,
        "fit {fit}, the rows without the magnet's offset {without}"
    );
}
