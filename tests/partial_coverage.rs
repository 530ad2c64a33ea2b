//! Acceptance: partial coverage. Caps of directions of 25°, 45°, 70° and 90° half-angle around a random axis, 0.2 µT
//! noise, 100 seeds each, 200 samples (a short hand-held turn) and 1000 samples (20 s at 50 Hz), for a sensor whose
//! response is a sphere (as in the hobbyist's flat turn) and for one with a realistic mild distortion (gains ±4 %,
//! cross terms ±1.5 %): every run either refuses naming a direction to rotate, or reports an offset whose every
//! component's error is within 3 of its reported standard error — as far as honest standard errors can promise it:
//! Gaussian errors put the worst of three components beyond 3 SE in 0.8 % of runs, so the study allows at most 1 % of
//! the fitted runs there, none beyond 4 SE, and asks the spread of error/SE to stay at most 1.15 on every cap (below
//! 1 is conservative). At 70° (sphere, 1000 samples) the median offset error is at most 0.3 µT (MotionCal 0.33 µT on
//! such data).
//!
//! Heavy: `cargo test --release --test partial_coverage -- --ignored --nocapture` (CI runs it).
//!
//! Issue 34, row 5: at 0.3–0.5 µT of noise a 70° cap was refused as "the offset along … is not determined: ±0.5 µT,
//! 1 % of the field", a message whose own rule refuses only above 5 %: the refusal came from the noise correction.
//! That refusal now states its own rule (`a_refusal_for_the_noise_states_its_rule`, not ignored).

use magcal_calib::FitError;
use magcal_calib::scalar::{self, ScalarOptions};
use magcal_calib::{frames, noise};
use nalgebra::{Matrix3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, UnitSphere};

const SEEDS: u64 = 100;
const FIELD_UT: f64 = 50.0;
const NOISE_UT: f64 = 0.2;

/// Directions uniform over the cap of half-angle `deg` around `axis`.
fn cap(axis: [f64; 3], deg: f64, rng: &mut ChaCha8Rng) -> [f64; 3] {
    let cos_max = deg.to_radians().cos();
    let z = rng.random_range(cos_max..1.0);
    let phi = rng.random_range(0.0..std::f64::consts::TAU);
    let r = (1.0 - z * z).sqrt();
    let local = Vector3::new(r * phi.cos(), r * phi.sin(), z);
    // A rotation taking +Z to the axis.
    let a = Vector3::from(axis);
    let zhat = Vector3::z();
    let v = zhat.cross(&a);
    let c = zhat.dot(&a);
    let rot = if v.norm() < 1e-12 {
        if c > 0.0 {
            Matrix3::identity()
        } else {
            Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
        }
    } else {
        let vx = v.cross_matrix();
        Matrix3::identity() + vx + vx * vx * (1.0 / (1.0 + c))
    };
    let d = rot * local;
    [d.x, d.y, d.z]
}

struct Outcome {
    /// Error over standard error of every component of every fitted offset.
    zs: Vec<f64>,
    refused: usize,
    within_3se: usize,
    errors_ut: Vec<f64>,
    worst_z: f64,
}

