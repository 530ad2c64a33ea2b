//! A scenario and its simulation into a recording.

use magcal_calib::effects::{Effect, EffectId};
use magcal_calib::frames;
use magcal_calib::reference_heading;
use magcal_recording::{Layout, Metadata, Recording, Sample};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::bench::{CleanReading, check_channels, clean_reading};
use crate::chips::ChipModel;
use crate::environment::{CurrentProfile, TemperatureProfile};
use crate::noise::{NoiseKind, NoiseSource};
use crate::sensor::SensorTruth;
use crate::stream_rng;
use crate::trajectory::{Pose, Trajectory};

/// Which attitude reference the recording carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AttitudeOutput {
    /// `qw,qx,qy,qz` plus the world field in the metadata (vector calibration).
    Quaternion,
    /// `rx,ry,rz`: the expected field in sensor axes (vector calibration).
    ReferenceField,
    /// None (scalar calibration only).
    None,
}

/// Everything that is simulated. Build one with [`Scenario::new`] and adjust the fields.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    /// Seed of every random draw.
    pub seed: u64,
    /// The `sensor` metadata.
    pub sensor_name: String,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// How the sensor is turned.
    pub trajectory: Trajectory,
    /// The world field the recording states (and, without world-frame effects, the true one), NED, µT.
    pub field_ned_ut: [f64; 3],
    /// The sensor's true calibration.
    pub sensor: SensorTruth,
    /// White noise per raw axis (its standard deviation), µT.
    pub noise_ut: [f64; 3],
    /// The noise's distribution.
    pub noise_kind: NoiseKind,
    /// Quantisation step of the raw reading, µT.
    pub lsb_ut: Option<f64>,
    /// Temperature over time (recorded as `temp` when set).
    pub temperature: Option<TemperatureProfile>,
    /// Quantisation step of the recorded temperature, °C.
    pub temp_lsb_c: Option<f64>,
    /// Currents (recorded as `i_<name>`).
    pub currents: Vec<CurrentProfile>,
    /// Physics left out of the 12-parameter model.
    pub effects: Vec<Effect>,
    /// Which attitude reference is recorded.
    pub attitude: AttitudeOutput,
    /// Random error of the recorded attitude, degrees RMS per axis (a motion-capture or jig error).
    pub attitude_noise_deg: f64,
    /// Record the gyro, with this white noise, rad/s.
    pub gyro_noise_rad_s: Option<f64>,
    /// Where the attitude reference's north points, degrees east of true north (a cube jig's edge, a capture
    /// volume's axes): the attitude is recorded against it, the sensor turns in the true field.
    pub reference_heading_deg: f64,
}

impl Scenario {
    /// A chip on the given trajectory at its default rate, in a 49.45 µT field (19.8 N, 1.2 E, 45.3 D), ideal
    /// calibration, the chip's noise and LSB, its temperature sensor at a constant 25 °C if it has one, recording
    /// the attitude quaternion.
    pub fn new(chip: &ChipModel, trajectory: Trajectory, seed: u64) -> Scenario {
        Scenario {
            seed,
            sensor_name: chip.name.to_owned(),
            sample_rate_hz: chip.rate_hz,
            trajectory,
            field_ned_ut: [19.8, 1.2, 45.3],
            sensor: SensorTruth::IDEAL,
            noise_ut: chip.noise_ut,
            noise_kind: NoiseKind::Gaussian,
            lsb_ut: Some(chip.lsb_ut),
            temperature: chip.temp_lsb_c.map(|_| TemperatureProfile::constant(25.0)),
            temp_lsb_c: chip.temp_lsb_c,
            currents: Vec::new(),
            effects: Vec::new(),
            attitude: AttitudeOutput::Quaternion,
            attitude_noise_deg: 0.0,
            gyro_noise_rad_s: None,
            reference_heading_deg: 0.0,
        }
    }
}

/// What the simulation knows and a fit should find.
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    /// The true calibration.
    pub sensor: SensorTruth,
    /// The injected effects.
    pub effects: Vec<Effect>,
    /// The raw reading per sample before noise and quantisation, µT.
    pub clean_raw_ut: Vec<[f64; 3]>,
    /// The true field in the reference's axes per sample (without effects), µT.
    pub field_ut: Vec<[f64; 3]>,
}

/// A simulated recording and its truth.
#[derive(Clone, Debug, PartialEq)]
pub struct SimRun {
    /// The recording, as a file would hold it.
    pub recording: Recording,
    /// The truth behind it.
    pub truth: Truth,
}

