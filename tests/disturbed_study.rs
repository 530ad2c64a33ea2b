//! Acceptance (issue 10, item 2): gross disturbances on simulated benches, where the truth is known. Each seed is a
//! random bench (`random_scenario`) with 0–3 disturbances of 3–300 µT (log-uniform), each of a random kind: a field
//! fixed to the sensor for a while (`bias_window`, something attached to the board), a field fixed in the room for a
//! while (`disturbance`), or a magnet fixed in the room near the moving sensor (`magnet_nearby`, sized by its peak
//! on the recording, placed 3–8 cm beside the sensor's path: a pass by it). Windows last from 1 s to a fifth of the recording, in separate slots. Each seed is run by the
//! vector method (attitude reference) and by the scalar method (the same readings without it, the magnitude known).
//!
//! Per run it checks, against the truth:
//! - the final offset and A within 3 of their reported standard errors, every component (for the scalar method the
//!   symmetric part of A, which is all it observes), with an error at most twice that of the same fit on the clean
//!   samples alone, or 0.2 µT (offset) / 0.005 (A), whichever is larger — in at least 95 % of the runs;
//! - every disturbance the method sees at more than 10 µT (the field's change for the vector method, its
//!   magnitude's for the scalar one: a field fixed in the room across the Earth's changes the magnitude little)
//!   located: a window's time and the spans that meet it overlap with an intersection over union of at least 0.5;
//!   for a magnet, whose field falls off smoothly with distance, 90 % of the samples it perturbs by more than 10 µT
//!   lie inside spans — at least 95 % of the disturbances;
//! - the final model no worse than the base fit on a clean held-out recording of the same bench (another
//!   trajectory): RMS residual at most 0.5 % above the base's — in every run;
//! - runs without a disturbance: a false alarm (a verdict other than consistent) in at most 1 %.
//!
//! The targets (95 %, none worse, ≤ 1 % false alarms) are the aim; the assertions hold the levels measured
//! so far, which fall short of them (see the tests' comments and docs/diagnosis.md).
//!
//! Heavy: `cargo test --release --test disturbed_study -- --ignored --nocapture` (CI runs it). To look at some
//! seeds: `MAGCAL_STUDY_SEEDS=15,66` runs only those (no floors are checked), and `MAGCAL_STUDY_DUMP=DIR` writes
//! each run's recording to `DIR/seed_<seed>_<method>.csv` for `magcal-fit`.

mod common;

use std::sync::Mutex;

use magcal_app::calibrate::calibrate;
use magcal_app::field::ReferenceField;
use magcal_app::fit::{Calibration, Method};
use magcal_calib::diagnosis::{SpanKind, Verdict};
use magcal_calib::effects::Effect;
use magcal_calib::model::{Inputs, Model};
use magcal_calib::{frames, scalar};
use magcal_recording::Recording;
use magcal_sim::study::{duration_s, random_scenario};
use magcal_sim::{AttitudeOutput, Scenario, simulate, stream_rng};
use nalgebra::Matrix3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SEEDS: u64 = 200;
/// Disturbances at least this large (µT) must be located.
const MUST_LOCATE_UT: f64 = 10.0;
/// A magnet is located when this share of the samples where it perturbs by more than 10 µT lies inside spans.
const MAGNET_RECALL: f64 = 0.9;
/// How much worse than the base the final model may fit the held-out recording (relative RMS).
const HELD_OUT_SLACK: f64 = 0.005;

