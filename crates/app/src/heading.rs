//! The heading error in degrees: how far a compass built on this sensor would point wrong, with the raw readings and
//! with the calibration, at the recording's field.
//!
//! The compass is the sensor held level — its z axis vertical — and turned through 360 headings ψ = 0°, 1°, …, 359°
//! in the local field (horizontal part `H`, vertical part `Z`; only the inclination matters, not the declination).
//! Which way up the sensor sits in the product is not known, so both are computed (z down, x forward, y right; and
//! z up, x forward, y left) and the worse one is reported. Errors are angles in the horizontal plane: the compass's
//! reading minus the true heading.
//!
//! - **Before**: the raw readings used as if they were calibrated. The fitted model is taken as the truth, so at
//!   heading ψ the sensor reads `raw(ψ) = A⁻¹·(B(ψ) − b)`; the error is the exact angle (atan2) of that reading's
//!   horizontal part from magnetic north.
//! - **Left** (after): what the calibration does not remove, as a one-standard-deviation figure per heading:
//!   `√(σ⊥(ψ)² + u²) / H` radians, where `σ⊥(ψ)` is the standard error of the calibrated field across the
//!   horizontal field direction at `raw(ψ)`, from the fit's parameter covariance ([`crate::uncertainty`]), and
//!   `u = √(max(r² − f², 0))` is the part of the residual RMS `r` (per axis, or of |B|) that the measured noise
//!   floor `f` does not account for: what the model leaves unexplained, taken as an error of that size in any
//!   direction.
//!   Figures above [`MAX_ERROR_DEG`] are capped there.
//! - **Left at the worst heading**: not the largest of those figures, which the largest of 360 correlated errors
//!   exceeds far more often than one standard deviation should, but the figure the worst heading's error stays
//!   within as often as a normal error stays within one standard deviation (68.3 %): `√(w² + u²) / H`, where `w` is
//!   that quantile of the largest error across the field over the headings, over [`WORST_DRAWS`] draws of the
//!   parameters' errors from their covariance ([`FieldUncertainty::factors`]; a fixed seed, so the figure is the
//!   same on every run). `tests/heading_claims.rs` measures it against actual errors.
//! - **Noise**: `f / H`, the jitter of a single reading. It is not a calibration error (averaging readings reduces
//!   it), so it is stated beside the figures, not in them.

use magcal_calib::frames::{self, Mat3};
use nalgebra::{DMatrix, DVector, Matrix3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::uncertainty::FieldUncertainty;

/// Headings the figures are computed over (one per degree).
pub const HEADINGS: usize = 360;
/// Draws of the parameters' errors the worst heading's figure is taken over.
pub const WORST_DRAWS: usize = 1000;
/// The share of draws whose worst heading's error the figure covers: a normal error's within one standard deviation.
pub const ONE_SIGMA_SHARE: f64 = 0.682_689_5;
/// The draws' seed: the same draws for every fit, so the figure is the same on every run.
const WORST_SEED: u64 = 0x6d61_6763_616c;
/// A compass cannot be further off than this: larger linearised figures are capped (they mean "no heading").
pub const MAX_ERROR_DEG: f64 = 180.0;

/// The local field as the compass sees it, in the calibrated units of the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalField {
    /// The horizontal part, µT.
    pub horizontal_ut: f64,
    /// The vertical part, positive down, µT.
    pub vertical_ut: f64,
}

impl LocalField {
    /// The field of this inclination (degrees, positive down) and magnitude (µT).
    pub fn new(inclination_deg: f64, magnitude_ut: f64) -> LocalField {
        let i = inclination_deg.to_radians();
        LocalField {
            horizontal_ut: magnitude_ut * i.cos(),
            vertical_ut: magnitude_ut * i.sin(),
        }
    }

    /// The inclination, degrees (positive down).
    pub fn inclination_deg(&self) -> f64 {
        self.vertical_ut.atan2(self.horizontal_ut).to_degrees()
    }
}

/// Which way up the level sensor is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    /// z axis down (x forward, y right): the NED body convention of autopilots.
    ZDown,
    /// z axis up (x forward, y left): a breakout board lying chip up, as most datasheets draw it.
    ZUp,
}

impl Face {
    /// Both.
    pub const BOTH: [Face; 2] = [Face::ZDown, Face::ZUp];

