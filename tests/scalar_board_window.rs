//! Scalar recordings with something magnetic on the board for part of the time (issue 37, acceptance 4).
//!
//! Through |B| alone a field fixed to the sensor from `t0` to `t1` is a second sphere centre with the same shape. The
//! scalar method must locate the window and calibrate from the rest, however much of the recording it holds:
//! windows of 5–60 µT for 20–60 % of a recording, at random times inside it, on the study's random benches (chip,
//! rate, noise, soft and hard iron, field). Judged as a user would: the spans the diagnosis reports meet the window
//! with an intersection over union of at least 0.8, and the calibration is within the tolerances the shared
//! recordings' README states for a good one (A within 3 %, the offset within 1 µT).

use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::Method;
use magcal_app::verdict::assess;
use magcal_calib::effects::Effect;
use magcal_calib::{frames, scalar};
use magcal_sim::study::{duration_s, random_scenario};
use magcal_sim::{AttitudeOutput, simulate, stream_rng};
use nalgebra::Matrix3;
use rand::RngExt;

/// A calibration is good within these (the shared recordings' README: A ≈ I within ~3 %, offset < 0.5–1 µT).
const A_TOLERANCE: f64 = 0.03;
const OFFSET_TOLERANCE_UT: f64 = 1.0;
/// The window is located when the reported spans meet it with at least this intersection over union.
const LOCATED_IOU: f64 = 0.8;

/// What one recording gave: the intersection over union, A's and the offset's errors, the largest error in the
/// fit's own standard errors, whether it was refused or graded redo, and a line to print.
struct Outcome {
    iou: f64,
    a_err: f64,
    o_err_ut: f64,
    worst_z: f64,
    refused_or_redo: bool,
    line: String,
}

impl Outcome {
    fn good(&self) -> bool {
        self.iou >= LOCATED_IOU && self.a_err <= A_TOLERANCE && self.o_err_ut <= OFFSET_TOLERANCE_UT
    }

    /// Not good, and nothing says so: graded usable or good, with an error beyond three of its standard errors
    /// outside the tolerances.
    fn silently_wrong(&self) -> bool {
        let within_tolerance = self.a_err <= A_TOLERANCE && self.o_err_ut <= OFFSET_TOLERANCE_UT;
        !within_tolerance && !self.refused_or_redo && self.worst_z > 3.0
    }
}

/// Seed `seed`'s random bench without its attitude, with a field of `size_ut` in a random direction on its board for
/// `share` of the recording, starting at a random time inside it; calibrated by the scalar method with its diagnosis.
fn run(seed: u64, size_ut: f64, share: f64) -> Outcome {
    let mut s = random_scenario(seed);
    s.attitude = AttitudeOutput::None;
    let t_end = duration_s(&s);
    let mut rng = stream_rng(seed, 37);
    let t0_s = rng.random_range(0.02..(0.98 - share)) * t_end;
    let t1_s = t0_s + share * t_end;
    let dir = [(); 3].map(|_| rng.random_range(-1.0..1.0));
    let dir = frames::scale(dir, 1.0 / frames::norm(dir));
    s.effects = vec![Effect::BiasWindow {
        t0_s,
        t1_s,
        offset_ut: frames::scale(dir, size_ut),
    }];
    let rec = simulate(&s).unwrap().recording;
    let field = ReferenceField::Magnitude {
        field_ut: frames::norm(s.field_ned_ut),
        source: "simulated".into(),
    };
    let what = format!(
        "seed {seed}, {size_ut} µT for {:.0} % ({t0_s:.1}–{t1_s:.1} s)",
        100.0 * share
    );
    let cal = match calibrate(&rec, Method::Auto, field, true) {
        Ok(c) => c,
        Err(e) => {
            return Outcome {
                iou: 0.0,
                a_err: f64::INFINITY,
                o_err_ut: f64::INFINITY,
                worst_z: f64::INFINITY,
                refused_or_redo: true,
                line: format!("{what}: refused: {e}"),
            };
        }
    };
    let t = rec.t_s.as_ref().unwrap();
    let spans: Vec<(f64, f64)> = cal
        .diagnosis
        .as_ref()
        .expect("diagnosed")
        .spans
        .iter()
        .map(|sp| (sp.t0_s, sp.t1_s))
        .collect();
    let (mut inter, mut union) = (0usize, 0usize);
    for &ti in t {
        let truth = (t0_s..t1_s).contains(&ti);
        let found = spans.iter().any(|(a, b)| (a..=b).contains(&&ti));
        inter += usize::from(truth && found);
        union += usize::from(truth || found);
    }
    let iou = inter as f64 / union.max(1) as f64;
    // The scalar method sees A's symmetric part √(AᵀA), and the offset −A⁻¹·b.
    let m = Matrix3::from_fn(|j, k| s.sensor.a[j][k]);
    let e = (m.transpose() * m).symmetric_eigen();
    let truth_a = e.eigenvectors
        * Matrix3::from_diagonal(&e.eigenvalues.map(f64::sqrt))
        * e.eigenvectors.transpose();
    let model = cal.model();
    let a_diff = Matrix3::from_fn(|j, k| model.a[j][k]) - truth_a;
    let o_diff = frames::sub(
        scalar::centre(&model.a, model.b_ut),
        scalar::centre(&s.sensor.a, s.sensor.b_ut),
    );
    let (a_se, _) = cal.standard_errors();
    let o_se = cal.offset_se_ut();
    let worst_z = (0..9)
        .map(|i| a_diff[(i / 3, i % 3)].abs() / a_se[i / 3][i % 3])
        .chain((0..3).map(|k| o_diff[k].abs() / o_se[k]))
        .fold(0.0, f64::max);
    let grade = assess(&cal, &rec, false).verdict.grade.name().to_owned();
    let (a_err, o_err_ut) = (a_diff.abs().max(), frames::norm(o_diff));
    Outcome {
        iou,
        a_err,
        o_err_ut,
        worst_z,
        refused_or_redo: grade == "redo",
        line: format!(
            "{what}: IoU {iou:.3}, A {a_err:.4}, offset {o_err_ut:.2} µT ({worst_z:.1} SE), {} span(s), {grade}",
            spans.len()
        ),
    }
}