/// 0–3 disturbances for a scenario, each with its size (µT).
fn disturbances(s: &Scenario, seed: u64) -> Vec<(Effect, f64)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xd157_0b0e);
    let k = (seed % 4) as usize;
    let t_end = duration_s(s);
    let slot = 0.9 * t_end / k.max(1) as f64;
    let mut dir = || {
        let v: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        frames::scale(v, 1.0 / frames::norm(v).max(1e-9))
    };
    let dirs: Vec<([f64; 3], [f64; 3])> = (0..k).map(|_| (dir(), dir())).collect();
    (0..k)
        .map(|j| {
            let size_ut = (rng.random_range(3.0f64.ln()..300.0f64.ln())).exp();
            let len = rng.random_range(1.0..(0.2 * t_end).min(0.8 * slot));
            let t0_s = 0.05 * t_end + j as f64 * slot + rng.random_range(0.0..slot - len);
            let (d, d2) = dirs[j];
            let e = match rng.random_range(0..3) {
                0 => Effect::BiasWindow {
                    t0_s,
                    t1_s: t0_s + len,
                    offset_ut: frames::scale(d, size_ut),
                },
                1 => Effect::Disturbance {
                    t0_s,
                    t1_s: t0_s + len,
                    field_ned_ut: frames::scale(d, size_ut),
                },
                // Placed beside the sensor's path, 3–8 cm from where the sensor is at some moment: a pass by it.
                _ => {
                    let poses = s
                        .trajectory
                        .poses(s.sample_rate_hz, &mut stream_rng(s.seed, 1));
                    let at = poses[rng.random_range(0..poses.len())].position_m;
                    let m = Effect::MagnetNearby {
                        position_m: frames::add(at, frames::scale(d, rng.random_range(0.03..0.08))),
                        moment_am2: frames::scale(d2, 1e-4),
                    };
                    let peak = perturbation_ut(s, &m, true).into_iter().fold(0.0, f64::max);
                    let (p, _) = m.params();
                    m.with_params(p.map(|v| v * size_ut / peak))
                }
            };
            (e, size_ut)
        })
        .collect()
}

/// The size of an effect's perturbation at each sample (µT), from noise-free simulations: of the calibrated field
/// (`vector`), or of its magnitude, which is all the scalar method sees.
fn perturbation_ut(s: &Scenario, e: &Effect, vector: bool) -> Vec<f64> {
    let quiet = Scenario {
        noise_ut: [0.0; 3],
        lsb_ut: None,
        attitude_noise_deg: 0.0,
        effects: Vec::new(),
        ..s.clone()
    };
    let with = Scenario {
        effects: vec![*e],
        ..quiet.clone()
    };
    let (a, b) = (simulate(&quiet).unwrap(), simulate(&with).unwrap());
    a.truth
        .clean_raw_ut
        .iter()
        .zip(&b.truth.clean_raw_ut)
        .map(|(x, y)| {
            let cal = |r: [f64; 3]| frames::add(frames::mat_vec(&s.sensor.a, r), s.sensor.b_ut);
            if vector {
                frames::norm(frames::sub(cal(*y), cal(*x)))
            } else {
                (frames::norm(cal(*y)) - frames::norm(cal(*x))).abs()
            }
        })
        .collect()
}

/// The recording's rows where `keep` holds.
fn rows(rec: &Recording, keep: &[bool]) -> Recording {
    fn pick<T: Clone>(v: &[T], keep: &[bool]) -> Vec<T> {
        v.iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(x, _)| x.clone())
            .collect()
    }
    let mut out = rec.clone();
    out.t_s = rec.t_s.as_deref().map(|v| pick(v, keep));
    out.mag_ut = pick(&rec.mag_ut, keep);
    out.temp_c = rec.temp_c.as_deref().map(|v| pick(v, keep));
    out.quat = rec.quat.as_deref().map(|v| pick(v, keep));
    out.ref_ut = rec.ref_ut.as_deref().map(|v| pick(v, keep));
    out.gyro_rad_s = rec.gyro_rad_s.as_deref().map(|v| pick(v, keep));
    for c in &mut out.currents {
        c.values = pick(&c.values, keep);
    }
    for c in &mut out.extra {
        c.values = pick(&c.values, keep);
    }
    out
}

fn field(s: &Scenario, vector: bool) -> ReferenceField {
    if vector {
        ReferenceField::Vector {
            field_ned_ut: s.field_ned_ut,
            source: "simulated".into(),
        }
    } else {
        ReferenceField::Magnitude {
            field_ut: frames::norm(s.field_ned_ut),
            source: "simulated".into(),
        }
    }
}

