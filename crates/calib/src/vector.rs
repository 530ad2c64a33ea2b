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
//! error, model errors that depend on direction) where the model-based one assumes them independent, the
//! delete-one-cell jackknife over the same cells, which sees what the sandwich misses where a few cells carry a
//! parameter (a thinly covered axis: the fit bends towards their errors, so their residuals look small), and the
//! cluster-robust covariance over [`TIME_BLOCKS`] blocks of time, which sees residuals alike for a while (something on
//! the board for part of the recording, a magnet's tail, a drift): on the physical Nexus 5 recording with 8 µT on the
//! board for 18 of its 64 referenced seconds, unlocated, A was 5.4 standard errors off by the other two. Before that
//! last one counts, the others are scaled by how much more the recording's two halves in time disagree than they
//! claim ([`split_dispersion`]; the sandwich over time sees part of the same disagreement, so it is not scaled): a
//! claim must hold on the next recording of the sensor, and structure the model does not explain over longer
//! stretches (a field that changes along the path, a reference whose error drifts) shows there.
//! On the physical BROAD 02 recording (thin coverage along x) its halves' `A` differed by 6.7 of their standard errors
//! without the jackknife and the scaling (κ = 8.3 there).

use nalgebra::{DMatrix, DVector, Matrix3, Matrix4, SMatrix, SVector, Vector3, Vector4};

use std::borrow::Cow;

use crate::FitError;
use crate::chunks;
use crate::coverage::{Coverage, SphereGrid, sphere_fraction};
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
    /// How much more the fits of the recording's two halves in time disagree than their covariances say (about 1 when
    /// they agree; 1 when not measured); the covariance is scaled by it when above 1 (see the module docs).
    pub dispersion: f64,
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
    /// Its median below three.
    const MEDIAN_OF_UNIT_IN_MODE: f64 = 1.512_9;

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

    /// The share of the sphere of directions the expected fields of the samples `kept` cover in sensor axes (the
    /// fit does not change them).
    fn covered(&self, _: &VectorFit, kept: &[bool]) -> f64 {
        sphere_fraction(
            self.expected_ut
                .iter()
                .zip(kept)
                .filter(|(e, k)| **k && e.iter().all(|v| v.is_finite()))
                .map(|(e, _)| *e),
            DIRECTION_CELLS,
        )
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

/// The samples of a fit and the weight each gets in it.
struct Samples<'a> {
    /// Raw readings in sensor axes, µT.
    raw_ut: &'a [[f64; 3]],
    /// The expected field in sensor axes, µT (NaN = missing).
    expected_ut: &'a [[f64; 3]],
    /// The caller's weight per sample, if any.
    weights: Option<&'a [f64]>,
    /// The caller's kept flag per sample, if any.
    kept: Option<&'a [bool]>,
}

impl<'a> Samples<'a> {
    /// The readings and expected fields with the weights and kept flags of `opts` (one of each per reading).
    fn new(
        raw_ut: &'a [[f64; 3]],
        expected_ut: &'a [[f64; 3]],
        opts: &VectorOptions<'a>,
    ) -> Samples<'a> {
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
        Samples {
            raw_ut,
            expected_ut,
            weights: opts.weights,
            kept: opts.kept,
        }
    }

    /// Samples, used or not.
    fn len(&self) -> usize {
        self.raw_ut.len()
    }

    /// The weight of sample `i`: zero when it is not kept, its reading or expected field has a NaN, or its weight
    /// is not positive.
    #[inline]
    fn weight(&self, i: usize) -> f64 {
        let usable = self.kept.is_none_or(|k| k[i])
            && self.expected_ut[i]
                .iter()
                .chain(&self.raw_ut[i])
                .all(|v| v.is_finite());
        let w = self.weights.map_or(1.0, |w| w[i]);
        if usable && w > 0.0 { w } else { 0.0 }
    }
}

/// The weighted means of the used samples and their weighted sums of products about those means (the centred
/// normal equations).
#[derive(Clone, Copy, Debug)]
struct Moments {
    /// Samples used (non-zero weight).
    n: usize,
    /// Sum of their weights.
    w_sum: f64,
    /// Weighted mean reading in sensor axes, µT.
    m_mean: Vector3<f64>,
    /// Weighted mean expected field in sensor axes, µT.
    r_mean: Vector3<f64>,
    /// `Σw·d·dᵀ` of the centred readings `d`, µT².
    s_mm: Matrix3<f64>,
    /// `Σw·e·dᵀ` of the centred expected fields `e` and readings `d`, µT².
    s_rm: Matrix3<f64>,
    /// `Σw·e·eᵀ` of the centred expected fields `e`, µT².
    s_rr: Matrix3<f64>,
}

