//! The seed paper's vector calibration (eqs. 2–4): each row of `[A | b]` is the least-squares solution of
//! `A_j·B̂_i + b_j ≈ B0_j,i` against the known field `B0_i` in sensor axes.
//!
//! The three problems share the design `[B̂ᵢᵀ 1]`; they are solved on centred data (the intercept decouples, and the
//! 3×3 normal matrix is then well conditioned even with a 400 µT hard iron), in f64, in three passes over the samples.
//!
//! The raw readings are the regressors and carry the sensor's noise, which biases plain least squares towards a
//! smaller `A` by about σ²/spread² (errors in variables). Given the raw noise variance, that bias is removed by
//! subtracting `N·σ²` from the normal matrix (the corrected least squares of Fuller, *Measurement Error Models*, 1987,
//! §2.2); with a zero variance this is the paper's plain least squares.

use nalgebra::{Matrix3, Matrix4, Vector3};

use crate::FitError;
use crate::coverage::Coverage;
use crate::frames::Mat3;
use crate::model::Model;

/// Options of the vector fit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VectorOptions {
    /// Variance of the raw readings' noise per sensor axis, µT² (see the module docs); zero for plain least squares.
    pub raw_noise_var_ut2: [f64; 3],
    /// Skip the coverage check (for callers that ran it already or fit on purpose-built subsets).
    pub skip_coverage_check: bool,
}

/// The result of a vector fit.
#[derive(Clone, Debug, PartialEq)]
pub struct VectorFit {
    /// `A`, row-major.
    pub a: Mat3,
    /// `b`, µT.
    pub b_ut: [f64; 3],
    /// Standard error of each entry of `A`.
    pub a_se: Mat3,
    /// Standard error of each entry of `b`, µT.
    pub b_se_ut: [f64; 3],
    /// Per calibrated axis `j`, the covariance of `(a_j1, a_j2, a_j3, b_j)`.
    pub covariance: [[[f64; 4]; 4]; 3],
    /// RMS of the residual `A·B̂ + b − B0` per axis, µT.
    pub residual_rms_ut: [f64; 3],
    /// Condition number of the centred design (√ of the ratio of the extreme eigenvalues of the readings'
    /// covariance): how unevenly the rotation explored the three directions.
    pub condition_number: f64,
    /// Samples used.
    pub n: usize,
    /// Samples skipped because their expected field was missing (NaN).
    pub skipped: usize,
    /// Spread of the readings.
    pub coverage: Coverage,
}

impl VectorFit {
    /// The fitted linear model.
    pub fn model(&self) -> Model {
        Model::linear(self.a, self.b_ut)
    }

    /// Standard error (µT, per axis) of the calibrated field for one raw reading, from the parameter covariance.
    pub fn field_se_ut(&self, raw_ut: [f64; 3]) -> [f64; 3] {
        let x = [raw_ut[0], raw_ut[1], raw_ut[2], 1.0];
        std::array::from_fn(|j| {
            let c = &self.covariance[j];
            let var: f64 = (0..4)
                .flat_map(|r| (0..4).map(move |s| (r, s)))
                .map(|(r, s)| x[r] * c[r][s] * x[s])
                .sum();
            var.max(0.0).sqrt()
        })
    }
}

