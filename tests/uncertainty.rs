//! Acceptance: the vector solver's uncertainties are honest. Over 200 seeded simulations, parameter errors divided by
//! the reported standard errors have a standard deviation in 0.8–1.25, and the calibrated-field error is within 20 % of
//! the least-squares bound σ·√(4/N).
//!
//! Heavy: run in release, `cargo test --release --test uncertainty -- --ignored` (CI does).

use magcal_calib::noise;
use magcal_calib::vector::{self, VectorOptions};
use magcal_calib::{Inputs, frames};
use magcal_sim::{ChipModel, Scenario, SensorTruth, Trajectory, simulate, stream_rng};

const RUNS: u64 = 200;

#[test]
#[ignore = "statistics over 200 simulations: run in release (CI does)"]
fn standard_errors_and_the_least_squares_bound_hold_over_200_simulations() {
    let chip = ChipModel::by_name("lis3mdl").unwrap();
    let mut z = Vec::new();
    let (mut err2, mut bound2) = (0.0, 0.0);
    for seed in 0..RUNS {
        let mut s = Scenario::new(
            &chip,
            Trajectory::Tumble {
                duration_s: 60.0,
                rate_rad_s: 1.0,
            },
            seed,
        );
        s.sample_rate_hz = 50.0;
        s.sensor = SensorTruth::random(0.1, 40.0, 3.0, &mut stream_rng(seed, 16));
        let sigma = 0.1 + 0.4 * (seed as f64 / RUNS as f64);
        s.noise_ut = [sigma; 3];
        s.lsb_ut = None;
        let run = simulate(&s).unwrap();
        let rec = &run.recording;
        let expected: Vec<[f64; 3]> = rec
            .quat
            .as_ref()
            .unwrap()
            .iter()
            .map(|q| frames::expected_sensor_field(*q, s.field_ned_ut))
            .collect();
        let floor = noise::estimate(&rec.mag_ut, Some(&expected));
        let fit = vector::fit(
            &rec.mag_ut,
            &expected,
            &VectorOptions {
                raw_noise_var_ut2: floor.floor_ut.map(|f| f * f),
                ..Default::default()
            },
        )
        .unwrap();
        for j in 0..3 {
            for k in 0..3 {
                z.push((fit.a[j][k] - s.sensor.a[j][k]) / fit.a_se[j][k]);
            }
            z.push((fit.b_ut[j] - s.sensor.b_ut[j]) / fit.b_se_ut[j]);
        }
        // Calibrated-field error over the recording's own (noise-free) readings, per axis.
        let truth = magcal_calib::Model::linear(s.sensor.a, s.sensor.b_ut);
        let model = fit.model();
        let n = run.truth.clean_raw_ut.len() as f64;
        let e2: f64 = run
            .truth
            .clean_raw_ut
            .iter()
            .map(|m| {
                let d = frames::sub(
                    model.apply(*m, &Inputs::NONE),
                    truth.apply(*m, &Inputs::NONE),
                );
                frames::dot(d, d) / 3.0
            })
            .sum::<f64>()
            / n;
        // The noise in calibrated axes is A·noise: σ_cal² = σ²·Σ_k A_jk², averaged over j.
        let sigma_cal2 = (0..3)
            .map(|j| {
                (0..3)
                    .map(|k| (s.sensor.a[j][k] * sigma).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / 3.0;
        err2 += e2;
        bound2 += sigma_cal2 * 4.0 / n;
    }
    let mean = z.iter().sum::<f64>() / z.len() as f64;
    let sd = (z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (z.len() - 1) as f64).sqrt();
    let ratio = (err2 / bound2).sqrt();
    println!(
        "{} z-scores: mean {mean:.3}, sd {sd:.3}; calibrated-field error / LS bound = {ratio:.3}",
        z.len()
    );
    assert!((0.8..=1.25).contains(&sd), "sd of error/SE = {sd}");
    assert!(mean.abs() < 0.2, "mean of error/SE = {mean}: biased");
    assert!(
        (0.8..=1.2).contains(&ratio),
        "calibrated-field error / bound = {ratio}"
    );
}
