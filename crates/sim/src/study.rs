//! Scenarios for studying the diagnosis: random benches, each effect of the catalogue in a random but physical
//! shape, and effects scaled to a chosen size per sample.

use magcal_calib::effects::{Effect, EffectId};
use magcal_calib::frames;
use rand::RngExt;

use crate::chips::CHIPS;
use crate::environment::{CurrentProfile, TemperatureProfile};
use crate::scenario::{Scenario, simulate};
use crate::sensor::SensorTruth;
use crate::stream_rng;
use crate::trajectory::Trajectory;

/// A random bench recording as the power study draws it: a random chip's LSB, random sensor errors (soft iron up to
/// 10 %, hard iron up to 40 µT, mounting up to 3°), a random world field (25–65 µT, inclination −70…+75°), a tumble
/// of 2–5 minutes at 20–100 Hz, noise 0.05–0.5 µT, a temperature that warms up and wobbles, and one current channel
/// switching on and off.
pub fn random_scenario(seed: u64) -> Scenario {
    let mut rng = stream_rng(seed, 17);
    let chip = CHIPS[rng.random_range(0..CHIPS.len())];
    let duration_s = rng.random_range(120.0..300.0);
    let mut s = Scenario::new(
        &chip,
        Trajectory::Tumble {
            duration_s,
            rate_rad_s: rng.random_range(0.5..1.5),
        },
        seed,
    );
    s.sample_rate_hz = rng.random_range(20.0..100.0);
    s.noise_ut = [rng.random_range(0.05..0.5); 3];
    // Quantisation well below the noise, as on the chips at their finest range.
    s.lsb_ut = Some(chip.lsb_ut.min(s.noise_ut[0] / 3.0));
    s.sensor = SensorTruth::random(0.1, 40.0, 3.0, &mut stream_rng(seed, 18));
    s.field_ned_ut = frames::field_from_angles(
        rng.random_range(-15.0..15.0),
        rng.random_range(-70.0..75.0),
        rng.random_range(25.0..65.0),
    );
    s.temperature = Some(TemperatureProfile {
        start_c: rng.random_range(15.0..30.0),
        warmup_c: rng.random_range(2.0..10.0),
        tau_s: rng.random_range(0.2..0.8) * duration_s,
        wobble_c: rng.random_range(0.5..2.0),
        wobble_period_s: rng.random_range(0.1..0.4) * duration_s,
        wobble_phase_rad: rng.random_range(0.0..std::f64::consts::TAU),
    });
    s.temp_lsb_c = Some(0.01);
    s.currents = vec![CurrentProfile {
        name: "i_motor".to_owned(),
        on_a: rng.random_range(0.5..3.0),
        mean_on_s: rng.random_range(3.0..15.0),
        mean_off_s: rng.random_range(3.0..15.0),
    }];
    s
}

/// The scenario's duration, s.
pub fn duration_s(s: &Scenario) -> f64 {
    match s.trajectory {
        Trajectory::Tumble { duration_s, .. } | Trajectory::Turntable { duration_s, .. } => {
            duration_s
        }
        Trajectory::Cube24 {
            dwell_s,
            transition_s,
        } => 24.0 * (dwell_s + transition_s),
    }
}