/// The centred moments of the used samples, from one pass of sums shifted by the first usable sample for
/// precision; fewer than [`MIN_SAMPLES`] used is an error.
fn moments(samples: &Samples<'_>) -> Result<Moments, FitError> {
    let Some(first) = (0..samples.len()).find(|&i| samples.weight(i) > 0.0) else {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: 0,
        });
    };
    let (m0, r0) = (
        Vector3::from(samples.raw_ut[first]),
        Vector3::from(samples.expected_ut[first]),
    );
    let Sums {
        n,
        w_sum,
        sm,
        sr,
        smm,
        srm,
        srr,
    } = shifted_sums(samples, m0, r0);
    if n < MIN_SAMPLES {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: n,
        });
    }
    let (dm, dr) = (sm / w_sum, sr / w_sum);
    Ok(Moments {
        n,
        w_sum,
        m_mean: m0 + dm,
        r_mean: r0 + dr,
        s_mm: smm - dm * dm.transpose() * w_sum,
        s_rm: srm - dr * dm.transpose() * w_sum,
        s_rr: srr - dr * dr.transpose() * w_sum,
    })
}

/// The weighted sums of the used samples' readings less `m0_ut` and expected fields less `r0_ut`, and of their
/// products, in one pass on all threads.
fn shifted_sums(samples: &Samples<'_>, m0_ut: Vector3<f64>, r0_ut: Vector3<f64>) -> Sums {
    chunks::fold(
        samples.len(),
        |range| {
            let mut s = Sums::default();
            for i in range {
                let w = samples.weight(i);
                if w == 0.0 {
                    continue;
                }
                let d = Vector3::from(samples.raw_ut[i]) - m0_ut;
                let e = Vector3::from(samples.expected_ut[i]) - r0_ut;
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
    .unwrap_or_default()
}

/// The spread of the readings; unless `opts` skips the check, an error when they do not cover the directions or
/// the expected field stays still while they turn.
fn checked_coverage(moments: &Moments, opts: &VectorOptions<'_>) -> Result<Coverage, FitError> {
    let coverage = Coverage::from_covariance(&(moments.s_mm / moments.w_sum));
    if !opts.skip_coverage_check {
        coverage.check()?;
        let reference_ut = Coverage::from_covariance(&(moments.s_rr / moments.w_sum)).spread_ut[0];
        if reference_ut < crate::coverage::STILL_SPREAD_UT {
            return Err(FitError::ReferenceStill {
                reference_ut,
                readings_ut: coverage.spread_ut[0],
            });
        }
    }
    Ok(coverage)
}

/// `A` and `b` by least squares corrected for the raw noise, and what their standard errors are made of.
#[derive(Clone, Copy, Debug)]
struct Estimates {
    /// `A`.
    a: Matrix3<f64>,
    /// `b`, µT.
    b_ut: Vector3<f64>,
    /// The inverse of the corrected normal matrix `S_mm − N·σ²` (centred).
    s_inv: Matrix3<f64>,
    /// The correction `N·σ²` taken off the normal matrix (diagonal, per sensor axis), µT².
    correction: Matrix3<f64>,
    /// The factor (at most 1) the raw noise variance was scaled by ([`VectorFit::noise_bound`]).
    noise_bound: f64,
    /// The residual's degrees of freedom (in units of weight).
    dof: f64,
}

/// Solves the centred normal equations: plain least squares first, whose residual bounds the raw noise the
/// correction may assume ([`noise_bound`]), then least squares corrected for that noise (see the module docs).
fn estimates(moments: &Moments, raw_noise_var_ut2: [f64; 3]) -> Result<Estimates, FitError> {
    let Moments {
        n,
        w_sum,
        m_mean,
        r_mean,
        s_mm,
        s_rm,
        s_rr,
    } = *moments;
    let s_mm_inv = s_mm.try_inverse().ok_or(FitError::Singular(
        "the readings' covariance has no inverse",
    ))?;
    // Plain least squares first: its residual bounds the raw noise the correction may assume.
    let dof = w_sum * (n - 4) as f64 / n as f64;
    let a_plain = s_rm * s_mm_inv;
    let rss_plain = s_rr - a_plain * s_rm.transpose();
    let noise = Vector3::from(raw_noise_var_ut2);
    let noise_bound = noise_bound(&a_plain, &rss_plain, dof, &noise);
    let correction = Matrix3::from_diagonal(&(noise * (noise_bound * w_sum)));
    let s_corr = s_mm - correction;
    let s_inv = s_corr
        .cholesky()
        .map(|c| c.inverse())
        .ok_or(FitError::Singular(
            "the readings' covariance less their noise is not positive: the noise is as large as the rotation",
        ))?;
    let a = s_rm * s_inv;
    let b_ut = r_mean - a * m_mean;
    Ok(Estimates {
        a,
        b_ut,
        s_inv,
        correction,
        noise_bound,
        dof,
    })
}

/// The factor (at most 1) that scales the raw noise variance `noise_ut2` down until, on every axis, what it makes
/// through the plain fit's `a_plain` fits in that fit's residual (`rss_plain` over `dof` degrees of freedom).
fn noise_bound(
    a_plain: &Matrix3<f64>,
    rss_plain: &Matrix3<f64>,
    dof: f64,
    noise_ut2: &Vector3<f64>,
) -> f64 {
    (0..3)
        .map(|j| {
            let through_a: f64 = (0..3).map(|k| a_plain[(j, k)].powi(2) * noise_ut2[k]).sum();
            if through_a > 0.0 {
                (rss_plain[(j, j)].max(0.0) / dof / through_a).min(1.0)
            } else {
                1.0
            }
        })
        .fold(1.0, f64::min)
}

/// A matrix as rows.
fn rows(a: &Matrix3<f64>) -> Mat3 {
    std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)]))
}

