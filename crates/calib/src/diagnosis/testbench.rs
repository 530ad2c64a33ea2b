//! A small simulated bench for the stages' unit tests: a sensor with known gains and hard iron tumbling smoothly in a
//! known field at 50 Hz, with Gaussian noise, a warming temperature, a switching current, and any effects of the
//! catalogue added by their own definition ([`Effect::perturbation_ut`]); the robust base fit made as the caller of
//! the diagnosis makes it.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::effects::{Context, Effect, WorldContext};
use crate::frames::{self, Mat3};
use crate::model::Model;
use crate::noise::{self, NoiseFloor};
use crate::robust::{self, RobustProblem};
use crate::vector::VectorProblem;

use super::samples::Samples;
use super::setup::Setup;
use super::{DiagnosisInput, Reference};

/// The world field, NED, µT.
pub const FIELD_NED_UT: [f64; 3] = [19.8, 1.2, 45.3];
/// The sensor's true `A⁻¹` (what it reads of a field) and hard iron.
const GAINS: Mat3 = [[1.05, 0.02, -0.01], [0.01, 0.96, 0.03], [-0.02, 0.01, 1.08]];
const HARD_IRON_UT: [f64; 3] = [12.0, -30.0, 8.0];
/// The noise per axis, µT.
pub const NOISE_UT: f64 = 0.3;

/// A simulated recording.
pub struct Bench {
    pub raw_ut: Vec<[f64; 3]>,
    pub quat: Vec<[f64; 4]>,
    pub t_s: Vec<f64>,
    pub temp_c: Vec<f64>,
    pub current_a: Vec<f64>,
    pub noise: NoiseFloor,
}

impl Bench {
    /// `n` samples at 50 Hz of a sensor tumbling about a wandering axis, with `effects` added (`seed` for the
    /// noise).
    pub fn new(n: usize, effects: &[Effect], seed: u64) -> Bench {
        Bench::turned(n, effects, seed, |t| {
            turn([(0.31 * t).sin(), (0.23 * t).cos(), 0.6], 0.7 * t)
        })
    }

    /// [`Bench::new`] with the attitude (sensor → NED) a function of time.
    pub fn turned(
        n: usize,
        effects: &[Effect],
        seed: u64,
        attitude: impl Fn(f64) -> [f64; 4],
    ) -> Bench {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, NOISE_UT).expect("a positive deviation");
        let (mut raw_ut, mut quat, mut t_s, mut temp_c, mut current_a) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for i in 0..n {
            let t = i as f64 * 0.02;
            let q = attitude(t);
            let field = frames::expected_sensor_field(q, FIELD_NED_UT);
            let rate = frames::scale(
                frames::sub(
                    frames::expected_sensor_field(attitude(t + 1e-3), FIELD_NED_UT),
                    frames::expected_sensor_field(attitude(t - 1e-3), FIELD_NED_UT),
                ),
                1.0 / 2e-3,
            );
            let temp = 22.0 + 8.0 * (1.0 - (-t / 30.0).exp());
            let current = if (t / 7.0) as usize % 2 == 1 {
                2.0
            } else {
                0.0
            };
            let currents = [current];
            let ctx = Context {
                t_s: t,
                temp_c: temp,
                currents_a: &currents,
                field_ut: field,
                field_rate_ut_per_s: rate,
                world: Some(WorldContext {
                    sensor_to_ned: frames::quat_to_matrix(q),
                    field_ned_ut: FIELD_NED_UT,
                    position_m: [0.0; 3],
                }),
            };
            let read = effects
                .iter()
                .fold(field, |acc, e| frames::add(acc, e.perturbation_ut(&ctx)));
            let m = frames::add(frames::mat_vec(&GAINS, read), HARD_IRON_UT);
            raw_ut.push(std::array::from_fn(|k| m[k] + noise.sample(&mut rng)));
            quat.push(q);
            t_s.push(t);
            temp_c.push(temp);
            current_a.push(current);
        }
        let expected: Vec<[f64; 3]> = quat
            .iter()
            .map(|q| frames::expected_sensor_field(*q, FIELD_NED_UT))
            .collect();
        let noise = noise::estimate(&raw_ut, Some(&expected));
        Bench {
            raw_ut,
            quat,
            t_s,
            temp_c,
            current_a,
            noise,
        }
    }

    /// The diagnosis' input against the attitude reference, with the rows the robust fit `kept` and its scale.
    pub fn input<'a>(&'a self, kept: Option<&'a [bool]>, scale_ut: f64) -> DiagnosisInput<'a> {
        DiagnosisInput {
            raw_ut: &self.raw_ut,
            t_s: Some(&self.t_s),
            temp_c: Some(&self.temp_c),
            currents: vec![("i_motor", &self.current_a)],
            reference: Reference::Attitude {
                quat: &self.quat,
                field_ned_ut: FIELD_NED_UT,
            },
            noise: self.noise,
            kept,
            scale_ut,
        }
    }

    /// The vector method's robust base fit: its model, the rows it kept, its scale.
    pub fn base(&self) -> (Model, Vec<bool>, f64) {
        let problem = self.problem();
        let r = robust::fit(&problem, Some(&self.t_s)).expect("the bench fits");
        (VectorProblem::model(&r.fit), r.kept, r.sigma_ut)
    }

    /// The vector method's problem of this recording.
    pub fn problem(&self) -> VectorProblem<'_> {
        VectorProblem {
            raw_ut: std::borrow::Cow::Borrowed(&self.raw_ut),
            expected_ut: std::borrow::Cow::Owned(
                self.quat
                    .iter()
                    .map(|q| frames::expected_sensor_field(*q, FIELD_NED_UT))
                    .collect(),
            ),
            raw_noise_var_ut2: self.noise.floor_ut.map(|f| f * f),
        }
    }
}

/// The turn by `2·half` radians about `axis`, as a quaternion.
pub fn turn(axis: [f64; 3], half: f64) -> [f64; 4] {
    let norm = frames::norm(axis);
    [
        half.cos(),
        half.sin() * axis[0] / norm,
        half.sin() * axis[1] / norm,
        half.sin() * axis[2] / norm,
    ]
}

/// The true calibration of the bench's sensor: `A` inverts its gains, `b` takes out its hard iron.
pub fn true_model() -> Model {
    let g = nalgebra::Matrix3::from_fn(|j, k| GAINS[j][k]);
    let a = g.try_inverse().expect("invertible gains");
    let a: Mat3 = std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)]));
    let b = frames::scale(frames::mat_vec(&a, HARD_IRON_UT), -1.0);
    Model::linear(a, b)
}

/// A field of `offset_ut` on the board from `t0_s` to `t1_s`.
pub fn on_board(t0_s: f64, t1_s: f64, offset_ut: [f64; 3]) -> Effect {
    Effect::BiasWindow {
        t0_s,
        t1_s,
        offset_ut,
    }
}

/// Runs `f` with the stages' shared part of the bench's recording against its robust base fit (the rows it kept as
/// the input's), and the base fit's residual.
pub fn with_setup<R>(bench: &Bench, f: impl FnOnce(&Setup<'_>, &[[f64; 3]]) -> R) -> R {
    let (base, kept, scale) = bench.base();
    let input = bench.input(Some(&kept), scale);
    let samples = Samples::gather(&input, &base, false);
    let setup = Setup::new(&input, &samples, &base);
    let residual = setup.residual(&base.a, base.b_ut, &[]);
    f(&setup, &residual)
}