    /// In words.
    pub fn name(self) -> &'static str {
        match self {
            Face::ZDown => "z down",
            Face::ZUp => "z up",
        }
    }

    /// The rotation taking sensor axes to the level frame (magnetic north, east, down) at heading `psi` (radians).
    pub fn sensor_to_level(self, psi: f64) -> Mat3 {
        let (s, c) = psi.sin_cos();
        match self {
            Face::ZDown => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
            // Yaw ψ after a roll of 180° about x: y and z columns flip sign.
            Face::ZUp => [[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]],
        }
    }
}

/// Worst case and RMS of an error over headings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stats {
    /// The largest absolute error, degrees.
    pub worst_deg: f64,
    /// The root mean square over the headings, degrees.
    pub rms_deg: f64,
}

impl Stats {
    fn of(errors_deg: &[f64]) -> Stats {
        Stats {
            worst_deg: errors_deg.iter().fold(0.0, |m, e| m.max(e.abs())),
            rms_deg: (errors_deg.iter().map(|e| e * e).sum::<f64>() / errors_deg.len() as f64)
                .sqrt(),
        }
    }

    fn max(self, other: Stats) -> Stats {
        Stats {
            worst_deg: self.worst_deg.max(other.worst_deg),
            rms_deg: self.rms_deg.max(other.rms_deg),
        }
    }
}

/// [`WORST_DRAWS`] draws of `n` independent standard normal errors, one column a draw, from [`WORST_SEED`].
fn standard_draws(n: usize) -> DMatrix<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(WORST_SEED);
    DMatrix::from_fn(n, WORST_DRAWS, |_, _| StandardNormal.sample(&mut rng))
}

/// The one-standard-deviation figure of the largest error over the headings, radians: the [`ONE_SIGMA_SHARE`]
/// quantile, over `draws` (one column a draw), of the largest `|g_k·z|`, where `g_k`, the error across the field at
/// heading `k` per unit draw (radians), is row `k` of `basis·coefficients`; never below the largest heading's own
/// standard deviation `|g_k|` (which it equals but for the draws' chance when one heading dominates).
fn worst_of_draws_rad(
    basis: &DMatrix<f64>,
    coefficients: &DMatrix<f64>,
    draws: &DMatrix<f64>,
) -> f64 {
    if coefficients.ncols() == 0 {
        return 0.0;
    }
    let mut worst: Vec<f64> = (basis * (coefficients * draws))
        .column_iter()
        .map(|c| c.amax())
        .collect();
    worst.sort_by(f64::total_cmp);
    let rank = (ONE_SIGMA_SHARE * worst.len() as f64).ceil() as usize;
    let largest_sd = (basis * coefficients)
        .row_iter()
        .map(|g| g.norm())
        .fold(0.0, f64::max);
    worst[rank.clamp(1, worst.len()) - 1].max(largest_sd)
}

/// `1, cos ψ, sin ψ, cos 2ψ, sin 2ψ` at each heading ψ (a row each).
fn harmonics() -> DMatrix<f64> {
    DMatrix::from_fn(HEADINGS, 5, |k, j| {
        let psi = (k as f64).to_radians();
        match j {
            0 => 1.0,
            1 => psi.cos(),
            2 => psi.sin(),
            3 => (2.0 * psi).cos(),
            _ => (2.0 * psi).sin(),
        }
    })
}

/// The errors at each heading for one face.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// Which way up.
    pub face: Face,
    /// Raw readings used as if calibrated: signed error at heading `k`°, degrees.
    pub before_deg: Vec<f64>,
    /// What the calibration leaves at heading `k`° (one standard deviation), degrees.
    pub left_deg: Vec<f64>,
    /// What the calibration leaves at the worst heading (one standard deviation of the worst; module docs), degrees.
    pub left_worst_deg: f64,
    /// The part of `left_worst_deg` from the fit's parameter uncertainty alone (`w / H`), degrees.
    pub parameters_worst_deg: f64,
}

