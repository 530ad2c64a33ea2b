//! The bench around one chip, sampled at any time: world field, attitude in a (virtual) hand, the sensor's true
//! errors, effects, temperature and noise.
//!
//! [`simulate`](crate::simulate) turns a whole [`Scenario`](crate::Scenario) into a recording at once. A simulated
//! chip (the register-level twins of `magcal-mockhw`) instead asks for the field when its own output data rate says a
//! conversion finishes, and a recorder decides what the hand does next: tumble freely, or move the sensor to a pose of
//! the cube jig and hold it there. [`Bench`] answers those questions. Both paths compute a sample with the same
//! function, so the physics lives in one place: the raw reading is `A⁻¹·(B + Σδ − b)` plus white noise, with the
//! effects `δ` from [`magcal_calib::effects`].
//!
//! ```
//! use magcal_sim::bench::{Bench, BenchConfig};
//! use magcal_sim::SensorTruth;
//!
//! let mut bench = Bench::new(BenchConfig::ideal([19.8, 1.2, 45.3], 7)).unwrap();
//! bench.hand_mut().move_to(0.0, magcal_sim::cube24_poses()[3].quat, 1.5);
//! let held = bench.sample(2.0);
//! assert_eq!(held.omega_rad_s, [0.0; 3]);
//! assert!((magcal_calib::frames::norm(held.raw_ut) - 49.45).abs() < 0.1);
//! ```

use magcal_calib::effects::{Context, Effect, WorldContext};
use magcal_calib::frames;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::environment::TemperatureProfile;
use crate::scenario::{SimError, against_true_north};
use crate::sensor::SensorTruth;
use crate::stream_rng;
use crate::trajectory::{Pose, TUMBLE_SUBSTEPS, TumbleRate, random_attitude, to_array};

/// What the sensor sees at one pose before noise: the field in the reference's axes and the clean raw reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CleanReading {
    /// The true world field in the sensor's reference axes (without effects), µT.
    pub field_ut: [f64; 3],
    /// The raw reading without noise or quantisation, µT.
    pub raw_ut: [f64; 3],
}

/// The one per-sample computation of the simulator: the world field seen at `pose`, perturbed by the effects, run
/// backwards through the sensor's true calibration `forward` (see [`SensorTruth::forward`]).
pub(crate) fn clean_reading(
    field_ned_ut: [f64; 3],
    effects: &[Effect],
    forward: &impl Fn([f64; 3]) -> [f64; 3],
    pose: &Pose,
    temp_c: f64,
    currents_a: &[f64],
) -> CleanReading {
    let r = frames::quat_to_matrix(pose.quat);
    let field = frames::mat_t_vec(&r, field_ned_ut);
    // A world-fixed field seen from a turning sensor: dB/dt = −ω × B.
    let rate = frames::cross(field, pose.omega_rad_s);
    let ctx = Context {
        t_s: pose.t_s,
        temp_c,
        currents_a,
        field_ut: field,
        field_rate_ut_per_s: rate,
        world: Some(WorldContext {
            sensor_to_ned: r,
            field_ned_ut,
            position_m: pose.position_m,
        }),
    };
    let perturbed = effects
        .iter()
        .fold(field, |acc, e| frames::add(acc, e.perturbation_ut(&ctx)));
    CleanReading {
        field_ut: field,
        raw_ut: forward(perturbed),
    }
}

/// Refuses effects that need a channel the simulation does not have.
pub(crate) fn check_channels(
    effects: &[Effect],
    has_temperature: bool,
    currents: usize,
) -> Result<(), SimError> {
    for e in effects {
        match e {
            Effect::TemperatureBias { .. } | Effect::TemperatureScale { .. }
                if !has_temperature =>
            {
                return Err(SimError::MissingChannel {
                    effect: e.id(),
                    needs: "a temperature profile",
                });
            }
            Effect::CurrentBias { channel, .. } if *channel >= currents => {
                return Err(SimError::MissingChannel {
                    effect: e.id(),
                    needs: "that current channel",
                });
            }
            _ => {}
        }
    }
    Ok(())
}

/// What surrounds the chip. The bench has no current channels, so [`Effect::CurrentBias`] is refused.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchConfig {
    /// The world field, NED, µT.
    pub field_ned_ut: [f64; 3],
    /// The sensor's true calibration (its axes against the reference's: for the cube jig, the jig's axes).
    pub sensor: SensorTruth,
    /// Physics left out of the 12-parameter model.
    pub effects: Vec<Effect>,
    /// The sensor's temperature over time; `None` holds it at 25 °C.
    pub temperature: Option<TemperatureProfile>,
    /// White noise per raw axis, µT.
    pub noise_ut: [f64; 3],
    /// Seed of the hand's random motion (stream 1) and of the noise (stream 3).
    pub seed: u64,
    /// Where the jig's edge (the hand's north) points, degrees east of true north: the hand's attitudes, and the
    /// cube poses the recorder writes, are against it; the sensor turns in the true field.
    pub reference_heading_deg: f64,
}