/// The fit of a reweighting pass ([`VectorOptions::estimates_only`]): the residual from the sums, no standard errors
/// (zero), no cells of direction; `total` samples, used or not.
fn estimates_only_fit(
    moments: &Moments,
    est: &Estimates,
    coverage: Coverage,
    total: usize,
) -> VectorFit {
    let Moments {
        n,
        w_sum,
        s_mm,
        s_rm,
        s_rr,
        ..
    } = *moments;
    let (a, b) = (est.a, est.b_ut);
    // The residual from the sums: Σw·e·eᵀ = S_rr − A·S_rmᵀ − S_rm·Aᵀ + A·S_mm·Aᵀ (centred; the intercept fits the
    // means exactly).
    let rss_matrix = s_rr - a * s_rm.transpose() - s_rm * a.transpose() + a * s_mm * a.transpose();
    VectorFit {
        a: rows(&a),
        b_ut: [b[0], b[1], b[2]],
        a_se: [[0.0; 3]; 3],
        b_se_ut: [0.0; 3],
        covariance: [[[0.0; 4]; 4]; 3],
        residual_rms_ut: std::array::from_fn(|j| (rss_matrix[(j, j)].max(0.0) / w_sum).sqrt()),
        condition_number: coverage.spread_ut[0] / coverage.spread_ut[2],
        n,
        skipped: total - n,
        coverage,
        noise_bound: est.noise_bound,
        direction_cells: 0,
        dispersion: 1.0,
    }
}

/// The second pass's sums per group — the cells of field direction, then the blocks of time — and over all samples.
#[derive(Clone, Debug)]
struct Scores {
    /// Per group and calibrated axis `j`, the score `−Σw·e_j·(d, 1)` (`e` the residual, `d` the centred reading).
    scores: Vec<[Vector4<f64>; 3]>,
    /// Per group, the sum of its samples' weights.
    group_weight: Vec<f64>,
    /// Per group, its share of the (uncorrected) normal matrix `Σw·(d, 1)·(d, 1)ᵀ`, for the delete-one-group
    /// jackknife.
    normal: Vec<Matrix4<f64>>,
    /// `Σw·e²` per calibrated axis, µT².
    rss_ut2: Vector3<f64>,
    /// Groups that are cells of direction (the first ones).
    cells: usize,
}

impl Scores {
    /// Empty sums over `cells` cells of direction and `blocks` blocks of time.
    fn zeros(cells: usize, blocks: usize) -> Scores {
        Scores {
            scores: vec![[Vector4::zeros(); 3]; cells + blocks],
            group_weight: vec![0.0; cells + blocks],
            normal: vec![Matrix4::zeros(); cells + blocks],
            rss_ut2: Vector3::zeros(),
            cells,
        }
    }