fn run(deg: f64, distorted: bool, samples: usize) -> Outcome {
    let mut out = Outcome {
        zs: Vec::new(),
        refused: 0,
        within_3se: 0,
        errors_ut: Vec::new(),
        worst_z: 0.0,
    };
    for seed in 0..SEEDS {
        let mut rng = ChaCha8Rng::seed_from_u64(
            1000 * deg as u64 + seed + if distorted { 500_000 } else { 0 },
        );
        let noise = Normal::new(0.0, NOISE_UT).unwrap();
        let axis: [f64; 3] = UnitSphere.sample(&mut rng);
        let offset: [f64; 3] = std::array::from_fn(|_| rng.random_range(-40.0..40.0));
        let mut a = Matrix3::identity();
        if distorted {
            for j in 0..3 {
                a[(j, j)] += rng.random_range(-0.04..0.04);
                for k in j + 1..3 {
                    let x = rng.random_range(-0.015..0.015);
                    a[(j, k)] = x;
                    a[(k, j)] = x;
                }
            }
        }
        let inv = a.try_inverse().unwrap();
        let raw: Vec<[f64; 3]> = (0..samples)
            .map(|_| {
                let d = cap(axis, deg, &mut rng);
                let m = inv * Vector3::from(frames::scale(d, FIELD_UT)) + Vector3::from(offset);
                [m.x, m.y, m.z].map(|v| v + noise.sample(&mut rng))
            })
            .collect();
        let floor = noise::estimate(&raw, None);
        let opts = ScalarOptions {
            field_ut: Some(FIELD_UT),
            raw_noise_var_ut2: floor.floor_ut.map(|f| f * f),
            ..Default::default()
        };
        match scalar::fit(&raw, &opts) {
            Ok(fit) => {
                let e = Vector3::from(fit.centre_ut) - Vector3::from(offset);
                out.zs
                    .extend((0..3).map(|k| e[k] / fit.centre_cov_ut2[k][k].sqrt()));
                // Each component's error in its reported standard errors.
                let z = (0..3)
                    .map(|k| e[k].abs() / fit.centre_cov_ut2[k][k].sqrt())
                    .fold(0.0, f64::max);
                if z <= 3.0 {
                    out.within_3se += 1;
                }
                out.worst_z = out.worst_z.max(z);
                out.errors_ut.push(e.norm());
            }
            Err(
                FitError::Undetermined { advice, .. } | FitError::NoiseDominates { advice, .. },
            ) => {
                assert!(advice.contains("turn the sensor"), "{advice}");
                out.refused += 1;
            }
            Err(FitError::Coverage(e)) => {
                let msg = e.to_string();
                assert!(
                    msg.contains("tip the sensor") || msg.contains("Turn it"),
                    "{msg}"
                );
                out.refused += 1;
            }
            Err(other) => panic!("{deg}° seed {seed}: unexpected error {other}"),
        }
    }
    out
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
#[ignore = "statistics over 1600 fits: run in release (CI does)"]
fn caps_refuse_or_report_an_offset_within_three_standard_errors() {
    println!(
        "| cap | sensor | samples | refused | fitted | within 3 SE | SD of error/SE | median offset error | worst error/SE |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut failures = Vec::new();
    let (mut fitted_all, mut beyond_3se) = (0, 0);
    for (distorted, samples, deg) in [false, true]
        .into_iter()
        .flat_map(|d| [200, 1000].map(|n| (d, n)))
        .flat_map(|(d, n)| [25.0, 45.0, 70.0, 90.0].map(|deg| (d, n, deg)))
    {
        {
            let mut o = run(deg, distorted, samples);
            let fitted = o.errors_ut.len();
            let zn = o.zs.len().max(1) as f64;
            let z_sd = (o.zs.iter().map(|z| z * z).sum::<f64>() / zn).sqrt();
            let med = median(&mut o.errors_ut);
            println!(
                "| {deg:.0}° | {} | {samples} | {} | {fitted} | {} | {} | {} | {:.2} |",
                if distorted { "distorted" } else { "sphere" },
                o.refused,
                o.within_3se,
                if fitted > 0 {
                    format!("{z_sd:.2}")
                } else {
                    "—".into()
                },
                if fitted > 0 {
                    format!("{med:.3} µT")
                } else {
                    "—".into()
                },
                o.worst_z
            );
            fitted_all += fitted;
            beyond_3se += fitted - o.within_3se;
            if o.worst_z > 4.0 {
                failures.push(format!(
                    "{deg}°, {samples} samples: an offset {:.2} standard errors off",
                    o.worst_z
                ));
            }
            if fitted > 0 && z_sd > 1.15 {
                failures.push(format!(
                    "{deg}°, {samples} samples: SD of error/SE {z_sd:.2}"
                ));
            }
            if deg == 70.0 && !distorted && samples == 1000 {
                if fitted < SEEDS as usize * 9 / 10 {
                    failures.push(format!("70°: {} of {SEEDS} refused", o.refused));
                }
                if med > 0.3 {
                    failures.push(format!("70°: median offset error {med} µT"));
                }
            }
        }
    }
    println!("beyond 3 SE: {beyond_3se} of {fitted_all} fitted runs");
    if beyond_3se as f64 > 0.01 * fitted_all as f64 {
        failures.push(format!(
            "{beyond_3se} of {fitted_all} fitted offsets beyond 3 SE"
        ));
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Issue 34, row 5: on a 70° cap at 0.3 µT of noise (1000 samples) the noise correction moves the fit by more than a
/// second-order correction may in some runs; the refusal says so, with the figures and the rule that refused — not an
/// uncertainty below the rule it names. The runs it fits keep honest standard errors.
#[test]
fn a_refusal_for_the_noise_states_its_rule() {
    let (mut refused, mut fitted) = (0, 0);
    for seed in 0..12u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(34_000 + seed);
        let noise = Normal::new(0.0, 0.3).unwrap();
        let axis: [f64; 3] = UnitSphere.sample(&mut rng);
        let offset: [f64; 3] = std::array::from_fn(|_| rng.random_range(-40.0..40.0));
        let raw: Vec<[f64; 3]> = (0..1000)
            .map(|_| {
                let d = cap(axis, 70.0, &mut rng);
                std::array::from_fn(|k| FIELD_UT * d[k] + offset[k] + noise.sample(&mut rng))
            })
            .collect();
        let floor = noise::estimate(&raw, None);
        let opts = ScalarOptions {
            field_ut: Some(FIELD_UT),
            raw_noise_var_ut2: floor.floor_ut.map(|f| f * f),
            ..Default::default()
        };
        match scalar::fit(&raw, &opts) {
            Ok(fit) => {
                fitted += 1;
                for k in 0..3 {
                    let z = (fit.centre_ut[k] - offset[k]).abs() / fit.centre_cov_ut2[k][k].sqrt();
                    assert!(z < 4.0, "seed {seed}: an offset {z:.1} standard errors off");
                }
            }
            Err(e @ FitError::NoiseDominates { .. }) => {
                let FitError::NoiseDominates {
                    centre_moved_ut,
                    centre_limit_ut,
                    gain_moved,
                    gain_limit,
                    converged,
                    noise_ut,
                    ..
                } = e
                else {
                    unreachable!()
                };
                refused += 1;
                // The rule that refused is the one broken, and the message says both.
                assert!(
                    !converged || centre_moved_ut > centre_limit_ut || gain_moved > gain_limit,
                    "{e}"
                );
                assert!((0.2..0.45).contains(&noise_ut), "{e}");
                let msg = e.to_string();
                assert!(
                    msg.contains(&format!("moves the offset by {centre_moved_ut:.1} µT"))
                        && msg.contains("the fit is refused when that correction moves the offset by more than 2.5 µT")
                        && msg.contains("turn the sensor"),
                    "{msg}"
                );
            }
            Err(other) => panic!("seed {seed}: {other}"),
        }
    }
    assert!(
        refused > 0 && fitted > 0,
        "refused {refused}, fitted {fitted}"
    );
}