/// Fits `A` and `b` to raw readings and the expected field in sensor axes (both µT). Samples whose expected field
/// has a NaN are skipped and counted.
pub fn fit(
    raw_ut: &[[f64; 3]],
    expected_ut: &[[f64; 3]],
    opts: &VectorOptions,
) -> Result<VectorFit, FitError> {
    assert_eq!(
        raw_ut.len(),
        expected_ut.len(),
        "one expected field per reading"
    );
    let valid = |i: &usize| expected_ut[*i].iter().all(|v| v.is_finite());
    let pairs = || (0..raw_ut.len()).filter(valid);

    // Pass 1: means.
    let (mut n, mut m_sum, mut r_sum) = (0usize, Vector3::zeros(), Vector3::zeros());
    for i in pairs() {
        n += 1;
        m_sum += Vector3::from(raw_ut[i]);
        r_sum += Vector3::from(expected_ut[i]);
    }
    const NEEDED: usize = 8;
    if n < NEEDED {
        return Err(FitError::TooFewSamples {
            needed: NEEDED,
            got: n,
        });
    }
    let nf = n as f64;
    let (m_mean, r_mean) = (m_sum / nf, r_sum / nf);

    // Pass 2: centred cross products.
    let (mut s_mm, mut s_rm) = (Matrix3::zeros(), Matrix3::zeros());
    for i in pairs() {
        let m = Vector3::from(raw_ut[i]) - m_mean;
        let r = Vector3::from(expected_ut[i]) - r_mean;
        s_mm += m * m.transpose();
        s_rm += r * m.transpose();
    }
    let coverage = Coverage::from_covariance(&(s_mm / nf));
    if !opts.skip_coverage_check {
        coverage.check()?;
    }
    let s_corr = s_mm - Matrix3::from_diagonal(&Vector3::from(opts.raw_noise_var_ut2)) * nf;
    let s_inv = s_corr.try_inverse().ok_or(FitError::Singular(
        "the readings' covariance has no inverse",
    ))?;
    let a = s_rm * s_inv;
    let b = r_mean - a * m_mean;

    // Pass 3: residuals.
    let mut rss = Vector3::zeros();
    for i in pairs() {
        let e = a * Vector3::from(raw_ut[i]) + b - Vector3::from(expected_ut[i]);
        rss += e.component_mul(&e);
    }
    let dof = (n - 4) as f64;
    let covariance: [[[f64; 4]; 4]; 3] = std::array::from_fn(|j| {
        // Covariance of (a_j, b_j) = σ_j²·(XᵀX)⁻¹, written out for the centred design.
        let var = rss[j] / dof;
        let s_inv_m = s_inv * m_mean;
        let mut c = Matrix4::zeros();
        c.fixed_view_mut::<3, 3>(0, 0).copy_from(&(s_inv * var));
        for k in 0..3 {
            c[(k, 3)] = -var * s_inv_m[k];
            c[(3, k)] = -var * s_inv_m[k];
        }
        c[(3, 3)] = var * (1.0 / nf + m_mean.dot(&s_inv_m));
        std::array::from_fn(|r| std::array::from_fn(|s| c[(r, s)]))
    });
    let a_arr: Mat3 = std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)]));
    Ok(VectorFit {
        a: a_arr,
        b_ut: [b[0], b[1], b[2]],
        a_se: std::array::from_fn(|j| std::array::from_fn(|k| covariance[j][k][k].sqrt())),
        b_se_ut: std::array::from_fn(|j| covariance[j][3][3].sqrt()),
        covariance,
        residual_rms_ut: std::array::from_fn(|j| (rss[j] / nf).sqrt()),
        condition_number: coverage.spread_ut[0] / coverage.spread_ut[2],
        n,
        skipped: raw_ut.len() - n,
        coverage,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal, UnitSphere};

    #[test]
    fn recovers_a_known_distortion_exactly_without_noise() {
        let a_true = [[1.05, 0.02, -0.01], [0.01, 0.97, 0.03], [-0.02, 0.0, 1.1]];
        let b_true = [5.0, -12.0, 30.0];
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let expected: Vec<[f64; 3]> = (0..500)
            .map(|_| {
                let d: [f64; 3] = UnitSphere.sample(&mut rng);
                frames::scale(d, 50.0)
            })
            .collect();
        let inv = Matrix3::from_fn(|j, k| a_true[j][k]).try_inverse().unwrap();
        let raw: Vec<[f64; 3]> = expected
            .iter()
            .map(|r| {
                let m = inv * (Vector3::from(*r) - Vector3::from(b_true));
                [m[0], m[1], m[2]]
            })
            .collect();
        let fit = fit(&raw, &expected, &VectorOptions::default()).unwrap();
        for j in 0..3 {
            assert!((fit.b_ut[j] - b_true[j]).abs() < 1e-9);
            for k in 0..3 {
                assert!((fit.a[j][k] - a_true[j][k]).abs() < 1e-12);
            }
            assert!(fit.residual_rms_ut[j] < 1e-9);
        }
    }

    #[test]
    fn skips_missing_references_and_reports_them() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let noise = Normal::new(0.0, 0.1).unwrap();
        let mut expected: Vec<[f64; 3]> = (0..400)
            .map(|_| frames::scale(UnitSphere.sample(&mut rng), 48.0))
            .collect();
        let raw: Vec<[f64; 3]> = expected
            .iter()
            .map(|r| r.map(|v| v + noise.sample(&mut rng)))
            .collect();
        for e in expected.iter_mut().step_by(4) {
            e[1] = f64::NAN;
        }
        let fit = fit(&raw, &expected, &VectorOptions::default()).unwrap();
        assert_eq!((fit.n, fit.skipped), (300, 100));
        for j in 0..3 {
            assert!(
                (fit.residual_rms_ut[j] - 0.1).abs() < 0.02,
                "{:?}",
                fit.residual_rms_ut
            );
        }
    }

    #[test]
    fn too_few_samples_is_an_error() {
        let err = fit(&[[1.0; 3]; 3], &[[1.0; 3]; 3], &VectorOptions::default()).unwrap_err();
        assert!(matches!(err, FitError::TooFewSamples { got: 3, .. }));
    }
}
