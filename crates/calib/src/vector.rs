//! The seed paper's vector calibration (eqs. 2–4): each row of `[A | b]` is the least-squares solution of
//! `A_j·B̂_i + b_j ≈ B0_j,i` against the known field `B0_i` in sensor axes.
//!
//! The three problems share the design `[B̂ᵢᵀ 1]`; they are solved on centred data (the intercept decouples, and the
//! 3×3 normal matrix is then well conditioned even with a 400 µT hard iron), in f64, from sums gathered in one pass.
//!
//! The raw readings are the regressors and carry the sensor's noise, which biases plain least squares towards a
//! smaller `A` by about σ²/spread² (errors in variables). Given the raw noise variance, that bias is removed by
//! subtracting `N·σ²` from the normal matrix (the corrected least squares of Fuller, *Measurement Error Models*, 1987,
//! §2.2); with a zero variance this is the paper's plain least squares. The raw noise can only show in the residual
//! through `A`, so a variance the residual cannot hold (`Σ_k A_jk²·σ_k²` above the residual variance of axis `j`, as
//! when the noise was measured on rows that jump from pose to pose) is scaled down until it can: the correction is
//! never larger than the data allow.
//!
//! Standard errors: the largest (in every direction of the parameter space) of the model-based covariance
//! `σ²·(XᵀX − N·σ_raw²)⁻¹` with its exact degrees of freedom, the cluster-robust (sandwich) covariance over cells of
//! field direction, which sees residuals that are alike within an orientation (reference errors, a pose's attitude
//! error, model errors that depend on direction) where the model-based one assumes them independent, and the
//! cluster-robust covariance over [`TIME_BLOCKS`] blocks of time, which sees residuals alike for a while (something on
//! the board for part of the recording, a magnet's tail, a drift): on the physical Nexus 5 recording with 8 µT on the
//! board for 18 of its 64 referenced seconds, unlocated, A was 5.4 standard errors off by the other two.

use nalgebra::{DMatrix, Matrix3, Matrix4, Vector3, Vector4};

use std::borrow::Cow;

use crate::FitError;
use crate::chunks;
use crate::coverage::{Coverage, SphereGrid};
use crate::frames::{self, Mat3};
use crate::model::Model;
use crate::robust::RobustProblem;

/// Options of the vector fit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VectorOptions<'a> {
    /// Variance of the raw readings' noise per sensor axis, µT² (see the module docs); zero for plain least squares.
    pub raw_noise_var_ut2: [f64; 3],
    /// Skip the coverage check (for callers that ran it already or fit on purpose-built subsets).
    pub skip_coverage_check: bool,
    /// A weight per sample in `[0, 1]` (zero leaves a sample out), for robust refits; all ones when absent.
    pub weights: Option<&'a [f64]>,
    /// Per sample, whether it is fitted (false leaves it out, whatever its weight); all when absent.
    pub kept: Option<&'a [bool]>,
    /// `A`, `b` and the residual only, from one pass of sums (for the reweighting passes of a robust fit): no
    /// standard errors (zero), no cells of direction.
    pub estimates_only: bool,
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
    /// RMS of the residual `A·B̂ + b − B0` per axis over the samples used (weighted), µT.
    pub residual_rms_ut: [f64; 3],
    /// Condition number of the centred design (√ of the ratio of the extreme eigenvalues of the readings'
    /// covariance): how unevenly the rotation explored the three directions.
    pub condition_number: f64,
    /// Samples used (non-zero weight).
    pub n: usize,
    /// Samples skipped because their expected field was missing (NaN) or their weight zero.
    pub skipped: usize,
    /// Spread of the readings.
    pub coverage: Coverage,
    /// The factor (at most 1) the raw noise variance was scaled by so that the residual can hold it.
    pub noise_bound: f64,
    /// Cells of field direction the samples fell in (the clusters of the robust standard errors).
    pub direction_cells: usize,
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

/// The vector method as a robust problem (see [`crate::robust`]): readings, expected fields, raw noise.
#[derive(Clone, Debug)]
pub struct VectorProblem<'a> {
    /// Raw readings, µT.
    pub raw_ut: Cow<'a, [[f64; 3]]>,
    /// The expected field in sensor axes, µT (NaN = missing).
    pub expected_ut: Cow<'a, [[f64; 3]]>,
    /// Variance of the raw noise per axis, µT².
    pub raw_noise_var_ut2: [f64; 3],
}