/// The truth a bench's fit is judged against: what the method can observe of the sensor's A — all of it (vector),
/// its symmetric part `√(AᵀA)` (scalar) — and the offset `−A⁻¹·b`.
fn truth(s: &Scenario, vector: bool) -> (Matrix3<f64>, [f64; 3]) {
    let m = Matrix3::from_fn(|j, k| s.sensor.a[j][k]);
    let offset = scalar::centre(&s.sensor.a, s.sensor.b_ut);
    if vector {
        return (m, offset);
    }
    let e = (m.transpose() * m).symmetric_eigen();
    let a = e.eigenvectors
        * Matrix3::from_diagonal(&e.eigenvalues.map(f64::sqrt))
        * e.eigenvectors.transpose();
    (a, offset)
}

/// Largest |A error| element and the offset error's norm (µT) of a model against the truth.
fn errors(model: &Model, truth_a: &Matrix3<f64>, truth_offset: [f64; 3]) -> (f64, f64) {
    let a = Matrix3::from_fn(|j, k| model.a[j][k]);
    let o = scalar::centre(&model.a, model.b_ut);
    (
        (a - truth_a).abs().max(),
        frames::norm(frames::sub(o, truth_offset)),
    )
}

/// Largest error over standard error among A's components and the offset's, and which it is.
fn worst_z(cal: &Calibration, truth_a: &Matrix3<f64>, truth_offset: [f64; 3]) -> (f64, String) {
    let model = cal.model();
    let (a_se, _) = cal.standard_errors();
    let o_se = cal.offset_se_ut();
    let o = scalar::centre(&model.a, model.b_ut);
    let za = (0..9).map(|i| {
        let (j, k) = (i / 3, i % 3);
        (
            (model.a[j][k] - truth_a[(j, k)]).abs() / a_se[j][k],
            format!("A[{j}][{k}]"),
        )
    });
    let zo = (0..3).map(|k| {
        (
            (o[k] - truth_offset[k]).abs() / o_se[k],
            format!("offset[{k}]"),
        )
    });
    za.chain(zo)
        .fold((0.0, String::new()), |m, z| if z.0 > m.0 { z } else { m })
}

/// RMS residual of a model on a recording against the truth: per axis (vector) or of the magnitude (scalar).
fn held_out_rms(model: &Model, rec: &Recording, s: &Scenario, vector: bool) -> f64 {
    let t = rec.t_s.as_ref().unwrap();
    let q = rec.quat.as_ref().unwrap();
    let f = frames::norm(s.field_ned_ut);
    let mut ss = 0.0;
    for i in 0..rec.mag_ut.len() {
        let currents: Vec<f64> = rec.currents.iter().map(|c| c.values[i]).collect();
        let inputs = Inputs {
            t_s: t[i],
            temp_c: rec.temp_c.as_ref().map_or(f64::NAN, |v| v[i]),
            currents_a: &currents,
        };
        let b = model.apply(rec.mag_ut[i], &inputs);
        ss += if vector {
            let e = frames::sub(b, frames::expected_sensor_field(q[i], s.field_ned_ut));
            frames::dot(e, e) / 3.0
        } else {
            (frames::norm(b) - f).powi(2)
        };
    }
    (ss / rec.mag_ut.len() as f64).sqrt()
}

/// The base and the final model's RMS residual on a clean held-out recording of the same bench: another trajectory
/// and noise (the held-out always has the attitude, to compute the truth).
fn held_out(cal: &Calibration, s: &Scenario, vector: bool) -> (f64, f64) {
    let held = Scenario {
        seed: s.seed + 1_000_000,
        effects: Vec::new(),
        attitude: AttitudeOutput::Quaternion,
        ..s.clone()
    };
    let rec = simulate(&held).unwrap().recording;
    (
        held_out_rms(&cal.base_model(), &rec, s, vector),
        held_out_rms(&cal.model(), &rec, s, vector),
    )
}

