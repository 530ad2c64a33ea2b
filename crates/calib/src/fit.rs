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
}