impl BenchConfig {
    /// A perfect, noise-free sensor in the field `field_ned_ut`, at a constant 25 °C.
    pub fn ideal(field_ned_ut: [f64; 3], seed: u64) -> BenchConfig {
        BenchConfig {
            field_ned_ut,
            sensor: SensorTruth::IDEAL,
            effects: Vec::new(),
            temperature: None,
            noise_ut: [0.0; 3],
            seed,
            reference_heading_deg: 0.0,
        }
    }
}

/// One instant on the bench.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BenchSample {
    /// Time, s.
    pub t_s: f64,
    /// Attitude `[w, x, y, z]`, sensor → NED (for the jig: jig → NED), against the hand's north (see
    /// [`BenchConfig::reference_heading_deg`]).
    pub quat: [f64; 4],
    /// Angular rate in sensor axes, rad/s.
    pub omega_rad_s: [f64; 3],
    /// The true field in the reference's axes, µT.
    pub field_ut: [f64; 3],
    /// The raw reading without noise, µT, in the sensor's axes.
    pub clean_raw_ut: [f64; 3],
    /// The raw reading with noise, µT, not quantised (quantisation belongs to the chip).
    pub raw_ut: [f64; 3],
    /// The sensor's temperature, °C.
    pub temp_c: f64,
}

/// What the hand is doing.
#[derive(Clone, Debug, PartialEq)]
enum Motion {
    /// Holding the sensor still.
    Still,
    /// Turning it freely (a smooth random tumble).
    Tumble(TumbleRate),
    /// Moving it from one attitude to another along the shortest rotation, smoothly (raised-cosine profile).
    Move {
        from: UnitQuaternion<f64>,
        /// The rotation from `from` to the target, as a rotation vector in the sensor's axes at `from`, rad.
        turn: Vector3<f64>,
        t0_s: f64,
        t1_s: f64,
    },
}

/// The virtual hand that holds the sensor: it follows the recorder's instructions.
#[derive(Clone, Debug, PartialEq)]
pub struct Hand {
    quat: UnitQuaternion<f64>,
    t_s: f64,
    motion: Motion,
    rng: ChaCha8Rng,
}

impl Hand {
    /// A hand holding the sensor still at a random attitude at t = 0; its random draws come from `rng`.
    fn new(mut rng: ChaCha8Rng) -> Hand {
        Hand {
            quat: random_attitude(&mut rng),
            t_s: 0.0,
            motion: Motion::Still,
            rng,
        }
    }

    /// Starts turning the sensor freely from `t_s` on, at an RMS rate of `rate_rad_s` (a hand: about 1).
    pub fn tumble(&mut self, t_s: f64, rate_rad_s: f64) {
        self.advance(t_s);
        self.motion = Motion::Tumble(TumbleRate::draw(rate_rad_s, &mut self.rng));
    }

    /// Moves the sensor from wherever it is at `t_s` to `quat` (sensor → NED) in `duration_s` (at once if not
    /// positive), then holds it there.
    pub fn move_to(&mut self, t_s: f64, quat: [f64; 4], duration_s: f64) {
        self.advance(t_s);
        let target = unit(quat);
        if duration_s <= 0.0 {
            self.quat = target;
            self.motion = Motion::Still;
            return;
        }
        let turn = (self.quat.inverse() * target).scaled_axis();
        self.motion = Motion::Move {
            from: self.quat,
            turn,
            t0_s: self.t_s,
            t1_s: self.t_s + duration_s,
        };
    }

    /// Holds the sensor still from `t_s` on.
    pub fn hold(&mut self, t_s: f64) {
        self.advance(t_s);
        self.motion = Motion::Still;
    }

    /// Whether the hand is holding the sensor still at its last time.
    pub fn is_still(&self) -> bool {
        match &self.motion {
            Motion::Still => true,
            Motion::Tumble(_) => false,
            Motion::Move { t1_s, .. } => self.t_s >= *t1_s,
        }
    }

    /// The attitude and rate at `t_s`. Time only runs forwards: an earlier `t_s` gives the pose at the last time.
    pub fn pose(&mut self, t_s: f64) -> Pose {
        self.advance(t_s);
        let omega = match &self.motion {
            Motion::Still => Vector3::zeros(),
            Motion::Tumble(rate) => rate.omega(self.t_s),
            Motion::Move {
                turn, t0_s, t1_s, ..
            } => {
                if self.t_s >= *t1_s || t1_s <= t0_s {
                    Vector3::zeros()
                } else {
                    turn * progress_rate(self.t_s, *t0_s, *t1_s)
                }
            }
        };
        Pose {
            t_s: self.t_s,
            quat: to_array(&self.quat),
            omega_rad_s: [omega.x, omega.y, omega.z],
            position_m: [0.0; 3],
        }
    }