/// The sizes and shares of the acceptance, each a case.
fn cases() -> Vec<(f64, f64)> {
    [5.0, 10.0, 20.0, 40.0, 60.0]
        .iter()
        .flat_map(|&size| [0.2, 0.4, 0.6].map(|share| (size, share)))
        .collect()
}

/// One bench, every size and share: the small field on the board for most of the recording, and the large one
/// that makes the board's state the majority, are where the window scan and the base fit used to fail (a 5 µT
/// field for 40 % went unseen, offset 2 µT off; 20–60 µT for 60 % were calibrated in the magnet's state, graded
/// redo, the offset off by the field itself).
#[test]
fn a_field_on_the_board_for_a_fifth_to_three_fifths_of_a_scalar_recording_is_located_and_left_out()
{
    let outcomes: Vec<Outcome> = cases()
        .iter()
        .map(|&(size, share)| run(1, size, share))
        .collect();
    let bad: Vec<&str> = outcomes
        .iter()
        .filter(|o| !o.good())
        .map(|o| o.line.as_str())
        .collect();
    assert!(bad.is_empty(), "{bad:#?}");
}

/// The study: 10 benches × 15 cases. Measured: 146 of 150 located and within tolerance (142 before a window was a
/// second centre fitted with the rest, 90 before windows up to half the recording were judged against the noise they
/// leave: docs/diagnosis.md); of the four others, two refused (the ends beside a 60 % window cover too few directions
/// to give the centre), one calibrated in the magnet's state and graded redo, and one located at IoU 0.68 within the
/// tolerances; none silently off.
#[test]
#[ignore = "study: 150 scalar recordings, about a minute in release"]
fn scalar_board_window_study() {
    let runs: Vec<(u64, f64, f64)> = (1..=10)
        .flat_map(|seed| {
            cases()
                .into_iter()
                .map(move |(size, share)| (seed, size, share))
        })
        .collect();
    let outcomes: Vec<Outcome> = runs
        .iter()
        .map(|&(seed, size, share)| run(seed, size, share))
        .collect();
    let good = outcomes.iter().filter(|o| o.good()).count();
    eprintln!(
        "scalar board windows: {good} of {} located and within tolerance",
        outcomes.len()
    );
    for o in outcomes.iter().filter(|o| !o.good()) {
        eprintln!("  {}", o.line);
    }
    let wrong: Vec<&str> = outcomes
        .iter()
        .filter(|o| o.silently_wrong())
        .map(|o| o.line.as_str())
        .collect();
    assert!(wrong.is_empty(), "silently wrong: {wrong:#?}");
    assert!(good >= 146, "{good} of {}", outcomes.len());
}