/// Intersection over union of `truth` with the spans that meet it.
fn iou(truth: &[bool], t: &[f64], spans: &[(f64, f64)]) -> f64 {
    let meets: Vec<&(f64, f64)> = spans
        .iter()
        .filter(|(a, b)| t.iter().zip(truth).any(|(t, x)| *x && (a..=b).contains(&t)))
        .collect();
    let (mut inter, mut union) = (0usize, 0usize);
    for (t, x) in t.iter().zip(truth) {
        let d = meets.iter().any(|(a, b)| (a..=b).contains(&t));
        inter += usize::from(*x && d);
        union += usize::from(*x || d);
    }
    inter as f64 / union.max(1) as f64
}

#[derive(Default)]
struct Tally {
    runs: usize,
    nulls: usize,
    false_alarms: Vec<String>,
    /// Runs within 3 SE and within the error bound.
    good: usize,
    /// Seeds within 3 SE and the error bound with every disturbance above 10 µT located, of all seeds (refused
    /// ones count against it).
    good_and_located: usize,
    bad: Vec<String>,
    must_locate: usize,
    located: usize,
    missed: Vec<String>,
    worse: Vec<String>,
    refused: Vec<String>,
}

fn run(seed: u64, vector: bool, tally: &Mutex<Tally>) {
    let mut s = random_scenario(seed);
    if !vector {
        s.attitude = AttitudeOutput::None;
    }
    let dist = disturbances(&s, seed);
    s.effects = dist.iter().map(|(e, _)| *e).collect();
    let sim = simulate(&s).unwrap();
    let rec = &sim.recording;
    if let Some(dir) = std::env::var_os("MAGCAL_STUDY_DUMP") {
        let method = if vector { "vector" } else { "scalar" };
        let dir = std::path::Path::new(&dir);
        rec.write(&dir.join(format!("seed_{seed}_{method}.csv")))
            .unwrap();
        let truth = format!(
            "field_ned_ut {:?} (|F| {:.3})\nA {:?}\nb_ut {:?}\n{:#?}\n",
            s.field_ned_ut,
            frames::norm(s.field_ned_ut),
            s.sensor.a,
            s.sensor.b_ut,
            dist
        );
        std::fs::write(dir.join(format!("seed_{seed}_{method}.truth")), truth).unwrap();
    }
    let what = format!(
        "seed {seed} {}: {:?}",
        if vector { "vector" } else { "scalar" },
        dist.iter()
            .map(|(e, size)| format!("{} {size:.1} µT", e.id()))
            .collect::<Vec<_>>()
    );
    let cal = match calibrate(rec, Method::Auto, field(&s, vector), true) {
        Ok(c) => c,
        Err(e) => {
            tally.lock().unwrap().refused.push(format!("{what}: {e}"));
            return;
        }
    };
    // However disturbed, a reference in magcal's convention and on the readings' clock is not taken for another.
    assert_eq!(cal.reference.convention, None, "{what}");
    assert_eq!(cal.reference.offset, None, "{what}");
    let d = cal.diagnosis.as_ref().expect("diagnosed");
    let t = rec.t_s.as_ref().unwrap();
    // Where each disturbance is, and the clean rows.
    let perturbed: Vec<Vec<f64>> = dist
        .iter()
        .map(|(e, _)| perturbation_ut(&s, e, vector))
        .collect();
    let noise = s.noise_ut[0];
    let clean: Vec<bool> = (0..t.len())
        .map(|i| perturbed.iter().all(|p| p[i] < 0.5 * noise))
        .collect();
    let (truth_a, truth_offset) = truth(&s, vector);
    let (a_err, o_err) = errors(&cal.model(), &truth_a, truth_offset);
    let clean_fit = calibrate(&rows(rec, &clean), Method::Auto, field(&s, vector), false);
    let (a_bound, o_bound) = match &clean_fit {
        Ok(c) => {
            let (a, o) = errors(&c.model(), &truth_a, truth_offset);
            ((2.0 * a).max(0.005), (2.0 * o).max(0.2))
        }
        Err(_) => (f64::INFINITY, f64::INFINITY),
    };
    let (z, z_at) = worst_z(&cal, &truth_a, truth_offset);
    let spans: Vec<(f64, f64)> = d.spans.iter().map(|sp| (sp.t0_s, sp.t1_s)).collect();
    let (base_ho, final_ho) = held_out(&cal, &s, vector);
    let found: Vec<String> = d
        .effects
        .iter()
        .map(|e| format!("{} {:.1} µT", e.effect.id(), e.size_ut))
        .chain(d.spans.iter().map(|sp| sp.explanation.clone()))
        .collect();
    let what = format!("{what} → found {found:?}");
    let mut tl = tally.lock().unwrap();
    tl.runs += 1;
    if dist.is_empty() {
        tl.nulls += 1;
        if d.verdict != Verdict::Consistent {
            let ids: Vec<&str> = d.effects.iter().map(|e| e.effect.id().as_str()).collect();
            tl.false_alarms
                .push(format!("{what}: {ids:?}, {} spans", d.spans.len()));
        }
    }
    let good = z <= 3.0 && a_err <= a_bound && o_err <= o_bound;
    let missed_before = tl.missed.len();
    if good {
        tl.good += 1;
    } else {
        tl.bad.push(format!(
            "{what}: worst z {z:.2} ({z_at}), A err {a_err:.4} (bound {a_bound:.4}), offset err {o_err:.3} µT \
             (bound {o_bound:.3})"
        ));
    }
    for ((e, _), p) in dist.iter().zip(&perturbed) {
        // What the method sees of it.
        let visible_ut = p.iter().copied().fold(0.0, f64::max);
        if visible_ut < MUST_LOCATE_UT {
            continue;
        }
        tl.must_locate += 1;
        let (ok, how) = match e {
            Effect::BiasWindow { t0_s, t1_s, .. } | Effect::Disturbance { t0_s, t1_s, .. } => {
                let truth: Vec<bool> = t.iter().map(|t| (t0_s..=t1_s).contains(&t)).collect();
                let u = iou(&truth, t, &spans);
                (u >= 0.5, format!("IoU {u:.2}"))
            }
            _ => {
                let above: Vec<f64> = t
                    .iter()
                    .zip(p)
                    .filter(|(_, v)| **v > MUST_LOCATE_UT)
                    .map(|(t, _)| *t)
                    .collect();
                let inside = above
                    .iter()
                    .filter(|t| spans.iter().any(|(a, b)| (a..=b).contains(t)))
                    .count();
                let share = inside as f64 / above.len() as f64;
                (
                    share >= MAGNET_RECALL,
                    format!("{:.0} % of it inside", 100.0 * share),
                )
            }
        };
        if ok {
            tl.located += 1;
        } else {
            tl.missed.push(format!(
                "{what}: {} seen at up to {visible_ut:.1} µT, {how}, spans {spans:?}",
                e.id()
            ));
        }
    }
    if good && tl.missed.len() == missed_before {
        tl.good_and_located += 1;
    }
    if final_ho > base_ho * (1.0 + HELD_OUT_SLACK) {
        tl.worse
            .push(format!("{what}: held-out {base_ho:.4} → {final_ho:.4} µT"));
    }
}