    /// The sums of two runs of samples, `self`'s first.
    fn merge(mut self, o: Scores) -> Scores {
        for (c, d) in self.scores.iter_mut().zip(&o.scores) {
            for j in 0..3 {
                c[j] += d[j];
            }
        }
        for (c, d) in self.group_weight.iter_mut().zip(&o.group_weight) {
            *c += d;
        }
        for (c, d) in self.normal.iter_mut().zip(&o.normal) {
            *c += d;
        }
        self.rss_ut2 += o.rss_ut2;
        self
    }

    /// The groups in `range` that hold samples.
    fn used(&self, range: std::ops::Range<usize>) -> Vec<usize> {
        range.filter(|&k| self.group_weight[k] > 0.0).collect()
    }

    /// The cells of direction that hold samples (the clusters of the robust standard errors).
    fn used_cells(&self) -> Vec<usize> {
        self.used(0..self.cells)
    }

    /// The blocks of time that hold samples.
    fn used_blocks(&self) -> Vec<usize> {
        self.used(self.cells..self.group_weight.len())
    }
}

/// The second pass, on all threads: the residuals under `est`, and their scores per cell of field direction and per
/// block of time ([`TIME_BLOCKS`]); `m_mean_ut` is the mean reading the scores are centred on.
fn residual_scores(samples: &Samples<'_>, est: &Estimates, m_mean_ut: Vector3<f64>) -> Scores {
    let (a, b) = (est.a, est.b_ut);
    let grid = SphereGrid::new(DIRECTION_CELLS);
    let total = samples.len();
    let blocks = TIME_BLOCKS.min(total);
    let scores_of = |range: std::ops::Range<usize>| {
        let mut s = Scores::zeros(grid.len(), blocks);
        for i in range {
            let w = samples.weight(i);
            if w == 0.0 {
                continue;
            }
            let m = Vector3::from(samples.raw_ut[i]);
            let e = a * m + b - Vector3::from(samples.expected_ut[i]);
            s.rss_ut2 += e.component_mul(&e) * w;
            let x = m - m_mean_ut;
            let xt = Vector4::new(x[0], x[1], x[2], 1.0);
            let outer = xt * xt.transpose() * w;
            let cell = grid.cell(samples.expected_ut[i]).unwrap_or(0);
            for group in [cell, grid.len() + i * blocks / total] {
                for j in 0..3 {
                    s.scores[group][j] -= xt * (w * e[j]);
                }
                s.group_weight[group] += w;
                s.normal[group] += outer;
            }
        }
        s
    };
    chunks::fold(total, scores_of, Scores::merge).unwrap_or_else(|| scores_of(0..0))
}

/// Per calibrated axis `j`, the covariance of `(a_j1, a_j2, a_j3, b_j)`: the largest, in every direction, of the
/// model-based one and the cluster-robust ones over the cells of direction and the blocks of time (`groups`), scaled
/// by the halves' `dispersion` when above 1 (see the module docs).
fn covariances(
    moments: &Moments,
    est: &Estimates,
    scores: &Scores,
    groups: [&[usize]; 2],
    dispersion: f64,
) -> [[[f64; 4]; 4]; 3] {
    // Bread: the corrected normal matrix in centred coordinates (the intercept decoupled).
    let mut bread_inv = Matrix4::zeros();
    bread_inv.fixed_view_mut::<3, 3>(0, 0).copy_from(&est.s_inv);
    bread_inv[(3, 3)] = 1.0 / moments.w_sum;
    // From centred (a_j, b'_j) to (a_j, b_j): b_j = b'_j − a_j·mean.
    let mut to_b = Matrix4::identity();
    for k in 0..3 {
        to_b[(3, k)] = -moments.m_mean[k];
    }
    let mut covariance = [[[0.0; 4]; 4]; 3];
    for j in 0..3 {
        let centred = axis_covariance(j, moments, est, scores, bread_inv, groups, dispersion);
        let c = to_b * centred * to_b.transpose();
        covariance[j] = std::array::from_fn(|r| std::array::from_fn(|s| c[(r, s)]));
    }
    covariance
}

/// The noise correction `N·σ²` per unit weight, as a 4×4 matrix of the centred problem (none on the intercept): what
/// a group of samples takes of it by its weight, from the normal matrix and (at the solution) from its score.
fn correction_per_weight(moments: &Moments, est: &Estimates) -> Matrix4<f64> {
    let mut per_weight = Matrix4::zeros();
    per_weight
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(est.correction / moments.w_sum));
    per_weight
}