/// A scenario that cannot be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// An effect needs a channel the scenario does not have.
    #[error("effect {effect} needs {needs}, which the scenario does not have")]
    MissingChannel {
        /// The effect.
        effect: EffectId,
        /// What it needs.
        needs: &'static str,
    },
    /// The scenario's channels do not make a valid recording.
    #[error("invalid recording layout: {0}")]
    Layout(String),
    /// The noise's distribution has parameters it cannot have.
    #[error("noise: {0}")]
    Noise(String),
    /// A current switches faster than the samples, or is no number of amperes.
    #[error(
        "current {name}: on {on_a} A, on for {mean_on_s} s and off for {mean_off_s} s on average: each mean must be \
         at least one sample period ({period_s} s), and the current a finite number"
    )]
    Current {
        /// The channel.
        name: String,
        /// Its current when on, A.
        on_a: f64,
        /// Its mean time on, s.
        mean_on_s: f64,
        /// Its mean time off, s.
        mean_off_s: f64,
        /// The sample period, s.
        period_s: f64,
    },
}

/// Refuses currents that would switch faster than the samples: their switching times would take memory without
/// bound (a mean of zero never ends).
fn check_currents(currents: &[CurrentProfile], rate_hz: f64) -> Result<(), SimError> {
    let period_s = 1.0 / rate_hz;
    match currents
        .iter()
        .find(|c| !(c.on_a.is_finite() && c.mean_on_s >= period_s && c.mean_off_s >= period_s))
    {
        Some(c) => Err(SimError::Current {
            name: c.name.clone(),
            on_a: c.on_a,
            mean_on_s: c.mean_on_s,
            mean_off_s: c.mean_off_s,
            period_s,
        }),
        None => Ok(()),
    }
}

/// Simulates a scenario.
pub fn simulate(s: &Scenario) -> Result<SimRun, SimError> {
    check_channels(&s.effects, s.temperature.is_some(), s.currents.len())?;
    check_currents(&s.currents, s.sample_rate_hz)?;
    let poses = s
        .trajectory
        .poses(s.sample_rate_hz, &mut stream_rng(s.seed, 1));
    let duration_s = poses.last().map_or(0.0, |p| p.t_s);
    let mut env_rng = stream_rng(s.seed, 2);
    let switches: Vec<Vec<f64>> = s
        .currents
        .iter()
        .map(|c| c.switch_times(duration_s, &mut env_rng))
        .collect();
    if let Some(why) = s.noise_kind.invalid() {
        return Err(SimError::Noise(why));
    }
    let mut noise = NoiseSource::new(stream_rng(s.seed, 3));

    let layout = Layout {
        t: true,
        temp: s.temperature.is_some(),
        quat: s.attitude == AttitudeOutput::Quaternion,
        reference: s.attitude == AttitudeOutput::ReferenceField,
        gyro: s.gyro_noise_rad_s.is_some(),
        currents: s.currents.iter().map(|c| c.name.clone()).collect(),
        extra: Vec::new(),
    };
    let meta = Metadata {
        sensor: Some(s.sensor_name.clone()),
        sample_rate_hz: Some(s.sample_rate_hz),
        field_ned_ut: (s.attitude == AttitudeOutput::Quaternion).then_some(s.field_ned_ut),
        routine: Some(s.trajectory.routine().to_owned()),
        other: vec![(
            "simulated".to_owned(),
            format!("magcal-sim, seed {}", s.seed),
        )],
        ..Metadata::default()
    };
    let mut recording =
        Recording::new(meta, &layout).map_err(|e| SimError::Layout(e.to_string()))?;
    let forward = s.sensor.forward();
    let mut truth = Truth {
        sensor: s.sensor,
        effects: s.effects.clone(),
        clean_raw_ut: Vec::with_capacity(poses.len()),
        field_ut: Vec::with_capacity(poses.len()),
    };
    let quantise = |v: f64, step: Option<f64>| step.map_or(v, |q| (v / q).round() * q);
    let mut currents_a = vec![0.0; s.currents.len()];
    for pose in &poses {
        let temp_c = s.temperature.map_or(f64::NAN, |p| p.at(pose.t_s));
        for (k, c) in s.currents.iter().enumerate() {
            currents_a[k] = c.at(&switches[k], pose.t_s);
        }
        let CleanReading {
            field_ut: field,
            raw_ut: clean,
        } = clean_reading(
            s.field_ned_ut,
            &s.effects,
            &forward,
            &against_true_north(pose, s.reference_heading_deg),
            temp_c,
            &currents_a,
        );
        let n = noise.reading(s.noise_kind, s.noise_ut);
        let raw: [f64; 3] = std::array::from_fn(|k| quantise(clean[k] + n[k], s.lsb_ut));
        truth.clean_raw_ut.push(clean);
        truth.field_ut.push(field);

        let mut sample = Sample {
            t_s: pose.t_s,
            mag_ut: raw,
            temp_c: quantise(temp_c, s.temp_lsb_c),
            currents_a: currents_a.clone(),
            ..Sample::default()
        };
        match s.attitude {
            AttitudeOutput::Quaternion => {
                sample.quat =
                    recorded_attitude(pose.quat, s.attitude_noise_deg, &mut || noise.gauss())
            }
            AttitudeOutput::ReferenceField => {
                let q = recorded_attitude(pose.quat, s.attitude_noise_deg, &mut || noise.gauss());
                sample.ref_ut = frames::expected_sensor_field(q, s.field_ned_ut);
            }
            AttitudeOutput::None => {}
        }
        if let Some(sigma) = s.gyro_noise_rad_s {
            sample.gyro_rad_s = pose.omega_rad_s.map(|w| w + sigma * noise.gauss());
        }
        recording
            .push(&sample)
            .map_err(|e| SimError::Layout(e.to_string()))?;
    }
    Ok(SimRun { recording, truth })
}