fn report(name: &str, t: &Tally) {
    let pct = |a: usize, n: usize| 100.0 * a as f64 / n.max(1) as f64;
    println!("## {name}");
    println!(
        "| runs | within 3 SE and the error bound | disturbances > 10 µT located (IoU ≥ 0.5) | both, of all seeds | final worse than base on held-out | false alarms on nulls | refused |"
    );
    println!("|---|---|---|---|---|---|---|");
    let seeds = t.runs + t.refused.len();
    println!(
        "| {} | {:.1} % | {} of {} ({:.1} %) | {} of {} ({:.1} %) | {} | {} of {} | {} |",
        t.runs,
        pct(t.good, t.runs),
        t.located,
        t.must_locate,
        pct(t.located, t.must_locate),
        t.good_and_located,
        seeds,
        pct(t.good_and_located, seeds),
        t.worse.len(),
        t.false_alarms.len(),
        t.nulls,
        t.refused.len()
    );
    for (label, list) in [
        ("outside", &t.bad),
        ("missed", &t.missed),
        ("worse", &t.worse),
        ("false alarm", &t.false_alarms),
        ("refused", &t.refused),
    ] {
        for l in list {
            println!("{label}: {l}");
        }
    }
}

/// The seeds `MAGCAL_STUDY_SEEDS` names (comma-separated), if set.
fn chosen_seeds() -> Option<Vec<u64>> {
    let v = std::env::var("MAGCAL_STUDY_SEEDS").ok()?;
    Some(
        v.split(',')
            .map(|s| {
                s.trim()
                    .parse()
                    .expect("MAGCAL_STUDY_SEEDS: comma-separated seeds")
            })
            .collect(),
    )
}