/// Row `j` of `A` with a zero intercept: the part of the centred solution the noise correction acts on.
fn row(est: &Estimates, j: usize) -> Vector4<f64> {
    Vector4::new(est.a[(j, 0)], est.a[(j, 1)], est.a[(j, 2)], 0.0)
}

/// Axis `j`'s covariance in centred coordinates: the model-based one from `bread_inv` (the inverse of the corrected
/// normal matrix), enlarged to the cluster-robust sandwich and the delete-one-cell jackknife over the cells of
/// direction, scaled by the halves' `dispersion` when above 1, then enlarged to the sandwich over the blocks of time
/// (`groups`: the cells, the blocks).
fn axis_covariance(
    j: usize,
    moments: &Moments,
    est: &Estimates,
    scores: &Scores,
    bread_inv: Matrix4<f64>,
    groups: [&[usize]; 2],
    dispersion: f64,
) -> Matrix4<f64> {
    let sigma2 = scores.rss_ut2[j] / est.dof;
    let model_based = bread_inv * sigma2;
    let correction_per_weight = correction_per_weight(moments, est);
    let eiv = correction_per_weight * row(est, j);
    let mut larger = DMatrix::from_column_slice(4, 4, model_based.as_slice());
    let [cells, blocks] = groups;
    for robust in [
        sandwich(j, scores, eiv, cells, bread_inv, moments.n),
        jackknife(j, scores, (eiv, correction_per_weight), cells, bread_inv),
    ]
    .into_iter()
    .flatten()
    {
        larger = loewner_max(
            &larger,
            &DMatrix::from_column_slice(4, 4, robust.as_slice()),
        );
    }
    // The halves' disagreement scales what does not look along time; the sandwich over blocks of time sees some of
    // the same disagreement already, so it is not scaled again.
    larger *= dispersion.max(1.0);
    if let Some(over_time) = sandwich(j, scores, eiv, blocks, bread_inv, moments.n) {
        larger = loewner_max(
            &larger,
            &DMatrix::from_column_slice(4, 4, over_time.as_slice()),
        );
    }
    Matrix4::from_column_slice(larger.as_slice())
}

/// How much more the fits of the recording's two halves in time (each block of time's sums left in one or the other)
/// disagree than their own covariances say: `κ = Σ_j d_jᵀ·(V₁ⱼ + V₂ⱼ)⁻¹·d_j / 12`, `d_j` the difference of the
/// halves' row `j` (`θ_h = θ + M_h⁻¹·s_h` exactly, `M_h` and `s_h` the half's corrected normal matrix and score),
/// `V_hj` the larger of the half's model-based covariance and its sandwich over its blocks. A claim must hold on the
/// next recording of the sensor: where structure the model does not explain (a field that changes along the path, a
/// reference whose error drifts) makes a fit depend on which stretch of the path it saw, the halves disagree by more
/// than they claim, and the whole fit's covariance is scaled by `κ` when above 1. 1 when a half cannot determine the
/// fit.
fn split_dispersion(
    moments: &Moments,
    est: &Estimates,
    scores: &Scores,
    time_blocks: &[usize],
) -> f64 {
    if time_blocks.len() < 8 {
        return 1.0;
    }
    let per_weight = correction_per_weight(moments, est);
    let (first, second) = time_blocks.split_at(time_blocks.len() / 2);
    // Each half's corrected normal matrix, the same for the three axes.
    let inverse_of = |blocks: &[usize]| -> Option<Matrix4<f64>> {
        let weight: f64 = blocks.iter().map(|&k| scores.group_weight[k]).sum();
        let matrix = blocks
            .iter()
            .map(|&k| scores.normal[k])
            .sum::<Matrix4<f64>>()
            - per_weight * weight;
        Some(matrix.cholesky()?.inverse())
    };
    let (Some(inverse_1), Some(inverse_2)) = (inverse_of(first), inverse_of(second)) else {
        return 1.0;
    };
    let mut statistic = 0.0;
    for j in 0..3 {
        let eiv = per_weight * row(est, j);
        let sigma2 = scores.rss_ut2[j] / est.dof;
        let half = |blocks: &[usize], inverse: Matrix4<f64>| {
            let block_scores: Vec<Vector4<f64>> = blocks
                .iter()
                .map(|&k| scores.scores[k][j] + eiv * scores.group_weight[k])
                .collect();
            let score: Vector4<f64> = block_scores.iter().sum();
            HalfFit::new(inverse, sigma2, inverse * score, &block_scores)
        };
        let Some(axis) = half(first, inverse_1).disagreement(&half(second, inverse_2)) else {
            return 1.0;
        };
        statistic += axis;
    }
    statistic / 12.0
}