    fn advance(&mut self, t_s: f64) {
        if t_s <= self.t_s {
            return;
        }
        match &self.motion {
            Motion::Still => {}
            Motion::Tumble(rate) => {
                // Integrate in steps no longer than the batch simulator's at 100 Hz.
                let dt = t_s - self.t_s;
                let steps = ((dt / 0.01).ceil() as usize).max(1) * TUMBLE_SUBSTEPS;
                rate.advance(&mut self.quat, self.t_s, dt, steps);
            }
            Motion::Move {
                from,
                turn,
                t0_s,
                t1_s,
            } => {
                let s = progress(t_s, *t0_s, *t1_s);
                self.quat = from * UnitQuaternion::from_scaled_axis(turn * s);
                if s >= 1.0 {
                    self.motion = Motion::Still;
                }
            }
        }
        self.t_s = t_s;
    }
}

/// Fraction of a move done at `t_s`: a raised cosine from 0 at `t0_s` to 1 at `t1_s` (no jerk at either end).
fn progress(t_s: f64, t0_s: f64, t1_s: f64) -> f64 {
    if t_s >= t1_s || t1_s <= t0_s {
        return 1.0;
    }
    let x = ((t_s - t0_s) / (t1_s - t0_s)).clamp(0.0, 1.0);
    (1.0 - (std::f64::consts::PI * x).cos()) / 2.0
}

/// d[`progress`]/dt, 1/s.
fn progress_rate(t_s: f64, t0_s: f64, t1_s: f64) -> f64 {
    let span = t1_s - t0_s;
    let x = ((t_s - t0_s) / span).clamp(0.0, 1.0);
    std::f64::consts::PI / 2.0 * (std::f64::consts::PI * x).sin() / span
}

fn unit(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// The bench: a [`BenchConfig`] brought to life, with a [`Hand`] and a noise source.
pub struct Bench {
    config: BenchConfig,
    forward: Box<dyn Fn([f64; 3]) -> [f64; 3] + Send>,
    noise_rng: ChaCha8Rng,
    hand: Hand,
}

impl std::fmt::Debug for Bench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bench")
            .field("config", &self.config)
            .field("hand", &self.hand)
            .finish_non_exhaustive()
    }
}

impl Bench {
    /// Sets up the bench; refuses effects that need a current channel (the bench has none) or a temperature
    /// effect without a temperature profile.
    pub fn new(config: BenchConfig) -> Result<Bench, SimError> {
        Bench::with_currents(config, 0)
    }

    /// Sets up the bench with `channels` current channels, whose values each sample is given
    /// ([`sample_with_currents`](Self::sample_with_currents)): a twin that knows its own currents (an autopilot's
    /// battery monitor); refuses effects on other channels, or a temperature effect without a temperature profile.
    pub fn with_currents(config: BenchConfig, channels: usize) -> Result<Bench, SimError> {
        check_channels(&config.effects, config.temperature.is_some(), channels)?;
        Ok(Bench {
            forward: Box::new(config.sensor.forward()),
            noise_rng: stream_rng(config.seed, 3),
            hand: Hand::new(stream_rng(config.seed, 1)),
            config,
        })
    }

    /// What the bench was set up with.
    pub fn config(&self) -> &BenchConfig {
        &self.config
    }

    /// The sensor's true calibration.
    pub fn truth(&self) -> SensorTruth {
        self.config.sensor
    }

    /// The hand, to tell it what to do.
    pub fn hand_mut(&mut self) -> &mut Hand {
        &mut self.hand
    }

    /// The hand, to ask what it does.
    pub fn hand(&self) -> &Hand {
        &self.hand
    }

    /// The sensor's temperature at `t_s`, °C.
    pub fn temperature_c(&self, t_s: f64) -> f64 {
        self.config.temperature.map_or(25.0, |p| p.at(t_s))
    }

    /// Everything at `t_s`, with fresh noise. Times should not decrease (the hand only moves forwards).
    pub fn sample(&mut self, t_s: f64) -> BenchSample {
        self.sample_with_currents(t_s, &[])
    }