/// `pose`, whose attitude is against a reference with its north `heading_deg` east of true north, against true
/// north.
pub(crate) fn against_true_north(pose: &Pose, heading_deg: f64) -> Pose {
    if heading_deg == 0.0 {
        return *pose;
    }
    Pose {
        quat: reference_heading::true_attitude(pose.quat, heading_deg),
        ..*pose
    }
}

/// The attitude as the reference records it: the truth turned by a small random rotation.
fn recorded_attitude(q: [f64; 4], noise_deg: f64, gauss: &mut impl FnMut() -> f64) -> [f64; 4] {
    if noise_deg == 0.0 {
        return q;
    }
    let e = Vector3::from_fn(|_, _| noise_deg.to_radians() * gauss());
    let q = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
        * UnitQuaternion::from_scaled_axis(e);
    [q.w, q.i, q.j, q.k]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chips::CHIPS;

    fn tumble() -> Trajectory {
        Trajectory::Tumble {
            duration_s: 20.0,
            rate_rad_s: 1.0,
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_recording() {
        let s = Scenario::new(&CHIPS[0], tumble(), 5);
        assert_eq!(simulate(&s).unwrap(), simulate(&s).unwrap());
        let other = Scenario {
            seed: 6,
            ..s.clone()
        };
        assert_ne!(
            simulate(&s).unwrap().recording.mag_ut,
            simulate(&other).unwrap().recording.mag_ut
        );
    }

    #[test]
    fn readings_are_on_the_lsb_grid_and_near_the_truth() {
        let chip = ChipModel::by_name("hmc5883l").unwrap();
        let run = simulate(&Scenario::new(&chip, tumble(), 1)).unwrap();
        for (m, clean) in run.recording.mag_ut.iter().zip(&run.truth.clean_raw_ut) {
            for k in 0..3 {
                let steps = m[k] / chip.lsb_ut;
                assert!((steps - steps.round()).abs() < 1e-6);
                assert!((m[k] - clean[k]).abs() < 6.0 * chip.noise_ut[k] + chip.lsb_ut);
            }
        }
    }

    #[test]
    fn the_recorded_attitude_reproduces_the_field() {
        let mut s = Scenario::new(&CHIPS[4], tumble(), 2);
        s.noise_ut = [0.0; 3];
        s.lsb_ut = None;
        let run = simulate(&s).unwrap();
        let q = run.recording.quat.as_ref().unwrap();
        for (i, m) in run.recording.mag_ut.iter().enumerate() {
            let expected = frames::expected_sensor_field(q[i], s.field_ned_ut);
            assert!((0..3).all(|k| (m[k] - expected[k]).abs() < 1e-9));
        }
    }

    #[test]
    fn a_reference_turned_from_true_north_records_the_attitude_against_it() {
        let mut s = Scenario::new(&CHIPS[4], tumble(), 2);
        s.noise_ut = [0.0; 3];
        s.lsb_ut = None;
        s.reference_heading_deg = 30.0;
        let run = simulate(&s).unwrap();
        let q = run.recording.quat.as_ref().unwrap();
        // The readings are the field in the reference's axes (its declination 30° less) seen at the attitude recorded.
        let field = reference_heading::turned(s.field_ned_ut, 30.0);
        for (i, m) in run.recording.mag_ut.iter().enumerate() {
            let expected = frames::expected_sensor_field(q[i], field);
            assert!((0..3).all(|k| (m[k] - expected[k]).abs() < 1e-9));
        }
        assert_eq!(run.recording.meta.field_ned_ut, Some(s.field_ned_ut));
    }

    #[test]
    fn an_effect_without_its_channel_is_refused() {
        let mut s = Scenario::new(&ChipModel::by_name("hmc5883l").unwrap(), tumble(), 2);
        s.effects.push(Effect::TemperatureBias {
            coef_ut_per_c: [0.1; 3],
            t_ref_c: 25.0,
        });
        assert!(matches!(simulate(&s), Err(SimError::MissingChannel { .. })));
    }
}