fn study(vector: bool) -> Tally {
    let tally = Mutex::new(Tally::default());
    match chosen_seeds() {
        Some(seeds) => seeds.iter().for_each(|&seed| run(seed, vector, &tally)),
        None => common::for_each_seed(SEEDS, |seed| run(seed, vector, &tally)),
    }
    tally.into_inner().unwrap()
}

/// What a study must keep: the share of runs within 3 SE and the error bound, of disturbances located, at most
/// this many runs worse on held-out data, this share of false alarms and of refusals (%).
struct Floor {
    good_pct: f64,
    located_pct: f64,
    /// Seeds within the bounds with every disturbance located, of all seeds.
    both_pct: f64,
    worse: usize,
    false_alarm_pct: f64,
    refused_pct: f64,
}

fn check(t: &Tally, f: &Floor) {
    if chosen_seeds().is_some() {
        return;
    }
    let pct = |a: usize, n: usize| 100.0 * a as f64 / n.max(1) as f64;
    assert!(
        pct(t.refused.len(), SEEDS as usize) <= f.refused_pct,
        "refused: {:?}",
        t.refused
    );
    assert!(
        pct(t.good, t.runs) >= f.good_pct,
        "{} of {} runs good",
        t.good,
        t.runs
    );
    assert!(
        pct(t.located, t.must_locate) >= f.located_pct,
        "{} of {} located",
        t.located,
        t.must_locate
    );
    let seeds = t.runs + t.refused.len();
    assert!(
        pct(t.good_and_located, seeds) >= f.both_pct,
        "{} of {seeds} seeds good with every disturbance located",
        t.good_and_located
    );
    assert!(t.worse.len() <= f.worse, "{:?}", t.worse);
    assert!(
        pct(t.false_alarms.len(), t.nulls) <= f.false_alarm_pct,
        "{:?}",
        t.false_alarms
    );
}

/// Seed `seed`'s bench with its disturbances, and its calibration with the diagnosis: by the vector method
/// (`vector`), or by the scalar one without the attitude.
fn calibrated(seed: u64, vector: bool) -> (Scenario, Calibration) {
    let mut s = random_scenario(seed);
    if !vector {
        s.attitude = AttitudeOutput::None;
    }
    s.effects = disturbances(&s, seed).iter().map(|(e, _)| *e).collect();
    let rec = simulate(&s).unwrap().recording;
    let cal = calibrate(&rec, Method::Auto, field(&s, vector), true).unwrap();
    (s, cal)
}

/// Seed 15 without the attitude: fields on the board for 30 s show in |B| only where they point along the field
/// (`d·u`), so a scan for a constant shift kept the lulls between (perturbed by up to 11 µT; the base offset was
/// 0.320 µT off, A 0.0071, and only the refit around the diagnosis' spans recovered them). The base fit's window
/// scan now fits `d·u` and leaves the whole windows out (measured: offset error 0.006 µT, A 0.0003), and the
/// diagnosis, which takes the scalar base fit's exclusions as they are, keeps that.
#[test]
fn fields_on_the_board_that_average_out_in_the_magnitude_are_left_out_of_the_base_fit() {
    let seed = 15;
    let (s, cal) = calibrated(seed, false);
    let (truth_a, truth_offset) = truth(&s, false);
    let (base_a, base_o) = errors(&cal.base_model(), &truth_a, truth_offset);
    let (final_a, final_o) = errors(&cal.model(), &truth_a, truth_offset);
    assert!(base_o < 0.05 && base_a < 0.001, "base {base_a} {base_o}");
    assert!(
        final_o < 0.05 && final_a < 0.001,
        "final {final_a} {final_o}"
    );
}