    /// [`sample`](Self::sample) with the current channels at `currents_a` (A): the effects on them act through the
    /// same function as the batch simulator's; give one value per channel the effects use.
    pub fn sample_with_currents(&mut self, t_s: f64, currents_a: &[f64]) -> BenchSample {
        let pose = self.hand.pose(t_s);
        let temp_c = self.temperature_c(pose.t_s);
        let clean = clean_reading(
            self.config.field_ned_ut,
            &self.config.effects,
            &self.forward,
            &against_true_north(&pose, self.config.reference_heading_deg),
            temp_c,
            currents_a,
        );
        let raw_ut = std::array::from_fn(|k| {
            let g: f64 = StandardNormal.sample(&mut self.noise_rng);
            clean.raw_ut[k] + self.config.noise_ut[k] * g
        });
        BenchSample {
            t_s: pose.t_s,
            quat: pose.quat,
            omega_rad_s: pose.omega_rad_s,
            field_ut: clean.field_ut,
            clean_raw_ut: clean.raw_ut,
            raw_ut,
            temp_c,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::cube24_poses;

    fn angle_deg(a: [f64; 4], b: [f64; 4]) -> f64 {
        unit(a).angle_to(&unit(b)).to_degrees()
    }

    #[test]
    fn a_move_ends_at_the_target_and_holds_it() {
        let mut bench = Bench::new(BenchConfig::ideal([20.0, 0.0, 45.0], 1)).unwrap();
        let target = cube24_poses()[9].quat;
        bench.hand_mut().move_to(1.0, target, 2.0);
        let mid = bench.sample(2.0);
        assert!(angle_deg(mid.quat, target) > 1.0, "still moving at mid-way");
        assert!(frames::norm(mid.omega_rad_s) > 0.0);
        assert!(!bench.hand().is_still());
        let end = bench.sample(3.5);
        assert!(angle_deg(end.quat, target) < 1e-9);
        assert_eq!(end.omega_rad_s, [0.0; 3]);
        assert!(bench.hand().is_still());
        let expected = frames::expected_sensor_field(target, [20.0, 0.0, 45.0]);
        assert!((0..3).all(|k| (end.raw_ut[k] - expected[k]).abs() < 1e-9));
    }

    #[test]
    fn the_move_rate_integrates_to_the_move() {
        let mut bench = Bench::new(BenchConfig::ideal([20.0, 0.0, 45.0], 2)).unwrap();
        let start = bench.sample(0.0).quat;
        let target = cube24_poses()[17].quat;
        bench.hand_mut().move_to(0.0, target, 1.0);
        // Integrate the reported body rate and compare with the reported attitude.
        let mut q = unit(start);
        let dt = 1e-3;
        for i in 0..1000 {
            let w = bench.sample((i as f64 + 0.5) * dt).omega_rad_s;
            q *= UnitQuaternion::from_scaled_axis(Vector3::from(w) * dt);
        }
        assert!(q.angle_to(&unit(target)).to_degrees() < 0.01);
    }

    #[test]
    fn a_tumble_follows_the_batch_tumble_rate_and_noise_is_per_axis() {
        let mut config = BenchConfig::ideal([20.0, 0.0, 45.0], 3);
        config.noise_ut = [0.5, 0.0, 0.0];
        let mut bench = Bench::new(config).unwrap();
        bench.hand_mut().tumble(0.0, 1.0);
        let mut sum2 = 0.0;
        let mut prev = bench.sample(0.0);
        for i in 1..=2000 {
            let s = bench.sample(i as f64 * 0.05);
            sum2 += frames::dot(s.omega_rad_s, s.omega_rad_s);
            assert_eq!(s.raw_ut[1], s.clean_raw_ut[1]);
            // The field magnitude is the world's whatever the attitude (ideal sensor).
            assert!((frames::norm(s.clean_raw_ut) - frames::norm([20.0, 0.0, 45.0])).abs() < 1e-9);
            prev = s;
        }
        let rms = (sum2 / 2000.0).sqrt();
        assert!((0.4..2.0).contains(&rms), "{rms}");
        assert!(prev.raw_ut[0] != prev.clean_raw_ut[0]);
    }

    #[test]
    fn a_move_of_no_duration_is_there_at_once() {
        let mut bench = Bench::new(BenchConfig::ideal([20.0, 0.0, 45.0], 5)).unwrap();
        let target = cube24_poses()[4].quat;
        bench.hand_mut().move_to(0.0, target, 0.0);
        assert!(angle_deg(bench.sample(0.0).quat, target) < 1e-9);
        assert!(bench.hand().is_still());
    }

    #[test]
    fn the_bench_has_no_current_channels() {
        let mut config = BenchConfig::ideal([20.0, 0.0, 45.0], 4);
        config.effects.push(Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: [1.0; 3],
        });
        assert!(matches!(
            Bench::new(config),
            Err(SimError::MissingChannel { .. })
        ));
    }
}