/// The heading figures of a calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct HeadingErrors {
    /// The field they are computed at.
    pub field: LocalField,
    /// Raw readings used as if calibrated (the worse face).
    pub before: Stats,
    /// What the calibration leaves (the worse face): at the worst heading (module docs) and the RMS over headings.
    pub left: Stats,
    /// The part of `left`'s worst from the fit's parameter uncertainty alone (the worse face), degrees.
    pub parameters_deg: f64,
    /// The residual the noise does not account for, µT (`u` in the module docs).
    pub unexplained_ut: f64,
    /// One reading's noise across the field direction, degrees RMS.
    pub noise_deg: f64,
    /// Per face, per heading.
    pub curves: Vec<Curve>,
}

/// What the heading figures are computed from.
#[derive(Clone, Copy, Debug)]
pub struct HeadingInput<'a> {
    /// The fitted `A` (its linear part is what the compass applies).
    pub a: Mat3,
    /// The fitted `b`, µT.
    pub b_ut: [f64; 3],
    /// The local field, in the model's calibrated units.
    pub field: LocalField,
    /// The fit's uncertainty, if known.
    pub uncertainty: Option<&'a FieldUncertainty>,
    /// The final model's residual RMS (per axis, or of |B|), µT.
    pub residual_rms_ut: f64,
    /// The noise floor to compare it with, calibrated units, µT.
    pub noise_floor_ut: f64,
}

/// `−atan2(w_E, w_N)` of the level-frame vector `w`, degrees: the compass's reading minus the true heading.
fn error_deg(w: [f64; 3]) -> f64 {
    -w[1].atan2(w[0]).to_degrees()
}