impl RobustProblem for VectorProblem<'_> {
    type Fit = VectorFit;
    /// The median of a χ distribution with three degrees of freedom.
    const MEDIAN_OF_UNIT: f64 = 1.538_2;

    fn len(&self) -> usize {
        self.raw_ut.len()
    }

    fn every(&self, stride: usize) -> Self {
        VectorProblem {
            raw_ut: self.raw_ut.iter().step_by(stride).copied().collect(),
            expected_ut: self.expected_ut.iter().step_by(stride).copied().collect(),
            raw_noise_var_ut2: self.raw_noise_var_ut2,
        }
    }

    /// Linear: solved directly, from no start.
    fn quick_fit(&self, weights: &[f64], _: Option<&VectorFit>) -> Result<VectorFit, FitError> {
        self.fit_with(&VectorOptions {
            weights: Some(weights),
            skip_coverage_check: true,
            estimates_only: true,
            ..Default::default()
        })
    }

    fn final_fit(&self, kept: &[bool], _: Option<&VectorFit>) -> Result<VectorFit, FitError> {
        self.fit_with(&VectorOptions {
            kept: Some(kept),
            ..Default::default()
        })
    }

    fn residuals(&self, fit: &VectorFit) -> Vec<f64> {
        let (raw, expected) = (&self.raw_ut, &self.expected_ut);
        chunks::map(raw.len(), |i| {
            let cal = frames::add(frames::mat_vec(&fit.a, raw[i]), fit.b_ut);
            frames::norm(frames::sub(cal, expected[i]))
        })
    }

    fn model(fit: &VectorFit) -> Model {
        fit.model()
    }
}

impl VectorProblem<'_> {
    /// The fit with `opts` and the problem's noise.
    fn fit_with(&self, opts: &VectorOptions) -> Result<VectorFit, FitError> {
        let opts = VectorOptions {
            raw_noise_var_ut2: self.raw_noise_var_ut2,
            ..*opts
        };
        fit(&self.raw_ut, &self.expected_ut, &opts)
    }
}

/// Weighted sums of the readings `d` and references `e` (shifted by the first usable sample), and their products.
#[derive(Clone, Copy, Debug)]
struct Sums {
    n: usize,
    w_sum: f64,
    sm: Vector3<f64>,
    sr: Vector3<f64>,
    smm: Matrix3<f64>,
    srm: Matrix3<f64>,
    srr: Matrix3<f64>,
}

impl Default for Sums {
    fn default() -> Sums {
        Sums {
            n: 0,
            w_sum: 0.0,
            sm: Vector3::zeros(),
            sr: Vector3::zeros(),
            smm: Matrix3::zeros(),
            srm: Matrix3::zeros(),
            srr: Matrix3::zeros(),
        }
    }
}

impl Sums {
    fn merge(self, o: Sums) -> Sums {
        Sums {
            n: self.n + o.n,
            w_sum: self.w_sum + o.w_sum,
            sm: self.sm + o.sm,
            sr: self.sr + o.sr,
            smm: self.smm + o.smm,
            srm: self.srm + o.srm,
            srr: self.srr + o.srr,
        }
    }
}

/// Cells of field direction for the cluster-robust standard errors.
const DIRECTION_CELLS: usize = 100;
/// Blocks of consecutive samples (of time, in a recording) for the cluster-robust standard errors over time (the
/// scalar fit's too).
pub(crate) const TIME_BLOCKS: usize = 32;
/// Fewest samples the fit takes (four unknowns per axis, and a few degrees of freedom for the residual).
pub const MIN_SAMPLES: usize = 8;