/// An effect of the given kind in a random physical shape (direction, timing), at an arbitrary size: scale it with
/// [`scale_to_rms`]. `current_bias` uses the scenario's first current channel.
pub fn random_effect(id: EffectId, s: &Scenario, seed: u64) -> Effect {
    let mut rng = stream_rng(seed, 19);
    let mut dir = || {
        let v = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        frames::scale(v, 1.0 / frames::norm(v).max(1e-9))
    };
    let d = dir();
    let d2 = dir();
    let mut rng = stream_rng(seed, 20);
    let t_end = duration_s(s);
    let t_ref_c = s.temperature.map_or(25.0, |t| t.start_c);
    match id {
        EffectId::TemperatureBias => Effect::TemperatureBias {
            coef_ut_per_c: d,
            t_ref_c,
        },
        EffectId::TemperatureScale => Effect::TemperatureScale {
            coef_per_c: frames::scale(d, 1e-3),
            t_ref_c,
        },
        EffectId::CurrentBias => Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: d,
        },
        EffectId::TimeLag => Effect::TimeLag {
            lag_s: if rng.random::<bool>() { 0.01 } else { -0.01 },
        },
        // Markedly unequal per-axis delays: one axis much slower than the others.
        EffectId::RateCoupling => {
            let slow = rng.random_range(0..3);
            let mut l = [0.0; 3];
            l[slow] = 0.01;
            Effect::RateCoupling { lag_axis_s: l }
        }
        EffectId::FieldDrift => Effect::FieldDrift {
            rate_ut_per_s: frames::scale(d, 1e-3),
            t_ref_s: t_end / 2.0,
        },
        EffectId::FieldDirectionError => {
            let a = rng.random_range(0.0..std::f64::consts::TAU);
            Effect::FieldDirectionError {
                declination_error_deg: a.cos(),
                inclination_error_deg: a.sin(),
            }
        }
        EffectId::Nonlinearity => Effect::Nonlinearity {
            cubic_per_ut2: frames::scale(d, 1e-6),
        },
        EffectId::BiasStep => Effect::BiasStep {
            t_s: rng.random_range(0.25..0.75) * t_end,
            step_ut: d,
        },
        EffectId::BiasDrift => Effect::BiasDrift {
            rate_ut_per_s: frames::scale(d, 1e-3),
            t_ref_s: 0.0,
        },
        EffectId::Disturbance => {
            let len = rng.random_range(0.1..0.3) * t_end;
            let t0_s = rng.random_range(0.1..0.9) * (t_end - len);
            Effect::Disturbance {
                t0_s,
                t1_s: t0_s + len,
                field_ned_ut: d2,
            }
        }
        EffectId::BiasWindow => {
            let len = rng.random_range(0.1..0.3) * t_end;
            let t0_s = rng.random_range(0.1..0.9) * (t_end - len);
            Effect::BiasWindow {
                t0_s,
                t1_s: t0_s + len,
                offset_ut: d2,
            }
        }
        // Half a metre from the wander's centre, the moment along a random direction.
        EffectId::MagnetNearby => Effect::MagnetNearby {
            position_m: frames::scale(d, 0.5),
            moment_am2: d2,
        },
    }
}

/// The RMS per axis over the recording of an effect's perturbation (µT): what "an effect of size x" means in the
/// study.
pub fn effect_rms_ut(s: &Scenario, e: &Effect) -> f64 {
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
    let (Ok(a), Ok(b)) = (simulate(&quiet), simulate(&with)) else {
        return f64::NAN;
    };
    let n = a.truth.clean_raw_ut.len().max(1) as f64;
    let ss: f64 = a
        .truth
        .clean_raw_ut
        .iter()
        .zip(&b.truth.clean_raw_ut)
        .map(|(x, y)| {
            // δ in calibrated axes: A·(raw_with − raw_without).
            let d = frames::mat_vec(&s.sensor.a, frames::sub(*y, *x));
            frames::dot(d, d)
        })
        .sum();
    (ss / (3.0 * n)).sqrt()
}

/// The effect rescaled so that its perturbation has `target_ut` RMS per axis over the recording (the field direction
/// error is scaled as if linear, which it is to 10⁻⁴ at these sizes).
pub fn scale_to_rms(s: &Scenario, e: &Effect, target_ut: f64) -> Effect {
    let now = effect_rms_ut(s, e);
    let k = target_ut / now;
    let (p, _) = e.params();
    e.with_params(p.map(|v| v * k))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effects_scale_to_the_asked_size() {
        let s = Scenario {
            trajectory: Trajectory::Tumble {
                duration_s: 60.0,
                rate_rad_s: 1.0,
            },
            sample_rate_hz: 20.0,
            ..random_scenario(3)
        };
        for id in EffectId::ALL {
            let e = scale_to_rms(&s, &random_effect(id, &s, 3), 0.1);
            let got = effect_rms_ut(&s, &e);
            assert!((got - 0.1).abs() < 1e-3, "{id}: {got}");
        }
    }
}