/// Computes the heading figures.
pub fn heading_errors(input: &HeadingInput<'_>) -> HeadingErrors {
    let h = input.field.horizontal_ut;
    let a_inv = Matrix3::from_fn(|j, k| input.a[j][k])
        .try_inverse()
        .unwrap_or_else(Matrix3::zeros);
    let a_inv: Mat3 = std::array::from_fn(|j| std::array::from_fn(|k| a_inv[(j, k)]));
    let unexplained_ut = (input.residual_rms_ut.powi(2) - input.noise_floor_ut.powi(2))
        .max(0.0)
        .sqrt();
    let field_level = [h, 0.0, input.field.vertical_ut];
    let factors = input
        .uncertainty
        .map_or_else(Vec::new, FieldUncertainty::factors);
    let draws = standard_draws(factors.len());
    let harmonics = harmonics();
    let unexplained_rad = unexplained_ut / h;
    let mut before = Stats::default();
    let mut left = Stats::default();
    let mut parameters_deg = 0.0f64;
    let curves: Vec<Curve> = Face::BOTH
        .into_iter()
        .map(|face| {
            let mut before_deg = Vec::with_capacity(HEADINGS);
            let mut left_deg = Vec::with_capacity(HEADINGS);
            // The error across the field at each heading per unit draw, radians.
            let mut per_draw_rad = DMatrix::zeros(HEADINGS, factors.len());
            for k in 0..HEADINGS {
                let r = face.sensor_to_level((k as f64).to_radians());
                let field_sensor = frames::mat_t_vec(&r, field_level);
                let raw = frames::mat_vec(&a_inv, frames::sub(field_sensor, input.b_ut));
                before_deg.push(error_deg(frames::mat_vec(&r, raw)));
                // Across the field in the horizontal plane: level-frame east, in sensor axes.
                let across = frames::mat_t_vec(&r, [0.0, 1.0, 0.0]);
                for (m, f) in factors.iter().enumerate() {
                    per_draw_rad[(k, m)] = frames::dot(f.at(raw), across) / h;
                }
                let sigma = input
                    .uncertainty
                    .map_or(0.0, |u| u.se_along_ut(raw, across));
                left_deg.push(
                    ((sigma * sigma + unexplained_ut * unexplained_ut).sqrt() / h)
                        .to_degrees()
                        .min(MAX_ERROR_DEG),
                );
            }
            // Each column is a trigonometric polynomial of degree 2 in the heading (the raw reading and the direction
            // across are each linear in its cosine and sine): its five Fourier coefficients give it exactly, and
            // each draw's curve costs five products a heading instead of one per factor.
            let coefficients = DMatrix::from_diagonal(&DVector::from_fn(5, |j, _| {
                if j == 0 { 1.0 / 360.0 } else { 1.0 / 180.0 }
            })) * harmonics.transpose()
                * &per_draw_rad;
            let w_rad = worst_of_draws_rad(&harmonics, &coefficients, &draws);
            let parameters_worst_deg = w_rad.to_degrees().min(MAX_ERROR_DEG);
            let left_worst_deg = w_rad.hypot(unexplained_rad).to_degrees().min(MAX_ERROR_DEG);
            parameters_deg = parameters_deg.max(parameters_worst_deg);
            before = before.max(Stats::of(&before_deg));
            left = left.max(Stats {
                worst_deg: left_worst_deg,
                ..Stats::of(&left_deg)
            });
            Curve {
                face,
                before_deg,
                left_deg,
                left_worst_deg,
                parameters_worst_deg,
            }
        })
        .collect();
    HeadingErrors {
        field: input.field,
        before,
        left,
        parameters_deg,
        unexplained_ut,
        noise_deg: (input.noise_floor_ut / h).to_degrees(),
        curves,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wrap_deg(x: f64) -> f64 {
        (x + 180.0).rem_euclid(360.0) - 180.0
    }

    /// The figures against a compass computed directly: for each of 360 headings, the raw reading of a sensor whose
    /// calibration is `A`, `b`, then the heading a level compass reads from it (`atan2(−y, x)` with z down,
    /// `atan2(y, x)` with z up), minus the true heading.
    #[test]
    fn before_matches_a_direct_compass_over_360_headings() {
        let a = [[1.06, 0.03, -0.02], [0.01, 0.94, 0.05], [-0.03, 0.02, 1.1]];
        let b = [9.0, -14.0, 30.0];
        let field = LocalField::new(64.0, 49.0);
        let out = heading_errors(&HeadingInput {
            a,
            b_ut: b,
            field,
            uncertainty: None,
            residual_rms_ut: 0.0,
            noise_floor_ut: 0.0,
        });
        let a_inv = Matrix3::from_fn(|j, k| a[j][k]).try_inverse().unwrap();
        let (h, z) = (field.horizontal_ut, field.vertical_ut);
        let mut worst = 0.0f64;
        let mut rms = [0.0f64; 2];
        for psi_deg in 0..360 {
            let (s, c) = (psi_deg as f64).to_radians().sin_cos();
            let readings = [
                nalgebra::Vector3::new(c * h, -s * h, z),
                nalgebra::Vector3::new(c * h, s * h, -z),
            ];
            for (f, true_field) in readings.into_iter().enumerate() {
                let raw = a_inv * (true_field - nalgebra::Vector3::from(b));
                let reading = if f == 0 {
                    (-raw.y).atan2(raw.x)
                } else {
                    raw.y.atan2(raw.x)
                };
                let err = wrap_deg(reading.to_degrees() - psi_deg as f64);
                let ours = out.curves[f].before_deg[psi_deg];
                assert!(
                    (err - ours).abs() < 1e-9,
                    "heading {psi_deg}, face {f}: {err} vs {ours}"
                );
                worst = worst.max(err.abs());
                rms[f] += err * err / 360.0;
            }
        }
        assert!((out.before.worst_deg - worst).abs() < 1e-9);
        assert!((out.before.rms_deg - rms[0].sqrt().max(rms[1].sqrt())).abs() < 1e-9);
        // A 30 µT offset on z does not turn a level compass; the x–y offsets of ~17 µT against H = 21.5 µT do.
        assert!(out.before.worst_deg > 30.0, "{:?}", out.before);
    }

    /// The worst heading's figure against what it is for errors whose law is known: one heading alone (its own
    /// standard deviation), and twelve independent headings of one standard deviation each (the largest of twelve
    /// |N(0, 1)| stays below 2.153 in 68.27 % of draws: (2Φ(x) − 1)¹² = 0.6827).
    #[test]
    fn the_worst_heading_figure_is_the_quantile_of_the_largest_error() {
        let draws = standard_draws(12);
        let worst = |g: &DMatrix<f64>| {
            worst_of_draws_rad(&DMatrix::identity(g.nrows(), g.nrows()), g, &draws)
        };
        let one = DMatrix::from_fn(1, 12, |_, m| if m < 4 { 0.5 } else { 0.0 });
        let w = worst(&one);
        assert!((1.0..1.04).contains(&w), "{w}");
        let w = worst(&DMatrix::identity(12, 12));
        assert!((w / 2.153 - 1.0).abs() < 0.04, "{w}");
        // The same headings twice over change nothing; no draws at all (no uncertainty) give zero.
        let twice = DMatrix::from_fn(24, 12, |k, m| f64::from(u8::from(k % 12 == m)));
        assert_eq!(worst(&twice), w);
        assert_eq!(worst(&DMatrix::zeros(HEADINGS, 0)), 0.0);
    }

    /// The worst heading's figure of a scalar fit's uncertainty, taken from the curves' Fourier coefficients, is the
    /// one the draws give at every one of the 360 headings directly; it is above the largest per-heading figure.
    #[test]
    fn the_worst_heading_from_five_coefficients_is_the_direct_one() {
        use crate::uncertainty::ScalarParts;

        let u = FieldUncertainty::Scalar(Box::new(ScalarParts {
            a: [[1.05, 0.02, -0.01], [0.02, 0.97, 0.03], [-0.01, 0.03, 1.02]],
            centre_ut: [12.0, -25.0, 7.0],
            centre_cov_ut2: [[0.04, 0.01, 0.0], [0.01, 0.09, -0.02], [0.0, -0.02, 0.05]],
            a_se: [
                [0.004, 0.002, 0.003],
                [0.002, 0.006, 0.001],
                [0.003, 0.001, 0.005],
            ],
        }));
        let a = [
            [0.95, -0.02, 0.01],
            [-0.02, 1.03, -0.03],
            [0.01, -0.03, 0.98],
        ];
        let b_ut = [-11.0, 26.0, -6.0];
        let field = LocalField::new(62.0, 48.0);
        let out = heading_errors(&HeadingInput {
            a,
            b_ut,
            field,
            uncertainty: Some(&u),
            residual_rms_ut: 0.0,
            noise_floor_ut: 0.0,
        });
        let factors = u.factors();
        let draws = standard_draws(factors.len());
        let a_inv = Matrix3::from_fn(|j, k| a[j][k]).try_inverse().unwrap();
        let h = field.horizontal_ut;
        for curve in &out.curves {
            let direct = DMatrix::from_fn(HEADINGS, factors.len(), |k, m| {
                let r = curve.face.sensor_to_level((k as f64).to_radians());
                let field_sensor =
                    nalgebra::Vector3::from(frames::mat_t_vec(&r, [h, 0.0, field.vertical_ut]));
                let raw = a_inv * (field_sensor - nalgebra::Vector3::from(b_ut));
                let across = frames::mat_t_vec(&r, [0.0, 1.0, 0.0]);
                frames::dot(factors[m].at([raw.x, raw.y, raw.z]), across) / h
            });
            let want_deg =
                worst_of_draws_rad(&DMatrix::identity(HEADINGS, HEADINGS), &direct, &draws)
                    .to_degrees();
            assert!(
                (curve.left_worst_deg - want_deg).abs() < 1e-9 * want_deg,
                "{:?}: {} against {want_deg}",
                curve.face,
                curve.left_worst_deg
            );
            let largest = curve.left_deg.iter().fold(0.0f64, |m, e| m.max(*e));
            assert!(
                curve.left_worst_deg > 1.2 * largest,
                "{} against {largest}",
                curve.left_worst_deg
            );
        }
    }

    #[test]
    fn a_perfect_sensor_has_no_error_and_the_unexplained_residual_sets_what_is_left() {
        let field = LocalField::new(60.0, 50.0);
        let out = heading_errors(&HeadingInput {
            a: frames::IDENTITY,
            b_ut: [0.0; 3],
            field,
            uncertainty: None,
            residual_rms_ut: 0.5,
            noise_floor_ut: 0.3,
        });
        assert!(out.before.worst_deg < 1e-12);
        // u = √(0.5² − 0.3²) = 0.4 µT against H = 25 µT: 0.917°, the same at every heading.
        assert!((out.unexplained_ut - 0.4).abs() < 1e-12);
        let want = (0.4f64 / 25.0).to_degrees();
        assert!((out.left.worst_deg - want).abs() < 1e-9 && (out.left.rms_deg - want).abs() < 1e-9);
        assert!((out.noise_deg - (0.3f64 / 25.0).to_degrees()).abs() < 1e-12);
        assert!((field.inclination_deg() - 60.0).abs() < 1e-12);
    }
}
