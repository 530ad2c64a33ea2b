//! The common face of the vector and scalar fits ([`CalibrationFit`]): what a report, a verdict or an export needs of
//! a fit, whatever its method — the model, the coverage, the residual, the standard errors.

use crate::coverage::Coverage;
use crate::frames::Mat3;
use crate::model::Model;
use crate::noise::rms3;
use crate::scalar::{self, ScalarFit};
use crate::vector::VectorFit;

/// What every calibration fit offers.
pub trait CalibrationFit {
    /// The fitted linear model `B = A·B̂ + b`.
    fn model(&self) -> Model;
    /// The spread of the readings it used.
    fn coverage(&self) -> &Coverage;
    /// Its residual's RMS, µT: per axis (vector), or of |B| (scalar).
    fn residual_rms_ut(&self) -> f64;
    /// Standard errors of `A`'s entries and of `b`, µT.
    fn standard_errors(&self) -> (Mat3, [f64; 3]);
    /// Standard errors of the offset `−A⁻¹·b`, µT.
    fn offset_se_ut(&self) -> [f64; 3];
    /// Samples used.
    fn samples_used(&self) -> usize;
    /// The field magnitude the fit aimed at, when it fitted |B| alone (scalar), µT.
    fn magnitude_ut(&self) -> Option<f64>;
    /// How much more the fits of the recording's two halves in time disagree than their covariances say.
    fn halves(&self) -> Halves;
}

/// How much more the fits of a recording's two halves in time disagree than their covariances say: `κ` per parameter
/// (about 1 when they agree, 1 when not measured), of `parameters` (12 for the vector fit, 9 for the scalar one).
/// The standard errors are scaled by `√κ` when it is above 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Halves {
    /// `κ = dᵀ(V₁ + V₂)⁻¹d / parameters`, `d` the halves' difference, `V` their covariances.
    pub kappa: f64,
    /// The parameters compared.
    pub parameters: usize,
}

/// The normal quantile of the halves' chance level: one recording in a hundred.
const CHANCE_Z: f64 = 2.326;

impl Halves {
    /// The factor the standard errors were widened by, `√κ`, at least 1.
    pub fn widening(&self) -> f64 {
        self.kappa.max(1.0).sqrt()
    }

    /// Whether the halves disagree by more than noise alone makes them in one recording in a hundred: `p·κ` beyond
    /// the 99th percentile of χ² with `p` degrees of freedom (Wilson–Hilferty's approximation).
    pub fn beyond_chance(&self) -> bool {
        let p = self.parameters as f64;
        let h = 2.0 / (9.0 * p);
        let limit = p * (1.0 - h + CHANCE_Z * h.sqrt()).powi(3);
        p * self.kappa > limit
    }
}

impl CalibrationFit for VectorFit {
    fn model(&self) -> Model {
        VectorFit::model(self)
    }

    fn coverage(&self) -> &Coverage {
        &self.coverage
    }

    fn residual_rms_ut(&self) -> f64 {
        rms3(self.residual_rms_ut)
    }

    fn standard_errors(&self) -> (Mat3, [f64; 3]) {
        (self.a_se, self.b_se_ut)
    }

    /// Propagated through `dc = −A⁻¹·(dA·c + db)` from the covariance of each row (rows independent).
    fn offset_se_ut(&self) -> [f64; 3] {
        let model = VectorFit::model(self);
        let c = scalar::centre(&model.a, model.b_ut);
        let row_var: [f64; 3] = std::array::from_fn(|j| {
            let g = [c[0], c[1], c[2], 1.0];
            (0..4)
                .flat_map(|r| (0..4).map(move |s| (r, s)))
                .map(|(r, s)| g[r] * self.covariance[j][r][s] * g[s])
                .sum::<f64>()
        });
        let a = nalgebra::Matrix3::from_fn(|j, k| model.a[j][k]);
        let inv = a.try_inverse().unwrap_or_else(nalgebra::Matrix3::zeros);
        std::array::from_fn(|k| {
            (0..3)
                .map(|j| (inv[(k, j)].powi(2)) * row_var[j])
                .sum::<f64>()
                .sqrt()
        })
    }

    fn samples_used(&self) -> usize {
        self.n
    }

    fn magnitude_ut(&self) -> Option<f64> {
        None
    }

    fn halves(&self) -> Halves {
        Halves {
            kappa: self.dispersion,
            parameters: 12,
        }
    }
}

impl CalibrationFit for ScalarFit {
    fn model(&self) -> Model {
        ScalarFit::model(self)
    }

    fn coverage(&self) -> &Coverage {
        &self.coverage
    }

    fn residual_rms_ut(&self) -> f64 {
        self.residual_rms_ut
    }

    fn standard_errors(&self) -> (Mat3, [f64; 3]) {
        (self.a_se, self.b_se_ut)
    }

    /// From the centre's covariance.
    fn offset_se_ut(&self) -> [f64; 3] {
        std::array::from_fn(|k| self.centre_cov_ut2[k][k].sqrt())
    }

    fn samples_used(&self) -> usize {
        self.n
    }

    fn magnitude_ut(&self) -> Option<f64> {
        Some(self.field_ut)
    }

    fn halves(&self) -> Halves {
        Halves {
            kappa: self.dispersion,
            parameters: 9,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Halves;

    #[test]
    fn the_halves_disagree_beyond_chance_above_the_99th_percentile_of_chi_squared() {
        // χ² at 0.99: 26.22 with 12 degrees of freedom, 21.67 with 9 (tables).
        let beyond = |kappa: f64, parameters: usize| Halves { kappa, parameters }.beyond_chance();
        assert!(!beyond(26.0 / 12.0, 12) && beyond(26.5 / 12.0, 12));
        assert!(!beyond(21.5 / 9.0, 9) && beyond(21.9 / 9.0, 9));
        assert_eq!(
            Halves {
                kappa: 0.5,
                parameters: 9
            }
            .widening(),
            1.0
        );
        assert_eq!(
            Halves {
                kappa: 4.0,
                parameters: 9
            }
            .widening(),
            2.0
        );
    }
}