/// Seed 94 with the attitude: a 12 µT field on the board for 22 s while a magnet is near the path. A constant
/// explains the span, but its samples kept in the fit (modelled as a `bias_window`) fitted a clean recording of the
/// same bench 0.7 % worse than the base fit (0.2056 → 0.2070 µT); they stay out unless they improve the clean
/// held-out fit noticeably, and the report still calls the span a field fixed to the sensor.
#[test]
fn a_modelled_window_whose_rows_gain_nothing_stays_out() {
    let seed = 94;
    let (s, cal) = calibrated(seed, true);
    let window = s
        .effects
        .iter()
        .find_map(|e| match e {
            Effect::BiasWindow { t0_s, t1_s, .. } => Some((*t0_s, *t1_s)),
            _ => None,
        })
        .expect("seed 94 has a field on the board");
    let d = cal.diagnosis.as_ref().unwrap();
    let span = d
        .spans
        .iter()
        .find(|sp| sp.t0_s < window.1 && window.0 < sp.t1_s)
        .expect("the window located");
    // Left out, and still said to be what it is.
    assert!(
        !span.modelled && matches!(span.kind, SpanKind::SensorFixed { .. }),
        "{span:?}"
    );
    let (base_ho, final_ho) = held_out(&cal, &s, true);
    assert!(
        final_ho <= base_ho * (1.0 + HELD_OUT_SLACK),
        "held-out {base_ho} → {final_ho}"
    );
}

/// Seed 42 without the attitude: a magnet 53 µT at its peak, passed near the end, whose tail (a few tenths of a µT,
/// below anything that could be called gross) lingers for a while as the sensor moves; it biases A's diagonal by
/// 0.0009, against standard errors from the direction cells of 0.00026 (3.5 of them). Residuals alike for a while
/// are what the cluster-robust covariance over blocks of time sees: the error stays within 3 standard errors.
#[test]
fn a_magnets_tail_widens_the_standard_errors_to_cover_its_bias() {
    let seed = 42;
    let (s, cal) = calibrated(seed, false);
    let (truth_a, truth_offset) = truth(&s, false);
    let (z, at) = worst_z(&cal, &truth_a, truth_offset);
    assert!(z <= 3.0, "{z} standard errors off at {at}");
}

/// Seed 159 with the attitude: the diagnosis locates spans a little wider than the robust fit left out, and
/// fitting without those edges predicts held-out rows no better, so the base fit — which kept them — stands. The
/// report used to call the whole spans "left out of the calibration" all the same; now every sample it says is left
/// out is one the fit did not use, and a span whose samples stayed in says how many, or that all did. (The scalar
/// method's spans are the base fit's exclusions, so there it cannot happen.)
/// Seed 98 without the attitude: 230 µT on the board for the first 14 s (nine times the field) and a magnet passing
/// at up to 244 µT. Every seed of a span that held the field on the board was captured by it (a gain of 0.02) and the
/// others, fitted on a sixth of a recording that covers half the sphere, settled on an ellipsoid twice too large
/// (gain 0.5): the fit was refused as undetermined. The seed from the bulk of the readings (their distance from
/// the median reading within Tukey's far fences) leaves the window out from the start and finds the clean state
/// (measured: offset 0.146 µT off, A 0.0072).
#[test]
fn a_field_many_times_the_earths_on_the_board_cannot_capture_every_seed() {
    let seed = 98;
    let (s, cal) = calibrated(seed, false);
    let (truth_a, truth_offset) = truth(&s, false);
    let (a_err, o_err) = errors(&cal.model(), &truth_a, truth_offset);
    assert!(o_err < 0.3 && a_err < 0.01, "A {a_err}, offset {o_err} µT");
}