/// Fits `A` and `b` to raw readings and the expected field in sensor axes (both µT). Samples whose expected field
/// or reading has a NaN are skipped and counted.
pub fn fit(
    raw_ut: &[[f64; 3]],
    expected_ut: &[[f64; 3]],
    opts: &VectorOptions<'_>,
) -> Result<VectorFit, FitError> {
    assert_eq!(
        raw_ut.len(),
        expected_ut.len(),
        "one expected field per reading"
    );
    if let Some(w) = opts.weights {
        assert_eq!(w.len(), raw_ut.len(), "one weight per reading");
    }
    if let Some(k) = opts.kept {
        assert_eq!(k.len(), raw_ut.len(), "one kept flag per reading");
    }
    let weight = |i: usize| {
        let usable = opts.kept.is_none_or(|k| k[i])
            && expected_ut[i]
                .iter()
                .chain(&raw_ut[i])
                .all(|v| v.is_finite());
        let w = opts.weights.map_or(1.0, |w| w[i]);
        if usable && w > 0.0 { w } else { 0.0 }
    };

    // One pass: weighted sums of the readings and references, shifted by the first usable sample for precision.
    let Some(first) = (0..raw_ut.len()).find(|&i| weight(i) > 0.0) else {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: 0,
        });
    };
    let (m0, r0) = (
        Vector3::from(raw_ut[first]),
        Vector3::from(expected_ut[first]),
    );
    let sums = chunks::fold(
        raw_ut.len(),
        |range| {
            let mut s = Sums::default();
            for i in range {
                let w = weight(i);
                if w == 0.0 {
                    continue;
                }
                let d = Vector3::from(raw_ut[i]) - m0;
                let e = Vector3::from(expected_ut[i]) - r0;
                s.n += 1;
                s.w_sum += w;
                s.sm += d * w;
                s.sr += e * w;
                s.smm += d * d.transpose() * w;
                s.srm += e * d.transpose() * w;
                s.srr += e * e.transpose() * w;
            }
            s
        },
        Sums::merge,
    )
    .unwrap_or_default();
    let Sums {
        n,
        w_sum,
        sm,
        sr,
        smm,
        srm,
        srr,
    } = sums;
    if n < MIN_SAMPLES {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: n,
        });
    }
    let (dm, dr) = (sm / w_sum, sr / w_sum);
    let m_mean = m0 + dm;
    let r_mean = r0 + dr;
    let s_mm = smm - dm * dm.transpose() * w_sum;
    let s_rm = srm - dr * dm.transpose() * w_sum;
    let s_rr = srr - dr * dr.transpose() * w_sum;

    let coverage = Coverage::from_covariance(&(s_mm / w_sum));
    if !opts.skip_coverage_check {
        coverage.check()?;
        let reference_ut = Coverage::from_covariance(&(s_rr / w_sum)).spread_ut[0];
        if reference_ut < crate::coverage::STILL_SPREAD_UT {
            return Err(FitError::ReferenceStill {
                reference_ut,
                readings_ut: coverage.spread_ut[0],
            });
        }
    }
    let s_mm_inv = s_mm.try_inverse().ok_or(FitError::Singular(
        "the readings' covariance has no inverse",
    ))?;
    // Plain least squares first: its residual bounds the raw noise the correction may assume.
    let dof = w_sum * (n - 4) as f64 / n as f64;
    let a_plain = s_rm * s_mm_inv;
    let rss_plain = s_rr - a_plain * s_rm.transpose();
    let noise = Vector3::from(opts.raw_noise_var_ut2);
    let noise_bound = (0..3)
        .map(|j| {
            let through_a: f64 = (0..3).map(|k| a_plain[(j, k)].powi(2) * noise[k]).sum();
            if through_a > 0.0 {
                (rss_plain[(j, j)].max(0.0) / dof / through_a).min(1.0)
            } else {
                1.0
            }
        })
        .fold(1.0, f64::min);
    let correction = Matrix3::from_diagonal(&(noise * (noise_bound * w_sum)));
    let s_corr = s_mm - correction;
    let s_inv = s_corr
        .cholesky()
        .map(|c| c.inverse())
        .ok_or(FitError::Singular(
            "the readings' covariance less their noise is not positive: the noise is as large as the rotation",
        ))?;
    let a = s_rm * s_inv;
    let b = r_mean - a * m_mean;

    let a_arr: Mat3 = std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)]));
    if opts.estimates_only {
        // The residual from the sums: Σw·e·eᵀ = S_rr − A·S_rmᵀ − S_rm·Aᵀ + A·S_mm·Aᵀ (centred; the intercept fits the
        // means exactly).
        let rss_matrix =
            s_rr - a * s_rm.transpose() - s_rm * a.transpose() + a * s_mm * a.transpose();
        return Ok(VectorFit {
            a: a_arr,
            b_ut: [b[0], b[1], b[2]],
            a_se: [[0.0; 3]; 3],
            b_se_ut: [0.0; 3],
            covariance: [[[0.0; 4]; 4]; 3],
            residual_rms_ut: std::array::from_fn(|j| (rss_matrix[(j, j)].max(0.0) / w_sum).sqrt()),
            condition_number: coverage.spread_ut[0] / coverage.spread_ut[2],
            n,
            skipped: raw_ut.len() - n,
            coverage,
            noise_bound,
            direction_cells: 0,
        });
    }

    // Second pass: residuals, and their scores per cell of field direction and per block of time.
    let grid = SphereGrid::new(DIRECTION_CELLS);
    let total = raw_ut.len();
    let blocks = TIME_BLOCKS.min(total);
    let groups = grid.len() + blocks;
    let scores_of = |range: std::ops::Range<usize>| {
        let mut scores: Vec<[Vector4<f64>; 3]> = vec![[Vector4::zeros(); 3]; groups];
        let mut group_weight = vec![0.0; groups];
        let mut rss = Vector3::zeros();
        for i in range {
            let w = weight(i);
            if w == 0.0 {
                continue;
            }
            let m = Vector3::from(raw_ut[i]);
            let e = a * m + b - Vector3::from(expected_ut[i]);
            rss += e.component_mul(&e) * w;
            let x = m - m_mean;
            let xt = Vector4::new(x[0], x[1], x[2], 1.0);
            let cell = grid.cell(expected_ut[i]).unwrap_or(0);
            for group in [cell, grid.len() + i * blocks / total] {
                for j in 0..3 {
                    scores[group][j] -= xt * (w * e[j]);
                }
                group_weight[group] += w;
            }
        }
        (scores, group_weight, rss)
    };
    let (scores, group_weight, rss) = chunks::fold(total, scores_of, |mut x, y| {
        for (c, d) in x.0.iter_mut().zip(&y.0) {
            for j in 0..3 {
                c[j] += d[j];
            }
        }
        for (c, d) in x.1.iter_mut().zip(&y.1) {
            *c += d;
        }
        (x.0, x.1, x.2 + y.2)
    })
    .unwrap_or_else(|| scores_of(0..0));
    let used = |range: std::ops::Range<usize>| -> Vec<usize> {
        range.filter(|&k| group_weight[k] > 0.0).collect()
    };
    let (clusters, time_blocks) = (used(0..grid.len()), used(grid.len()..groups));

    // Bread: the corrected normal matrix in centred coordinates (the intercept decoupled).
    let mut bread_inv = Matrix4::zeros();
    bread_inv.fixed_view_mut::<3, 3>(0, 0).copy_from(&s_inv);
    bread_inv[(3, 3)] = 1.0 / w_sum;
    // From centred (a_j, b'_j) to (a_j, b_j): b_j = b'_j − a_j·mean.
    let mut to_b = Matrix4::identity();
    for k in 0..3 {
        to_b[(3, k)] = -m_mean[k];
    }
    let mut covariance = [[[0.0; 4]; 4]; 3];
    for j in 0..3 {
        let sigma2 = rss[j] / dof;
        let model_based = bread_inv * sigma2;
        let theta = Vector4::new(a[(j, 0)], a[(j, 1)], a[(j, 2)], 0.0);
        let eiv = Vector4::new(
            correction[(0, 0)],
            correction[(1, 1)],
            correction[(2, 2)],
            0.0,
        )
        .component_mul(&theta)
            / w_sum;
        // The cluster-robust sandwich over `groups` (cells of direction, or blocks of time), when it has more than one.
        let sandwich = |groups: &[usize]| {
            let g = groups.len() as f64;
            let meat: Matrix4<f64> = groups
                .iter()
                .map(|&k| {
                    let score = scores[k][j] + eiv * group_weight[k];
                    score * score.transpose()
                })
                .sum();
            let small_sample = g / (g - 1.0) * (n as f64 - 1.0) / (n as f64 - 4.0);
            (groups.len() > 1).then(|| bread_inv * meat * bread_inv * small_sample)
        };
        let mut larger = DMatrix::from_column_slice(4, 4, model_based.as_slice());
        for robust in [sandwich(&clusters), sandwich(&time_blocks)]
            .into_iter()
            .flatten()
        {
            larger = loewner_max(
                &larger,
                &DMatrix::from_column_slice(4, 4, robust.as_slice()),
            );
        }
        let c = to_b * Matrix4::from_column_slice(larger.as_slice()) * to_b.transpose();
        covariance[j] = std::array::from_fn(|r| std::array::from_fn(|s| c[(r, s)]));
    }
    Ok(VectorFit {
        a: a_arr,
        b_ut: [b[0], b[1], b[2]],
        a_se: std::array::from_fn(|j| std::array::from_fn(|k| covariance[j][k][k].sqrt())),
        b_se_ut: std::array::from_fn(|j| covariance[j][3][3].sqrt()),
        covariance,
        residual_rms_ut: std::array::from_fn(|j| (rss[j] / w_sum).sqrt()),
        condition_number: coverage.spread_ut[0] / coverage.spread_ut[2],
        n,
        skipped: raw_ut.len() - n,
        coverage,
        noise_bound,
        direction_cells: clusters.len(),
    })
}

/// A covariance at least as large as both `a` and `b` in every direction: `a^½·U·max(Λ, 1)·Uᵀ·a^½`, where `U·Λ·Uᵀ`
/// is `b` whitened by `a`. It is `a` where `b` is smaller and `b` where `b` is larger.
pub(crate) fn loewner_max(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let ea = a.clone().symmetric_eigen();
    if !ea.eigenvalues.iter().all(|l| *l > 0.0) {
        return b.clone();
    }
    let with = |f: &dyn Fn(f64) -> f64| {
        &ea.eigenvectors
            * DMatrix::from_diagonal(&ea.eigenvalues.map(f))
            * ea.eigenvectors.transpose()
    };
    let (half, inv_half) = (with(&f64::sqrt), with(&|l| 1.0 / l.sqrt()));
    let w = &inv_half * b * &inv_half;
    let ew = ((&w + w.transpose()) * 0.5).symmetric_eigen();
    let clipped = &ew.eigenvectors
        * DMatrix::from_diagonal(&ew.eigenvalues.map(|l| l.max(1.0)))
        * ew.eigenvectors.transpose();
    &half * clipped * &half
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