/// One half of a recording in time, fitted on its own: how far its solution is from the whole recording's, and its
/// covariance — the larger of the model-based `H⁻¹·σ²` and the sandwich over its blocks' scores about their mean.
/// The vector fit's (per calibrated axis) and the scalar fit's halves' disagreement are both made of these.
pub(crate) struct HalfFit {
    shift: DVector<f64>,
    covariance: DMatrix<f64>,
}

impl HalfFit {
    /// From the half's inverse information `inverse`, the residual variance `sigma2`, its `shift` from the whole
    /// fit and its blocks' scores.
    pub(crate) fn new<const N: usize>(
        inverse: SMatrix<f64, N, N>,
        sigma2: f64,
        shift: SVector<f64, N>,
        block_scores: &[SVector<f64, N>],
    ) -> HalfFit {
        let g = block_scores.len() as f64;
        let mean = block_scores.iter().sum::<SVector<f64, N>>() / g;
        let meat = block_scores
            .iter()
            .map(|s| (s - mean) * (s - mean).transpose())
            .sum::<SMatrix<f64, N, N>>()
            * (g / (g - 1.0));
        HalfFit {
            shift: DVector::from_column_slice(shift.as_slice()),
            covariance: loewner_max(
                &DMatrix::from_column_slice(N, N, (inverse * sigma2).as_slice()),
                &DMatrix::from_column_slice(N, N, (inverse * meat * inverse).as_slice()),
            ),
        }
    }

    /// `dᵀ·(V₁ + V₂)⁻¹·d` of two halves, `d` the difference of their solutions (χ² with as many degrees of freedom as
    /// parameters when the covariances hold); `None` when `V₁ + V₂` has no inverse.
    pub(crate) fn disagreement(&self, other: &HalfFit) -> Option<f64> {
        let d = &self.shift - &other.shift;
        let v = (&self.covariance + &other.covariance).cholesky()?;
        Some(d.dot(&v.solve(&d)))
    }
}

/// The cluster-robust sandwich covariance of axis `j` over `groups` (cells of direction, or blocks of time), each
/// group's score with the noise correction's share `eiv` per unit weight, when there is more than one group; `n`
/// samples used.
fn sandwich(
    j: usize,
    scores: &Scores,
    eiv: Vector4<f64>,
    groups: &[usize],
    bread_inv: Matrix4<f64>,
    n: usize,
) -> Option<Matrix4<f64>> {
    let g = groups.len() as f64;
    let meat: Matrix4<f64> = groups
        .iter()
        .map(|&k| {
            let score = scores.scores[k][j] + eiv * scores.group_weight[k];
            score * score.transpose()
        })
        .sum();
    let small_sample = g / (g - 1.0) * (n as f64 - 1.0) / (n as f64 - 4.0);
    (groups.len() > 1).then(|| bread_inv * meat * bread_inv * small_sample)
}

/// The delete-one-group jackknife covariance of axis `j` over `groups`: `(G−1)/G·Σ(δ_g − δ̄)(δ_g − δ̄)ᵀ`, `δ_g` the
/// change of the solution when group `g` is left out, `−(M − M_g)⁻¹·s_g` exactly (`M` the corrected normal matrix,
/// `bread_inv` its inverse; `M_g` and the score `s_g` the group's shares, each group taking the noise correction's
/// share `eiv` of the score and `correction_per_weight` of the matrix by its weight). Where a few groups carry a
/// parameter (a thinly covered axis), the fit bends towards their errors and their residuals look small to the
/// sandwich; leaving each out sees how far the solution moves. A group without which the problem has no solution is
/// passed over. `None` with fewer than two groups left.
fn jackknife(
    j: usize,
    scores: &Scores,
    (eiv, correction_per_weight): (Vector4<f64>, Matrix4<f64>),
    groups: &[usize],
    bread_inv: Matrix4<f64>,
) -> Option<Matrix4<f64>> {
    let normal = bread_inv.try_inverse()?;
    let shifts: Vec<Vector4<f64>> = groups
        .iter()
        .filter_map(|&k| {
            let w = scores.group_weight[k];
            let share = scores.normal[k] - correction_per_weight * w;
            let rest = (normal - share).cholesky()?;
            Some(-rest.solve(&(scores.scores[k][j] + eiv * w)))
        })
        .collect();
    let g = shifts.len();
    (g > 1).then(|| {
        let mean = shifts.iter().sum::<Vector4<f64>>() / g as f64;
        shifts
            .iter()
            .map(|d| (d - mean) * (d - mean).transpose())
            .sum::<Matrix4<f64>>()
            * ((g as f64 - 1.0) / g as f64)
    })
}