#[test]
fn what_the_report_says_is_left_out_is_left_out() {
    let seed = 159;
    let (_, cal) = calibrated(seed, true);
    let d = cal.diagnosis.as_ref().unwrap();
    let r = &d.residuals;
    let wrong = r
        .rows
        .iter()
        .zip(&r.excluded)
        .filter(|(row, x)| **x && cal.robust.kept[**row])
        .count();
    assert_eq!(wrong, 0, "samples reported left out that the fit used");
    let partly: Vec<_> = d.spans.iter().filter(|sp| sp.kept_samples > 0).collect();
    assert!(!partly.is_empty(), "{:?}", d.spans);
    for sp in partly {
        let says = if sp.wholly_kept() {
            "kept in the calibration".to_string()
        } else {
            format!("{} of its", sp.kept_samples)
        };
        assert!(!sp.modelled && sp.explanation.contains(&says), "{sp:?}");
    }
}

#[test]
#[ignore = "statistics over 200 seeds: run in release (CI does)"]
fn vector_method_calibrates_around_gross_disturbances() {
    let t = study(true);
    report("vector method", &t);
    // Measured 2026-11-26: 95.5 % good (91.0 % before the cluster-robust standard errors and leaving out the
    // constants that could be fixed to either frame, 95.0 % before the robust fit's sixth seeds and concentration
    // steps), 100 % located (98.2 % before spans merged across a lull were split where constants explain the
    // parts, 99.1 % before a span was split around a steady stretch a constant explains), 95.5 % of the seeds both
    // (94.5 % before that), none worse (2 before ambiguous guesses were left out and room-fixed constants needed the
    // frame told apart, 1 before a modelled span's rows had to improve the clean held-out fit by 2 %), 0 of 50 false
    // alarms, none refused: the targets. These floors keep them, less one run of good and of both.
    check(
        &t,
        &Floor {
            good_pct: 95.0,
            located_pct: 99.5,
            both_pct: 95.0,
            worse: 0,
            false_alarm_pct: 1.0,
            refused_pct: 0.0,
        },
    );
}

#[test]
#[ignore = "statistics over 200 seeds: run in release (CI does)"]
fn scalar_method_calibrates_around_gross_disturbances() {
    let t = study(false);
    report("scalar method", &t);
    // Measured 2026-11-29: 95.0 % good and of both, at the floors (95.5 % before a field on the board became a second
    // centre fitted with the rest: seed 175, fields of 5.8 and 219 µT on its board, A 0.0064 off against a bound of
    // 0.005, 2.0 standard errors). Measured 2026-11-27: 95.5 % good (95.0 % before a gross span went on beyond its
    // ramp, down to about the noise: `ScalarProblem::RAMP_TAIL`; on 2026-11-26 93.5 % before the base fit's window scan fitted a field fixed to the
    // sensor as well as one fixed in the room, and the diagnosis took its exclusions as they were; 92.5 % before the
    // standard errors saw residuals alike over blocks of time, 92.0 % before the final fit left out the disturbed rows
    // the diagnosis located beyond the robust fit's; 84.8 % before the robust fit's sixth seeds, concentration steps
    // and shifted windows), 100 % located (98.9 % before spans merged across a lull were split here too), 95.5 % of the
    // seeds both (94.5 % before the ramps' tails: magnets' tails at 1–6 µT kept beside the spans), none worse (1 before
    // a scalar finding had to explain a quarter of the residual's excess), 0 of 50 false alarms, none refused (1 before
    // the bulk seed: seed 98, see below; it is now calibrated, 3.5 standard errors off in one element of A): the
    // issue's targets. These floors keep them, less one run of good and of both, and one refusal.
    check(
        &t,
        &Floor {
            good_pct: 95.0,
            located_pct: 99.5,
            both_pct: 95.0,
            worse: 0,
            false_alarm_pct: 1.0,
            refused_pct: 0.5,
        },
    );
}
