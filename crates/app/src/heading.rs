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
//! - **Noise**: `f / H`, the jitter of a single reading. It is not a calibration error (averaging readings reduces
//!   it), so it is stated beside the figures, not in them.

use magcal_calib::frames::{self, Mat3};
use nalgebra::Matrix3;

use crate::uncertainty::FieldUncertainty;

/// Headings the figures are computed over (one per degree).
pub const HEADINGS: usize = 360;
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

/// The errors at each heading for one face.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// Which way up.
    pub face: Face,
    /// Raw readings used as if calibrated: signed error at heading `k`°, degrees.
    pub before_deg: Vec<f64>,
    /// What the calibration leaves at heading `k`° (one standard deviation), degrees.
    pub left_deg: Vec<f64>,
}

/// The heading figures of a calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct HeadingErrors {
    /// The field they are computed at.
    pub field: LocalField,
    /// Raw readings used as if calibrated (the worse face).
    pub before: Stats,
    /// What the calibration leaves (the worse face).
    pub left: Stats,
    /// The part of `left` from the fit's parameter uncertainty alone, worst heading, degrees.
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
    let mut before = Stats::default();
    let mut left = Stats::default();
    let mut parameters_deg = 0.0f64;
    let curves: Vec<Curve> = Face::BOTH
        .into_iter()
        .map(|face| {
            let mut before_deg = Vec::with_capacity(HEADINGS);
            let mut left_deg = Vec::with_capacity(HEADINGS);
            for k in 0..HEADINGS {
                let r = face.sensor_to_level((k as f64).to_radians());
                let field_sensor = frames::mat_t_vec(&r, field_level);
                let raw = frames::mat_vec(&a_inv, frames::sub(field_sensor, input.b_ut));
                before_deg.push(error_deg(frames::mat_vec(&r, raw)));
                // Across the field in the horizontal plane: level-frame east, in sensor axes.
                let across = frames::mat_t_vec(&r, [0.0, 1.0, 0.0]);
                let sigma = input
                    .uncertainty
                    .map_or(0.0, |u| u.se_along_ut(raw, across));
                parameters_deg = parameters_deg.max((sigma / h).to_degrees().min(MAX_ERROR_DEG));
                left_deg.push(
                    ((sigma * sigma + unexplained_ut * unexplained_ut).sqrt() / h)
                        .to_degrees()
                        .min(MAX_ERROR_DEG),
                );
            }
            before = before.max(Stats::of(&before_deg));
            left = left.max(Stats::of(&left_deg));
            Curve {
                face,
                before_deg,
                left_deg,
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