/// Fits `A` and `b` to raw readings and the expected field in sensor axes (both µT). Samples whose expected field
/// or reading has a NaN are skipped and counted.
pub fn fit(
    raw_ut: &[[f64; 3]],
    expected_ut: &[[f64; 3]],
    opts: &VectorOptions<'_>,
) -> Result<VectorFit, FitError> {
    let samples = Samples::new(raw_ut, expected_ut, opts);
    let moments = moments(&samples)?;
    let coverage = checked_coverage(&moments, opts)?;
    let est = estimates(&moments, opts.raw_noise_var_ut2)?;
    if opts.estimates_only {
        return Ok(estimates_only_fit(&moments, &est, coverage, raw_ut.len()));
    }
    let scores = residual_scores(&samples, &est, moments.m_mean);
    let (clusters, time_blocks) = (scores.used_cells(), scores.used_blocks());
    let dispersion = split_dispersion(&moments, &est, &scores, &time_blocks);
    let covariance = covariances(
        &moments,
        &est,
        &scores,
        [&clusters, &time_blocks],
        dispersion,
    );
    let (n, b) = (moments.n, est.b_ut);
    Ok(VectorFit {
        a: rows(&est.a),
        b_ut: [b[0], b[1], b[2]],
        a_se: std::array::from_fn(|j| std::array::from_fn(|k| covariance[j][k][k].sqrt())),
        b_se_ut: std::array::from_fn(|j| covariance[j][3][3].sqrt()),
        covariance,
        residual_rms_ut: std::array::from_fn(|j| (scores.rss_ut2[j] / moments.w_sum).sqrt()),
        condition_number: coverage.spread_ut[0] / coverage.spread_ut[2],
        n,
        skipped: raw_ut.len() - n,
        coverage,
        noise_bound: est.noise_bound,
        direction_cells: clusters.len(),
        dispersion,
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

    /// A recording of a sensor turned through every direction, whose offset moves by `step_ut` along x halfway
    /// through: raw readings and expected fields, 0.3 µT of noise.
    fn stepped(step_ut: f64, seed: u64) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 0.3).unwrap();
        let n = 4000;
        let expected: Vec<[f64; 3]> = (0..n)
            .map(|_| frames::scale(UnitSphere.sample(&mut rng), 50.0))
            .collect();
        let raw = expected
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let offset = if i < n / 2 { 0.0 } else { step_ut };
                [
                    r[0] + offset + noise.sample(&mut rng),
                    r[1] + noise.sample(&mut rng),
                    r[2] + noise.sample(&mut rng),
                ]
            })
            .collect();
        (raw, expected)
    }

    #[test]
    fn halves_that_disagree_widen_the_claims_and_halves_that_agree_do_not() {
        // Clean: the halves agree as their covariances say (κ about 1, χ² of 12 over 12).
        let (raw, expected) = stepped(0.0, 5);
        let clean = fit(&raw, &expected, &VectorOptions::default()).unwrap();
        assert!(clean.dispersion < 2.5, "κ {}", clean.dispersion);
        // An offset that moves by 2 µT halfway: the whole fit's offset is the mean, 1 µT from either half's; without the
        // halves its standard error was the sandwich over blocks of time's 0.18 µT, now 0.31 µT.
        let (raw, expected) = stepped(2.0, 5);
        let moved = fit(&raw, &expected, &VectorOptions::default()).unwrap();
        assert!(moved.dispersion > 100.0, "κ {}", moved.dispersion);
        assert!(
            moved.b_se_ut[0] > 0.25 && moved.b_se_ut[0] > 10.0 * clean.b_se_ut[0],
            "{} against {}",
            moved.b_se_ut[0],
            clean.b_se_ut[0]
        );
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
