//! The classic scalar calibration: find `A` (symmetric) and the centre `c` so that `|A·(B̂ − c)|` equals the field
//! magnitude at every sample (`b = −A·c`).
//!
//! - **No trivial solution.** The unknowns are the centre and `A`, not `A` and `b`: with `b` free, `A = 0` and
//!   `|b| = F` fit any magnitude exactly, and partial recordings collapse onto it. With the centre, `A → 0` needs the
//!   centre at infinity, which no data favour.
//! - **Only what the coverage supports.** A cap of directions cannot tell an ellipsoid's centre from its shape. The
//!   shape (how `A` departs from a multiple of the identity) carries a prior — axes' gains equal within
//!   [`SHAPE_PRIOR_GAIN`], cross terms within [`SHAPE_PRIOR_CROSS`], what real magnetometers and their soft iron show —
//!   and the overall scale and the centre are free. On a full sphere the data outweigh the prior by orders of
//!   magnitude (the fit is the plain one); on a cap the prior fills in what the data cannot say, and the reported
//!   uncertainty of the centre includes it. This is MotionCal's fallback from a 10- to a 4-element model, made
//!   continuous.
//! - **Samples weighted by the directions they add.** Samples are counted per equal-area cell of direction and a
//!   cell holding more than twice the median cell's count is weighted down to it, so a still start or a slow stretch
//!   does not outweigh the rotation (MotionCal and ArduPilot thin by such cells).
//! - **Honest uncertainties.** The largest, direction by direction, of the model-based covariance, the
//!   cluster-robust one over the same cells, which sees residuals that depend on direction (model errors) or are
//!   alike within an orientation, and the cluster-robust one over blocks of time, which sees residuals alike for a
//!   while (the tail of a magnet the sensor passed, a slow drift).
//!
//! The fit itself is Levenberg–Marquardt on the magnitude residual `|A·(B̂ − c)| − F`, started from a linear sphere
//! fit. Only the magnitude is constrained, so a rotation of the calibrated field is invisible: see
//! [`ROTATION_NOTE`].

use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, SVector, SymmetricEigen, Vector3, Vector4};

use std::borrow::Cow;

use crate::FitError;
use crate::chunks;
use crate::coverage::{Coverage, SphereGrid, capped_cell_weights, describe, sphere_fraction};
use crate::frames::{self, Mat3};
use crate::model::Model;
use crate::robust::{self, RobustProblem, quantile};
use crate::vector::{HalfFit, TIME_BLOCKS};

/// What the scalar method cannot see, in words for reports.
pub const ROTATION_NOTE: &str = "the scalar method constrains only |B|, and a rotation of the calibrated field leaves \
|B| unchanged: it cannot observe the sensor's misalignment, so A is the symmetric matrix that maps the readings onto a \
sphere and the components are only as well aligned as the sensor is mounted";

/// Prior standard deviation of an axis's gain about the mean gain (relative): gains of one chip's axes differ by a
/// few per cent, and by up to ~20 % on some (the HMC5883L's Z).
pub const SHAPE_PRIOR_GAIN: f64 = 0.1;
/// Prior standard deviation of a cross term of `A` (relative to the mean gain): soft iron and non-orthogonality.
pub const SHAPE_PRIOR_CROSS: f64 = 0.05;
/// The centre's standard error above which the fit is refused, as a fraction of the field magnitude: the recording
/// does not say where the centre is (at 5 %, a heading error of up to ~10° where the horizontal field is half the
/// total).
pub const REFUSE_CENTRE_SE: f64 = 0.05;
/// The noise correction is a second-order one: it may move the centre by at most this fraction of the raw radius and
/// `A` by this fraction of its mean gain. A larger move means the recording does not pin the fit down against its
/// own noise, and the fit is refused.
const MAX_CORRECTION: f64 = 0.05;
/// Gauss–Newton steps of the noise correction (it converges in a handful where the fit is determined).
const MAX_CORRECTION_STEPS: usize = 30;
/// The centre's standard error above which the fit is only accepted with a warning, fraction of the field.
pub const WARN_CENTRE_SE: f64 = 0.02;
/// A magnitude residual above this fraction of the field after the best ellipsoid: the readings are not on one.
const NOT_AN_ELLIPSOID: f64 = 0.2;
/// Parameters: the centre (x, y, z) and the six entries of the symmetric `A` (xx, yy, zz, xy, xz, yz).
const P: usize = 9;
const MAX_ITERATIONS: usize = 100;
/// A solver step this small, in standard errors of the parameters, is not taken.
const NEGLIGIBLE_STEP_SE: f64 = 0.01;
/// Rounds of settling the prior's weight on the residual variance.
const MAX_ROUNDS: usize = 8;
/// Cells of direction for the weights and the cluster-robust standard errors.
const DIRECTION_CELLS: usize = 100;
/// The bulk seed's fences, in interquartile ranges beyond the quartiles (Tukey's far out).
const BULK_FENCE: f64 = 3.0;
/// Fewest samples the fit takes.
pub const MIN_SAMPLES: usize = 12;

/// Index pairs of the symmetric matrix's parameters, after the three of the centre.
pub const SYM: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

/// Options of the scalar fit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScalarOptions<'a> {
    /// The field magnitude, µT. Without it, the calibrated sphere keeps the volume of the raw ellipsoid.
    pub field_ut: Option<f64>,
    /// Skip the coverage check.
    pub skip_coverage_check: bool,
    /// A weight per sample in `[0, 1]` (zero leaves a sample out), for robust refits; all ones when absent.
    pub weights: Option<&'a [f64]>,
    /// Variance of the raw readings' noise per sensor axis, µT², for the noise correction of the score (see the
    /// module docs); zero for the plain magnitude least squares.
    pub raw_noise_var_ut2: [f64; 3],
    /// Estimates only, quickly: no noise correction, no uncertainties (zero), no refusal of an undetermined centre
    /// (for the seeds of a robust fit).
    pub quick: bool,
    /// A fit of nearly the same readings for the solver to start from (fewer passes over them); without it, the
    /// solver starts from the sphere through them.
    pub start: Option<&'a ScalarFit>,
    /// Windows of the readings with a centre of their own (something fixed to the sensor for a while), their
    /// readings moved back by their shifts before the fit; the shifts' uncertainty is in the covariance.
    pub second_centres: &'a [SecondCentre],
}

/// A window of the readings `[start, end)` with a centre of its own: something fixed to the sensor (a magnet on the
/// board) moved every raw reading in it by `shift_ut`; the shape is the same.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SecondCentre {
    /// The first reading in the window and one past the last.
    pub range: (usize, usize),
    /// What it added to the raw readings, µT.
    pub shift_ut: [f64; 3],
}

/// The result of a scalar fit.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalarFit {
    /// `A`, symmetric, row-major.
    pub a: Mat3,
    /// `b = −A·c`, µT.
    pub b_ut: [f64; 3],
    /// Standard error of each entry of `A`.
    pub a_se: Mat3,
    /// Standard error of each entry of `b`, µT.
    pub b_se_ut: [f64; 3],
    /// The centre `c` (the raw reading that calibrates to zero), µT.
    pub centre_ut: [f64; 3],
    /// Covariance of the centre, µT².
    pub centre_cov_ut2: Mat3,
    /// The magnitude the fit aimed at, µT.
    pub field_ut: f64,
    /// Whether that magnitude was given (otherwise it is the raw ellipsoid's mean radius).
    pub field_given: bool,
    /// Weighted RMS of `|A·(B̂ − c)| − F`, µT.
    pub residual_rms_ut: f64,
    /// Levenberg–Marquardt iterations.
    pub iterations: usize,
    /// Samples used (non-zero weight).
    pub n: usize,
    /// Spread of the readings.
    pub coverage: Coverage,
    /// Cells of direction the samples fell in.
    pub direction_cells: usize,
    /// How much of what is known of the shape comes from the prior rather than the data: 0 on a full sphere, near 1
    /// on a small cap.
    pub shape_prior_share: f64,
    /// The direction (sensor axes) along which the centre is least certain, and the centre's standard error there
    /// (raw units, µT) as the coverage determines it (before the halves' disagreement scales the claims).
    pub weakest: ([f64; 3], f64),
    /// How much more the fits of the recording's two halves in time disagree than their covariances say, as the
    /// vector fit's ([`crate::vector::VectorFit::dispersion`]); the claims are scaled by it when above 1.
    pub dispersion: f64,
}

impl ScalarFit {
    /// The magnitude residual `|A·m + b| − F` (µT) of a raw reading `m` under the fit.
    fn misfit(&self) -> impl Fn([f64; 3]) -> f64 + Sync + '_ {
        let a = Matrix3::from_fn(|j, k| self.a[j][k]);
        let b = Vector3::from(self.b_ut);
        move |m| (a * Vector3::from(m) + b).norm() - self.field_ut
    }

    /// The fitted linear model.
    pub fn model(&self) -> Model {
        Model::linear(self.a, self.b_ut)
    }

    /// The raw ellipsoid's semi-axes, largest first, µT: the field magnitude over the eigenvalues of `A`.
    pub fn radii_ut(&self) -> [f64; 3] {
        let a = Matrix3::from_fn(|j, k| self.a[j][k]);
        let mut r: Vec<f64> = SymmetricEigen::new(a)
            .eigenvalues
            .iter()
            .map(|l| self.field_ut / l)
            .collect();
        r.sort_by(|x, y| y.total_cmp(x));
        [r[0], r[1], r[2]]
    }

    /// The ellipsoid's centre in raw units, `−A⁻¹·b` (the hard-iron offset as most tools quote it), µT.
    pub fn centre_ut(&self) -> [f64; 3] {
        self.centre_ut
    }

    /// A warning when the centre is uncertain along some direction (the coverage is partial), with what to do.
    pub fn warning(&self) -> Option<String> {
        let (d, se_raw) = self.weakest;
        let se = se_raw * (self.a[0][0] + self.a[1][1] + self.a[2][2]) / 3.0;
        (se > WARN_CENTRE_SE * self.field_ut).then(|| {
            format!(
                "the offset is uncertain along {}: ±{:.2} µT ({:.0} % of the field), because the recording covers \
                 only part of the directions{}; {}",
                describe(d),
                se,
                100.0 * se / self.field_ut,
                if self.shape_prior_share > 0.5 {
                    " and the ellipsoid's shape was assumed near-spherical"
                } else {
                    ""
                },
                rotate_advice(d)
            )
        })
    }
}

/// The scalar method as a robust problem (see [`crate::robust`]): readings, the magnitude, the raw noise.
#[derive(Clone, Debug)]
pub struct ScalarProblem<'a> {
    /// Raw readings, µT.
    pub raw_ut: Cow<'a, [[f64; 3]]>,
    /// The field magnitude, µT, if known.
    pub field_ut: Option<f64>,
    /// Variance of the raw noise per axis, µT².
    pub raw_noise_var_ut2: [f64; 3],
}

impl RobustProblem for ScalarProblem<'_> {
    type Fit = ScalarFit;
    /// The median of |N(0, 1)|.
    const MEDIAN_OF_UNIT: f64 = 0.674_49;
    /// Its median below three.
    const MEDIAN_OF_UNIT_IN_MODE: f64 = 0.672_4;
    /// A magnet passing at constant speed, its field falling off as the distance cubed, takes about twice as long to
    /// fall from 3 to 1 scales as from 6 to 3: its tail is left out down to about the noise. Measured on the
    /// disturbed study: 189 → 191 of 200 seeds within their bounds, every disturbance still located, no false alarm
    /// on the nulls. (The vector method keeps none: there the same tail cost 8 seeds, each with standard errors
    /// that no longer covered an error within the bound.)
    const RAMP_TAIL: f64 = 2.0;

    fn len(&self) -> usize {
        self.raw_ut.len()
    }

    fn every(&self, stride: usize) -> Self {
        ScalarProblem {
            raw_ut: self.raw_ut.iter().step_by(stride).copied().collect(),
            ..self.clone()
        }
    }

    fn quick_fit(&self, weights: &[f64], start: Option<&ScalarFit>) -> Result<ScalarFit, FitError> {
        self.fit_with(weights, true, start)
    }

    fn final_fit(&self, kept: &[bool], start: Option<&ScalarFit>) -> Result<ScalarFit, FitError> {
        self.fit_with(&robust::weights_of(kept), false, start)
    }

    fn residuals(&self, fit: &ScalarFit) -> Vec<f64> {
        let r = fit.misfit();
        let raw = &self.raw_ut;
        chunks::map(raw.len(), |i| r(raw[i]).abs())
    }

    fn model(fit: &ScalarFit) -> Model {
        fit.model()
    }

    /// A field fixed in the room adds about a constant to the magnitude whatever the attitude, one fixed to the
    /// sensor `d·u` along the field's direction `u`: the windows where the magnitude's residual moves so, against the
    /// sensor's noise in |B| (none without a noise figure).
    fn shifted(&self, fit: &ScalarFit, kept: &[bool]) -> Vec<(usize, usize)> {
        let a = Matrix3::from_fn(|j, k| fit.a[j][k]);
        let b = Vector3::from(fit.b_ut);
        let var = Vector3::from(self.raw_noise_var_ut2);
        let raw = &self.raw_ut;
        let r = fit.misfit();
        let rho = chunks::map(raw.len(), |i| r(raw[i]));
        let u = chunks::map(raw.len(), |i| {
            (a * Vector3::from(raw[i]) + b)
                .try_normalize(0.0)
                .map_or([0.0; 3], Into::into)
        });
        // The noise of |B|: the raw noise seen along the field direction, averaged over (at most ~10 000) readings.
        let stride = (raw.len() / 10_000).max(1);
        let (sum, count) = raw
            .iter()
            .step_by(stride)
            .filter_map(|m| {
                let u = (a * Vector3::from(*m) + b).try_normalize(0.0)?;
                Some(
                    (a.transpose() * u)
                        .component_mul(&(a.transpose() * u))
                        .dot(&var),
                )
            })
            .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
        let noise = (sum / count.max(1) as f64).sqrt();
        // A window in a state of its own: a second centre fitted with the rest.
        let own_state = |window: (usize, usize)| {
            let (joint, centres) = self.joint(fit, kept, &[window], true)?;
            let e = self.residuals_shifted(&joint, &centres);
            Some(robust::variance_with_wander(|| {
                e.iter()
                    .zip(kept)
                    .filter(|(x, k)| **k && x.is_finite())
                    .map(|(x, _)| *x)
            }))
        };
        if noise > 0.0 {
            robust::shifted_windows(&rho, &u, kept, noise, Some(&own_state))
        } else {
            Vec::new()
        }
    }

    /// The readings whose distance from their median point lies within Tukey's far fences (three interquartile
    /// ranges beyond the quartiles): a field many times the Earth's on the board or beside it for a while, which
    /// captures every seed of a span that holds it, lies far beyond them, and the undisturbed readings, at the
    /// ellipsoid's radius from its centre, within.
    fn bulk_weights(&self) -> Option<Vec<f64>> {
        let median_point: [f64; 3] = std::array::from_fn(|k| {
            let axis: Vec<f64> = self.raw_ut.iter().map(|m| m[k]).collect();
            quantile(&axis, 0.5)
        });
        let distance = |m: &[f64; 3]| frames::norm(frames::sub(*m, median_point));
        let r: Vec<f64> = self.raw_ut.iter().map(distance).collect();
        let (q1, q3) = (quantile(&r, 0.25), quantile(&r, 0.75));
        if !(q1.is_finite() && q3.is_finite()) {
            return None;
        }
        let (low, high) = (q1 - BULK_FENCE * (q3 - q1), q3 + BULK_FENCE * (q3 - q1));
        Some(
            self.raw_ut
                .iter()
                .map(|m| f64::from(u8::from((low..=high).contains(&distance(m)))))
                .collect(),
        )
    }

    fn covered(&self, fit: &ScalarFit, kept: &[bool]) -> f64 {
        self.directions_covered(fit, |i| kept[i])
    }

    /// The share of the sphere of directions the readings cover as seen from a fit's centre: from a wrong centre
    /// (a huge sphere through a band of the readings and a still stretch, as a seed on a cap of the recording can
    /// make) they lie in a cap.
    fn support(&self, fit: &ScalarFit) -> f64 {
        self.directions_covered(fit, |_| true)
    }

    /// Each window a second centre ([`ScalarProblem::joint`]).
    fn with_windows(
        &self,
        without: &ScalarFit,
        kept: &[bool],
        windows: &[(usize, usize)],
    ) -> Option<robust::OwnStates<ScalarFit>> {
        let (fit, centres) = self.joint(without, kept, windows, false)?;
        let mut residual_ut = self.residuals_shifted(&fit, &centres);
        residual_ut.iter_mut().for_each(|x| *x = x.abs());
        Some(robust::OwnStates {
            fit,
            residual_ut,
            windows: centres.iter().map(|c| c.range).collect(),
        })
    }
}

impl ScalarProblem<'_> {
    /// The samples `kept` with each of `windows` a second centre ([`SecondCentre`]), fitted with the rest, from the
    /// fit `without` them: the shape, the centre and the shifts at once ([`ScalarProblem::solve_joint`]), then each
    /// window's bounds where the two states explain the readings best ([`ScalarProblem::relocated`]), until the
    /// bounds settle; then the solver's own fit with the windows' readings moved back by their shifts (a quick one
    /// when `quick`).
    fn joint(
        &self,
        without: &ScalarFit,
        kept: &[bool],
        windows: &[(usize, usize)],
        quick: bool,
    ) -> Option<(ScalarFit, Vec<SecondCentre>)> {
        let mut windows = windows.to_vec();
        windows.sort_unstable();
        // The readings a window may hold: the kept ones, and those left out that the windows held to begin with.
        let mut candidate = kept.to_vec();
        for &(a, b) in &windows {
            candidate[a..b].fill(true);
        }
        let fitted = |centres: &[SecondCentre]| {
            let mut fitted = kept.to_vec();
            for w in centres {
                fitted[w.range.0..w.range.1].copy_from_slice(&candidate[w.range.0..w.range.1]);
            }
            fitted
        };
        let mut centres = windows
            .iter()
            .map(|&range| {
                window_shift(&self.raw_ut, &candidate, range, without)
                    .map(|shift_ut| SecondCentre { range, shift_ut })
            })
            .collect::<Option<Vec<_>>>()?;
        let mut joint = without.clone();
        for _ in 0..RELOCATIONS {
            joint = self.solve_joint(&joint, &fitted(&centres), &mut centres);
            let relocated = self.relocated(&joint, &candidate, &centres);
            if relocated
                .iter()
                .zip(&centres)
                .all(|(x, y)| x.range == y.range)
            {
                break;
            }
            centres = relocated;
        }
        // A window's readings that its own state leaves grossly off (something else passing while the magnet sat on
        // the board) are left out, as the base fit leaves out the rest's.
        let mut fitted = fitted(&centres);
        let e = self.residuals_shifted(&joint, &centres);
        let scale = robust::scale::<Self>(
            &e.iter()
                .zip(kept)
                .filter(|(x, k)| **k && x.is_finite())
                .map(|(x, _)| x.abs())
                .collect::<Vec<_>>(),
        );
        let mut trimmed = false;
        for w in &centres {
            for i in w.range.0..w.range.1 {
                let gross = e[i].is_nan() || e[i].abs() > robust::GROSS_SIGMA * scale;
                if fitted[i] && gross {
                    fitted[i] = false;
                    trimmed = true;
                }
            }
        }
        if trimmed {
            joint = self.solve_joint(&joint, &fitted, &mut centres);
        }
        if centres
            .iter()
            .any(|w| self.room_explains(&joint, &fitted, w))
        {
            return None;
        }
        let joint = self
            .fit_shifted(&robust::weights_of(&fitted), quick, Some(&joint), &centres)
            .ok()?;
        Some((joint, centres))
    }

    /// Levenberg–Marquardt on the shape, the centre and every second centre's shift at once (least squares of the
    /// magnitude on the `kept` readings, the magnitude of `start`, with the solver's shape prior), from `start` and
    /// the shifts in `centres`, which it updates: the shifts and the centre pull on each other, which fitting them
    /// in turn follows only slowly. Returns `start` with the shape and centre found.
    fn solve_joint(
        &self,
        start: &ScalarFit,
        kept: &[bool],
        centres: &mut [SecondCentre],
    ) -> ScalarFit {
        let q = P + 3 * centres.len();
        let n = self.raw_ut.len();
        let mut window = vec![0usize; n];
        for (k, w) in centres.iter().enumerate() {
            window[w.range.0..w.range.1].fill(k + 1);
        }
        let field = start.field_ut;
        let sums = |p: &DVector<f64>| {
            let (c, a) = unpack(&SVector::from_iterator(p.rows(0, P).iter().copied()));
            let chunk = |range: std::ops::Range<usize>| {
                let (mut h, mut g, mut rss) = (DMatrix::zeros(q, q), DVector::zeros(q), 0.0);
                let mut jq = DVector::zeros(q);
                for i in range.filter(|&i| kept[i]) {
                    let m = Vector3::from(self.raw_ut[i]);
                    if !m.iter().all(|v| v.is_finite()) {
                        continue;
                    }
                    let w = window[i];
                    let centre = match w {
                        0 => c,
                        k => c + Vector3::from(p.fixed_rows::<3>(P + 3 * (k - 1)).into_owned()),
                    };
                    let (r, j, _) = residual(&m, &a, &centre, field);
                    jq.fill(0.0);
                    jq.rows_mut(0, P).copy_from_slice(&j);
                    if w > 0 {
                        jq.rows_mut(P + 3 * (w - 1), 3).copy_from_slice(&j[..3]);
                    }
                    h.ger(1.0, &jq, &jq, 1.0);
                    g.axpy(r, &jq, 1.0);
                    rss += r * r;
                }
                (h, g, rss)
            };
            chunks::fold(n, chunk, |x, y| (x.0 + y.0, x.1 + y.1, x.2 + y.2))
                .unwrap_or_else(|| chunk(0..0))
        };
        let mut p = DVector::zeros(q);
        p.rows_mut(0, 3).copy_from_slice(&start.centre_ut);
        for (idx, (r, s)) in SYM.iter().enumerate() {
            p[3 + idx] = start.a[*r][*s];
        }
        for (k, w) in centres.iter().enumerate() {
            p.rows_mut(P + 3 * k, 3).copy_from_slice(&w.shift_ut);
        }
        // The solver's shape prior ([`shape_precision`]), weighted by the residual variance at the start.
        let (h0, g0, rss0) = sums(&p);
        let used = kept.iter().filter(|k| **k).count().max(1) as f64;
        let gain = (start.a[0][0] + start.a[1][1] + start.a[2][2]) / 3.0;
        let mut prior = DMatrix::zeros(q, q);
        prior
            .view_mut((0, 0), (P, P))
            .copy_from(&(shape_precision(gain) * (rss0 / used)));
        let with_prior = |(h, g, rss): (DMatrix<f64>, DVector<f64>, f64), p: &DVector<f64>| {
            let qp = &prior * p;
            (h + &prior, g + &qp, rss + p.dot(&qp))
        };
        let (mut h, mut g, mut rss) = with_prior((h0, g0, rss0), &p);
        let mut lambda = 1e-3;
        for _ in 0..JOINT_ITERATIONS {
            let mut damped = h.clone();
            for k in 0..q {
                damped[(k, k)] += lambda * h[(k, k)].max(1e-300);
            }
            let Some(step) = damped.cholesky().map(|ch| ch.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let trial = &p + &step;
            let (th, tg, trss) = with_prior(sums(&trial), &trial);
            if trss.is_finite() && trss <= rss {
                let done = rss - trss <= 1e-12 * rss;
                (p, h, g, rss) = (trial, th, tg, trss);
                lambda = (lambda / 10.0).max(1e-12);
                if done {
                    break;
                }
            } else {
                lambda *= 10.0;
                if lambda > 1e12 {
                    break;
                }
            }
        }
        for (k, w) in centres.iter_mut().enumerate() {
            w.shift_ut = [p[P + 3 * k], p[P + 3 * k + 1], p[P + 3 * k + 2]];
        }
        let mut out = start.clone();
        let (c, a) = unpack(&SVector::from_iterator(p.rows(0, P).iter().copied()));
        out.centre_ut = c.into();
        out.a = std::array::from_fn(|r| std::array::from_fn(|s| a[(r, s)]));
        out.b_ut = (-(a * c)).into();
        out
    }

    /// Whether a field fixed in the room explains the `kept` readings of the window `w` at least as well as its
    /// second centre: under `fit`, their magnitude a constant of its own (a room's field adds about a constant to
    /// |B| whatever the attitude, a board's moves the centre).
    fn room_explains(&self, fit: &ScalarFit, kept: &[bool], w: &SecondCentre) -> bool {
        let r = fit.misfit();
        let inside: Vec<[f64; 3]> = (w.range.0..w.range.1)
            .filter(|&i| kept[i] && self.raw_ut[i].iter().all(|v| v.is_finite()))
            .map(|i| self.raw_ut[i])
            .collect();
        let n = inside.len().max(1) as f64;
        let mean = inside.iter().map(|m| r(*m)).sum::<f64>() / n;
        let room = inside.iter().map(|m| (r(*m) - mean).powi(2)).sum::<f64>();
        let centre = inside
            .iter()
            .map(|m| r(frames::sub(*m, w.shift_ut)).powi(2))
            .sum::<f64>();
        room <= centre
    }

    /// Each second centre's window moved to where its state explains the `candidate` readings better than the
    /// sensor's own under `fit` by the most (the largest sum of the two squared residuals' difference over a run of
    /// readings, between its neighbours), or left where it is if nowhere.
    fn relocated(
        &self,
        fit: &ScalarFit,
        candidate: &[bool],
        centres: &[SecondCentre],
    ) -> Vec<SecondCentre> {
        let r = fit.misfit();
        let n = self.raw_ut.len();
        (0..centres.len())
            .map(|w| {
                let lo = w.checked_sub(1).map_or(0, |p| centres[p].range.1);
                let hi = centres.get(w + 1).map_or(n, |next| next.range.0);
                let shift = centres[w].shift_ut;
                let gain = (lo..hi).map(|i| {
                    let m = self.raw_ut[i];
                    let g = r(m).powi(2) - r(frames::sub(m, shift)).powi(2);
                    if candidate[i] && g.is_finite() {
                        g
                    } else {
                        0.0
                    }
                });
                let range = best_run(gain).map_or(centres[w].range, |(s, e)| (lo + s, lo + e));
                SecondCentre {
                    range,
                    ..centres[w]
                }
            })
            .collect()
    }
}

/// The run `[start, end)` of `x` with the largest positive sum (Kadane), `None` if no sum is positive.
fn best_run(x: impl Iterator<Item = f64>) -> Option<(usize, usize)> {
    let (mut best, mut best_sum) = (None, 0.0);
    let (mut start, mut sum) = (0, 0.0);
    for (i, v) in x.enumerate() {
        if sum <= 0.0 {
            (start, sum) = (i, 0.0);
        }
        sum += v;
        if sum > best_sum {
            (best, best_sum) = (Some((start, i + 1)), sum);
        }
    }
    best
}

/// At most this many times [`ScalarProblem::joint`] moves the windows' bounds…
const RELOCATIONS: usize = 5;
/// …and this many steps [`ScalarProblem::solve_joint`] takes.
const JOINT_ITERATIONS: usize = 50;

/// Iterations of [`window_shift`]'s Gauss–Newton.
const SHIFT_ITERATIONS: usize = 30;

/// The shift `d` of the raw readings `[a, b)` that are `kept` which `fit` explains best: Gauss–Newton on
/// `|A·(m − c − d)| − F` over `d`, from none, each step halved until it lowers the sum of squares. `None` if the
/// readings do not determine it.
fn window_shift(
    raw_ut: &[[f64; 3]],
    kept: &[bool],
    (a, b): (usize, usize),
    fit: &ScalarFit,
) -> Option<[f64; 3]> {
    let am = Matrix3::from_fn(|j, k| fit.a[j][k]);
    let c = Vector3::from(fit.centre_ut);
    let readings: Vec<Vector3<f64>> = (a..b)
        .filter(|&i| kept[i] && raw_ut[i].iter().all(|v| v.is_finite()))
        .map(|i| Vector3::from(raw_ut[i]))
        .collect();
    if readings.len() < MIN_SAMPLES {
        return None;
    }
    let sums = |d: &Vector3<f64>| {
        let centre = c + d;
        readings.iter().fold(
            (Matrix3::zeros(), Vector3::zeros(), 0.0),
            |(h, g, rss), m| {
                let (r, j, _) = residual(m, &am, &centre, fit.field_ut);
                let jc = Vector3::new(j[0], j[1], j[2]);
                (h + jc * jc.transpose(), g + jc * r, rss + r * r)
            },
        )
    };
    let mut d = Vector3::zeros();
    let (mut h, mut g, mut rss) = sums(&d);
    for _ in 0..SHIFT_ITERATIONS {
        let mut step = -(h.cholesky()?.solve(&g));
        let mut better = None;
        for _ in 0..20 {
            let at = sums(&(d + step));
            if at.2 <= rss {
                better = Some(at);
                break;
            }
            step *= 0.5;
        }
        let Some(at) = better else {
            break;
        };
        d += step;
        let done = rss - at.2 <= 1e-12 * rss;
        (h, g, rss) = at;
        if done {
            break;
        }
    }
    Some(d.into())
}

impl ScalarProblem<'_> {
    /// The share of the sphere of directions the finite readings `keep` selects cover, calibrated by `fit`.
    fn directions_covered(&self, fit: &ScalarFit, keep: impl Fn(usize) -> bool) -> f64 {
        let a = Matrix3::from_fn(|j, k| fit.a[j][k]);
        let b = Vector3::from(fit.b_ut);
        sphere_fraction(
            self.raw_ut
                .iter()
                .enumerate()
                .filter(|(i, m)| keep(*i) && m.iter().all(|v| v.is_finite()))
                .map(|(_, m)| (a * Vector3::from(*m) + b).into()),
            DIRECTION_CELLS,
        )
    }

    fn fit_with(
        &self,
        weights: &[f64],
        quick: bool,
        start: Option<&ScalarFit>,
    ) -> Result<ScalarFit, FitError> {
        self.fit_shifted(weights, quick, start, &[])
    }

    /// [`Self::fit_with`] with windows of their own centres.
    fn fit_shifted(
        &self,
        weights: &[f64],
        quick: bool,
        start: Option<&ScalarFit>,
        second_centres: &[SecondCentre],
    ) -> Result<ScalarFit, FitError> {
        fit(
            &self.raw_ut,
            &ScalarOptions {
                field_ut: self.field_ut,
                skip_coverage_check: quick,
                weights: Some(weights),
                raw_noise_var_ut2: self.raw_noise_var_ut2,
                quick,
                start,
                second_centres,
            },
        )
    }

    /// Each reading's residual under `fit` (signed), those in the `second_centres` moved back by their shifts.
    fn residuals_shifted(&self, fit: &ScalarFit, second_centres: &[SecondCentre]) -> Vec<f64> {
        let r = fit.misfit();
        let raw = &self.raw_ut;
        chunks::map(raw.len(), |i| {
            let shift = second_centres
                .iter()
                .find(|w| (w.range.0..w.range.1).contains(&i))
                .map_or([0.0; 3], |w| w.shift_ut);
            r(frames::sub(raw[i], shift))
        })
    }
}

/// `−A⁻¹·b`: the raw reading that calibrates to zero.
pub fn centre(a: &Mat3, b_ut: [f64; 3]) -> [f64; 3] {
    let a = Matrix3::from_fn(|j, k| a[j][k]);
    let c = -(a.try_inverse().unwrap_or_else(Matrix3::zeros) * Vector3::from(b_ut));
    [c[0], c[1], c[2]]
}

/// How to turn the sensor so that a direction gets observed.
fn rotate_advice(d: [f64; 3]) -> String {
    let axis = describe(d).replace("sensor axis ≈ ", "");
    format!(
        "turn the sensor so that {axis} points both along and against the field (and the other axes too: every \
         face up and every face down), or use the cube24 routine"
    )
}

/// One accumulation over the samples: `JᵀWJ`, `JᵀWr` (less the noise's share when corrected), `Σwr²` at
/// parameters `p`, and in a full fit the same sums by group for the covariance.
struct Pass {
    jtj: SMatrix<f64, P, P>,
    jtr: SVector<f64, P>,
    rss: f64,
    groups: Option<Groups>,
}

/// The sums [`Problem::covariance`] needs, made in the same pass: per cell of direction the score (`JᵀWr` less the
/// noise's share) and the upper triangle of the information `JᵀWJ`, per block of time (after the cells) the score
/// and the information; and per axis `Σw·(A·u)ₖ²`, which says how much of the raw noise reaches the magnitude
/// ([`Problem::bounded_noise`]).
struct Groups {
    scores: Vec<[f64; P]>,
    info: Vec<[f64; TRIANGLE]>,
    block_info: Vec<[f64; TRIANGLE]>,
    radial: [f64; 3],
}

/// The parameters' covariance ([`Problem::covariance`]).
struct Covariance {
    /// What the fit claims: scaled by the halves' disagreement.
    claimed: SMatrix<f64, P, P>,
    /// What the coverage determines: not scaled (the refusals' covariance).
    determined: SMatrix<f64, P, P>,
    /// How much the prior informs the shape.
    prior_share: f64,
    /// The halves' disagreement the claims were scaled by (when above 1).
    dispersion: f64,
}

/// Where one reading sits under the parameters: `d = m − c`, the direction `u` of `A·d` and `1/|A·d|`.
struct Local {
    d: Vector3<f64>,
    u: Vector3<f64>,
    inv_len: f64,
}

/// The magnitude residual of one reading, its gradient in the parameters, and where the reading sits.
#[inline]
fn residual(
    m: &Vector3<f64>,
    a: &Matrix3<f64>,
    c: &Vector3<f64>,
    field_ut: f64,
) -> (f64, [f64; P], Local) {
    let d = m - c;
    let v = a * d;
    let norm = v.norm();
    let inv_len = 1.0 / norm;
    let u = v * inv_len;
    let au = a * u;
    let mut j = [0.0; P];
    for k in 0..3 {
        j[k] = -au[k];
    }
    for (idx, (r, s)) in SYM.iter().enumerate() {
        j[3 + idx] = if r == s {
            u[*r] * d[*s]
        } else {
            u[*r] * d[*s] + u[*s] * d[*r]
        };
    }
    (norm - field_ut, j, Local { d, u, inv_len })
}

/// What the raw noise (variances `s2` per axis) adds on average to `r·∇r` of one reading, to second order: the
/// magnitude's bias `½·tr(∇²f·Σ)` times the gradient, plus the covariance of the reading's noise in `r` and in `∇r`.
/// `a2` is `A·A`, made once per pass; `at` and `grad` are the reading's place and gradient from [`residual`].
#[inline]
fn noise_score(
    at: &Local,
    a: &Matrix3<f64>,
    a2: &Matrix3<f64>,
    s2: &Vector3<f64>,
    grad: &[f64; P],
) -> [f64; P] {
    let Local { d, u, inv_len } = at;
    // `A·u`, the gradient in the centre with its sign turned.
    let w = Vector3::new(-grad[0], -grad[1], -grad[2]);
    // With P = I − u·uᵀ and A symmetric: K = A·P·A/|v| = (A² − w·wᵀ)/|v|, and P·A·x = A·x − u·(w·x).
    let bias = 0.5
        * (0..3)
            .map(|i| (a2[(i, i)] - w[i] * w[i]) * s2[i])
            .sum::<f64>()
        * inv_len;
    let sw = s2.component_mul(&w);
    let w_sw = w.dot(&sw);
    let kw = (a2 * sw - w * w_sw) * *inv_len;
    let z = (a * sw - u * w_sw) * *inv_len;
    let mut out = [0.0; P];
    for i in 0..3 {
        out[i] = bias * grad[i] - kw[i];
    }
    for (idx, (r, q)) in SYM.iter().enumerate() {
        let (r, q) = (*r, *q);
        let cov = if r == q {
            u[r] * sw[r] + d[r] * z[r]
        } else {
            u[r] * sw[q] + u[q] * sw[r] + d[r] * z[q] + d[q] * z[r]
        };
        out[3 + idx] = bias * grad[3 + idx] + cov;
    }
    out
}

fn unpack(p: &SVector<f64, P>) -> (Vector3<f64>, Matrix3<f64>) {
    let mut a = Matrix3::zeros();
    for (idx, (r, s)) in SYM.iter().enumerate() {
        a[(*r, *s)] = p[3 + idx];
        a[(*s, *r)] = p[3 + idx];
    }
    (p.fixed_rows::<3>(0).into_owned(), a)
}

/// The entries of the upper triangle of a `P`×`P` matrix, row by row.
const TRIANGLE: usize = P * (P + 1) / 2;

/// One accumulation at `p`: `JᵀWJ`, `JᵀWr` (less the noise's share with `noise`) and `Σwr²`.
fn pass(
    raw: &[[f64; 3]],
    w: &[f64],
    p: &SVector<f64, P>,
    field_ut: f64,
    noise: Option<&Vector3<f64>>,
) -> Pass {
    let (c, a) = unpack(p);
    let chunk = |range: std::ops::Range<usize>| {
        let (raw, w) = (&raw[range.clone()], &w[range]);
        match noise {
            None => accumulate::<false>(raw, w, &a, &c, field_ut, &Vector3::zeros()),
            Some(s2) => accumulate::<true>(raw, w, &a, &c, field_ut, s2),
        }
    };
    let (jtj, jtr, rss) = chunks::fold(raw.len(), chunk, |x, y| {
        (
            std::array::from_fn(|e| x.0[e] + y.0[e]),
            std::array::from_fn(|i| x.1[i] + y.1[i]),
            x.2 + y.2,
        )
    })
    .unwrap_or_else(|| chunk(0..0));
    Pass {
        jtj: mirror(&jtj),
        jtr: SVector::<f64, P>::from(jtr),
        rss,
        groups: None,
    }
}

/// The sums of one chunk: the upper triangle of `JᵀWJ` row by row, `JᵀWr` less the noise's share (with `NOISE`,
/// of variances `s2`) and `Σwr²`, in plain arrays.
fn accumulate<const NOISE: bool>(
    raw: &[[f64; 3]],
    w: &[f64],
    a: &Matrix3<f64>,
    c: &Vector3<f64>,
    field_ut: f64,
    s2: &Vector3<f64>,
) -> ([f64; TRIANGLE], [f64; P], f64) {
    let (mut jtj, mut jtr, mut rss) = ([0.0; TRIANGLE], [0.0; P], 0.0);
    let a2 = a * a;
    for (m, &wi) in raw.iter().zip(w) {
        if wi == 0.0 {
            continue;
        }
        let m = Vector3::from(*m);
        let (r, j, local) = residual(&m, a, c, field_ut);
        let wj = j.map(|v| wi * v);
        if NOISE {
            let k = noise_score(&local, a, &a2, s2, &j);
            (0..P).for_each(|x| jtr[x] += wj[x] * r - wi * k[x]);
        } else {
            (0..P).for_each(|x| jtr[x] += wj[x] * r);
        }
        add_upper(&mut jtj, &wj, &j);
        rss += wi * r * r;
    }
    (jtj, jtr, rss)
}

/// Adds `wj·jᵀ` to an upper triangle summed row by row.
#[inline]
fn add_upper(upper: &mut [f64; TRIANGLE], wj: &[f64; P], j: &[f64; P]) {
    let mut e = 0;
    for x in 0..P {
        for y in x..P {
            upper[e] += wj[x] * j[y];
            e += 1;
        }
    }
}

/// The symmetric matrix of an upper triangle summed row by row.
fn mirror(upper: &[f64; TRIANGLE]) -> SMatrix<f64, P, P> {
    let mut full = SMatrix::<f64, P, P>::zeros();
    let mut e = 0;
    for x in 0..P {
        for y in x..P {
            full[(x, y)] = upper[e];
            full[(y, x)] = upper[e];
            e += 1;
        }
    }
    full
}

/// The shape prior's precision (per unit of `A`'s mean gain²): free centre and overall scale, each gain's departure
/// from the mean gain and each cross term penalised.
fn shape_precision(gain: f64) -> SMatrix<f64, P, P> {
    let mut q = SMatrix::<f64, P, P>::zeros();
    let (d, o) = (
        1.0 / (SHAPE_PRIOR_GAIN * gain).powi(2),
        1.0 / (SHAPE_PRIOR_CROSS * gain).powi(2),
    );
    for r in 0..3 {
        for s in 0..3 {
            q[(3 + r, 3 + s)] = d * (if r == s { 1.0 } else { 0.0 } - 1.0 / 3.0);
        }
        q[(6 + r, 6 + r)] = o;
    }
    q
}

/// A weighted linear sphere fit: `|m|² = 2·c·m + k`, centred for conditioning. Returns the centre and radius.
fn sphere(raw: &[[f64; 3]], w: &[f64]) -> Option<(Vector3<f64>, f64)> {
    let sum = |range: std::ops::Range<usize>| {
        raw[range.clone()]
            .iter()
            .zip(&w[range])
            .fold((Vector3::zeros(), 0.0), |(s, n), (m, wi)| {
                (s + Vector3::from(*m) * *wi, n + wi)
            })
    };
    let (sum, w_sum) =
        chunks::fold(raw.len(), sum, |x, y| (x.0 + y.0, x.1 + y.1)).unwrap_or_else(|| sum(0..0));
    let mean = sum / w_sum;
    let products = |range: std::ops::Range<usize>| {
        let (mut xtx, mut xty) = (nalgebra::Matrix4::<f64>::zeros(), Vector4::<f64>::zeros());
        for (m, &wi) in raw[range.clone()].iter().zip(&w[range]) {
            let d = Vector3::from(*m) - mean;
            let x = Vector4::new(2.0 * d.x, 2.0 * d.y, 2.0 * d.z, 1.0);
            xtx += x * x.transpose() * wi;
            xty += x * (d.norm_squared() * wi);
        }
        (xtx, xty)
    };
    let (xtx, xty) = chunks::fold(raw.len(), products, |x, y| (x.0 + y.0, x.1 + y.1))
        .unwrap_or_else(|| products(0..0));
    let sol = xtx.cholesky()?.solve(&xty);
    let c = Vector3::new(sol[0], sol[1], sol[2]);
    let r2 = sol[3] + c.norm_squared();
    (r2 > 0.0 && r2.is_finite()).then(|| (c + mean, r2.sqrt()))
}

/// Each reading's cell of direction about `centre`, the weights that keep any cell from outweighing the rotation
/// ([`capped_cell_weights`]), and the number of occupied cells.
fn direction_weights(
    raw: &[[f64; 3]],
    base: &[f64],
    centre: &Vector3<f64>,
    grid: &SphereGrid,
) -> (Vec<f64>, Vec<usize>, usize) {
    let cell: Vec<usize> = chunks::map(raw.len(), |i| {
        let d = Vector3::from(raw[i]) - centre;
        grid.cell([d.x, d.y, d.z]).unwrap_or(0)
    });
    let w = capped_cell_weights(&cell, base, grid.len());
    let occupied = |r: std::ops::Range<usize>| {
        let mut occupied = vec![false; grid.len()];
        for (c, wi) in cell[r.clone()].iter().zip(&base[r]) {
            occupied[*c] |= *wi > 0.0;
        }
        occupied
    };
    let occupied = chunks::fold(cell.len(), occupied, |mut x, y| {
        x.iter_mut().zip(&y).for_each(|(x, y)| *x |= y);
        x
    })
    .unwrap_or_default();
    let cells = occupied.iter().filter(|o| **o).count();
    (w, cell, cells)
}

/// The problem as the solver sees it: the usable readings, their weights and cells, the magnitude aimed at and the
/// shape prior.
struct Problem<'a> {
    /// The usable readings: the caller's own when every reading is usable.
    raw: Cow<'a, [[f64; 3]]>,
    /// Weights, the direction weights included.
    w: Vec<f64>,
    w_sum: f64,
    /// The cell of direction of each reading, and how many cells hold readings.
    cell: Vec<usize>,
    cells: usize,
    grid: SphereGrid,
    /// The magnitude aimed at, µT (the given one, or the raw sphere's radius).
    target: f64,
    /// The shape prior's precision per unit of residual variance.
    q: SMatrix<f64, P, P>,
    /// Degrees of freedom of the residual.
    dof: f64,
    /// Whether every pass also sums by group ([`Groups`]): a full fit's, whose covariance comes from its last pass.
    grouped: bool,
    /// The second centre each reading lies in ([`Usable::window`]) and how many there are.
    window: Vec<u8>,
    windows: usize,
}

/// A solution and the accumulation at it.
struct Solution {
    p: SVector<f64, P>,
    at: Pass,
    /// The residual variance per sample that weighs the prior.
    sigma2: f64,
    iterations: usize,
}

impl<'a> Problem<'a> {
    /// The problem of the usable `readings`, their cells of direction taken about the sphere's centre `c0_ut`: it
    /// aims at the magnitude `target` (µT) with the shape prior for the mean gain `gain`, and sums by group when
    /// `grouped` (a full fit).
    fn new(
        readings: Usable<'a>,
        c0_ut: &Vector3<f64>,
        target: f64,
        gain: f64,
        grouped: bool,
    ) -> Problem<'a> {
        let Usable {
            raw,
            base,
            n,
            window,
        } = readings;
        let windows = window.iter().copied().max().map_or(0, usize::from);
        let grid = SphereGrid::new(DIRECTION_CELLS);
        let (w, cell, cells) = direction_weights(&raw, &base, c0_ut, &grid);
        let w_sum =
            chunks::fold(w.len(), |r| w[r].iter().sum::<f64>(), |x, y| x + y).unwrap_or_default();
        Problem {
            raw,
            w,
            w_sum,
            cell,
            cells,
            grid,
            target,
            q: shape_precision(gain),
            dof: w_sum * n.saturating_sub(P + 3 * windows).max(1) as f64 / n as f64,
            grouped,
            window,
            windows,
        }
    }
}

impl Problem<'_> {
    fn pass(&self, p: &SVector<f64, P>, noise: Option<&Vector3<f64>>) -> Pass {
        if self.grouped {
            self.grouped_pass(p, noise)
        } else {
            pass(&self.raw, &self.w, p, self.target, noise)
        }
    }

    /// A pass that also sums by cell of direction and by block of time ([`Groups`]).
    fn grouped_pass(&self, p: &SVector<f64, P>, noise: Option<&Vector3<f64>>) -> Pass {
        let (c, a) = unpack(p);
        let a2 = a * a;
        let n = self.raw.len();
        let ncell = self.grid.len();
        let blocks = TIME_BLOCKS.min(n.max(1));
        let chunk = |range: std::ops::Range<usize>| {
            let mut g = Groups {
                scores: vec![[0.0; P]; ncell + blocks],
                info: vec![[0.0; TRIANGLE]; ncell],
                block_info: vec![[0.0; TRIANGLE]; blocks],
                radial: [0.0; 3],
            };
            let mut rss = 0.0;
            for k in range {
                let (m, wk) = (Vector3::from(self.raw[k]), self.w[k]);
                if wk == 0.0 {
                    continue;
                }
                let (r, j, local) = residual(&m, &a, &c, self.target);
                let mut s = [0.0; P];
                match noise {
                    None => (0..P).for_each(|x| s[x] = wk * (j[x] * r)),
                    Some(s2) => {
                        let n = noise_score(&local, &a, &a2, s2, &j);
                        (0..P).for_each(|x| s[x] = wk * (j[x] * r - n[x]));
                    }
                }
                let block = k * blocks / n;
                for group in [self.cell[k], ncell + block] {
                    g.scores[group]
                        .iter_mut()
                        .zip(&s)
                        .for_each(|(a, b)| *a += b);
                }
                let wj = j.map(|v| wk * v);
                add_upper(&mut g.info[self.cell[k]], &wj, &j);
                add_upper(&mut g.block_info[block], &wj, &j);
                // The gradient in the centre is −A·u.
                (0..3).for_each(|x| g.radial[x] += wk * j[x] * j[x]);
                rss += wk * r * r;
            }
            (g, rss)
        };
        let (g, rss) = chunks::fold(n, chunk, |mut x, y| {
            for (a, b) in x.0.scores.iter_mut().zip(&y.0.scores) {
                a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
            }
            for (a, b) in x.0.info.iter_mut().zip(&y.0.info) {
                a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
            }
            for (a, b) in x.0.block_info.iter_mut().zip(&y.0.block_info) {
                a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
            }
            (0..3).for_each(|k| x.0.radial[k] += y.0.radial[k]);
            x.1 += y.1;
            x
        })
        .unwrap_or_else(|| chunk(0..0));
        Pass {
            jtj: g.info.iter().map(mirror).sum(),
            jtr: g.scores[..ncell].iter().copied().map(SVector::from).sum(),
            rss,
            groups: Some(g),
        }
    }

    /// The objective: the weighted sum of squares plus the prior weighted by `sigma2`.
    fn objective(&self, rss: f64, p: &SVector<f64, P>, sigma2: f64) -> f64 {
        rss + sigma2 * (p.transpose() * self.q * p)[(0, 0)]
    }

    /// Levenberg–Marquardt on the magnitude residual plus the prior weighted by `sigma2`, from `p` (where the
    /// accumulation is `at`). Stops when a step's predicted decrease is at the rounding level of the sum of `n`
    /// squares (`√n·ε` of it): such a step cannot be told from rounding by evaluating it, so it is not evaluated.
    fn minimise(
        &self,
        mut p: SVector<f64, P>,
        mut at: Pass,
        sigma2: f64,
        iterations: &mut usize,
    ) -> (SVector<f64, P>, Pass) {
        let q = &self.q;
        let rounding = f64::EPSILON * (self.raw.len() as f64).sqrt();
        let mut phi = self.objective(at.rss, &p, sigma2);
        let mut lambda = 1e-3;
        while *iterations < MAX_ITERATIONS {
            let h = at.jtj + q * sigma2;
            let g = at.jtr + q * p * sigma2;
            let mut damped = h;
            for k in 0..P {
                damped[(k, k)] += lambda * h[(k, k)].max(1e-300);
            }
            let Some(step) = damped.cholesky().map(|ch| ch.solve(&(-g))) else {
                *iterations += 1;
                lambda *= 10.0;
                if lambda > 1e12 {
                    break;
                }
                continue;
            };
            // What the quadratic model promises: a decrease at the rounding level of the sum means we are there; so
            // does a hardly damped step of at most [`NEGLIGIBLE_STEP_SE`] standard errors (a step of k of them
            // promises ½·k²·σ²): it would not move the estimates.
            let predicted = -(g.dot(&step)) - 0.5 * (step.transpose() * h * step)[(0, 0)];
            let negligible =
                lambda <= 1e-3 && predicted.abs() <= 0.5 * NEGLIGIBLE_STEP_SE.powi(2) * sigma2;
            if predicted.abs() <= rounding * phi || negligible {
                break;
            }
            *iterations += 1;
            let trial = p + step;
            let t = self.pass(&trial, None);
            let t_phi = self.objective(t.rss, &trial, sigma2);
            if t_phi.is_finite() && t_phi <= phi {
                let decrease = phi - t_phi;
                (p, at, phi) = (trial, t, t_phi);
                lambda = (lambda / 10.0).max(1e-12);
                if decrease <= 1e-10 * phi {
                    break;
                }
            } else {
                lambda *= 10.0;
                if lambda > 1e12 || predicted.abs() <= 1e-12 * phi {
                    break;
                }
            }
        }
        (p, at)
    }

    /// The fit with the prior weighted by the residual variance: start from the sphere's residual and refit until
    /// the fit's own residual variance settles.
    fn settle(&self, p0: SVector<f64, P>, rounds: usize) -> Solution {
        let mut iterations = 0;
        let mut p = p0;
        let mut at = self.pass(&p, None);
        let mut sigma2 = (at.rss / self.dof).max(f64::MIN_POSITIVE);
        for _ in 0..rounds {
            (p, at) = self.minimise(p, at, sigma2, &mut iterations);
            let settled = (at.rss / self.dof).max(f64::MIN_POSITIVE);
            let change = (settled / sigma2 - 1.0).abs();
            sigma2 = settled;
            if change < 0.05 {
                break;
            }
        }
        Solution {
            p,
            at,
            sigma2,
            iterations,
        }
    }

    /// The raw noise variance the residual can hold: `raw_var` scaled down (never up) so that the radial noise it
    /// makes through `A` is at most the residual variance (from the groups of `sol`'s pass).
    fn bounded_noise(&self, sol: &Solution, raw_var: Vector3<f64>) -> Vector3<f64> {
        let g = sol.at.groups.as_ref().expect("a full fit's pass");
        let radial = (0..3).map(|k| g.radial[k] * raw_var[k]).sum::<f64>() / self.w_sum;
        if radial > 0.0 {
            raw_var * (sol.sigma2 / radial).min(1.0)
        } else {
            raw_var
        }
    }

    /// Gauss–Newton on the score less the noise's share of it, from `sol`. Returns whether it converged.
    fn correct(&self, sol: &mut Solution, noise: &Vector3<f64>) -> bool {
        let q = &self.q;
        let mut converged = false;
        for _ in 0..MAX_CORRECTION_STEPS {
            sol.iterations += 1;
            sol.at = self.pass(&sol.p, Some(noise));
            let h = sol.at.jtj + q * sol.sigma2;
            let g = sol.at.jtr + q * sol.p * sol.sigma2;
            let Some(step) = h.cholesky().map(|ch| ch.solve(&(-g))) else {
                break;
            };
            sol.p += step;
            // Done when the step is a negligible fraction of the parameters' uncertainty ([`NEGLIGIBLE_STEP_SE`]:
            // Gauss–Newton's next step would be far smaller still), or of the parameters.
            let tiny = step
                .iter()
                .zip(sol.p.iter())
                .all(|(d, x)| d.abs() <= 1e-12 * (x.abs() + 1.0));
            if tiny
                || (step.transpose() * h * step)[(0, 0)] <= NEGLIGIBLE_STEP_SE.powi(2) * sol.sigma2
            {
                converged = true;
                break;
            }
        }
        // The last pass stands for the covariance: the step after it moved the estimates by a negligible fraction
        // of their uncertainty.
        converged
    }

    /// The parameters' covariance from the groups of `sol`'s last pass: the largest, in every direction, of the
    /// model-based one, the delete-one-cell jackknife over the cells of direction (each cell's score through the
    /// information without that cell) and the sandwich over [`TIME_BLOCKS`] blocks of time; for the claims, the first
    /// two scaled by how much more the recording's two halves disagree than they claim
    /// ([`Problem::split_dispersion`]) before the sandwich over time counts.
    fn covariance(&self, sol: &Solution) -> Option<Covariance> {
        let at = &sol.at;
        let g = at.groups.as_ref().expect("a full fit's pass");
        let scores: Vec<SVector<f64, P>> = g.scores.iter().copied().map(SVector::from).collect();
        let info: Vec<SMatrix<f64, P, P>> = g.info.iter().map(mirror).collect();
        let ncell = self.grid.len();
        let blocks = scores.len() - ncell;
        let h = at.jtj + self.q * sol.sigma2;
        let h_inv = h.try_inverse()?;
        let model_based = h_inv * sol.sigma2;
        let used = |groups: std::ops::Range<usize>| -> Vec<usize> {
            groups
                .filter(|&k| scores[k].iter().any(|v| *v != 0.0))
                .collect()
        };
        let mut larger = DMatrix::from_column_slice(P, P, model_based.as_slice());
        // The delete-one-cell jackknife over the cells of direction: the prior as pseudo-observations adds its own
        // share; each cell's score moves the fit by its score through the information of the other cells.
        let cells = used(0..ncell);
        if cells.len() > P {
            let g = cells.len() as f64;
            let mut jack = h_inv * (self.q * (sol.sigma2 * sol.sigma2)) * h_inv;
            for &k in &cells {
                let without = (h - info[k]).try_inverse().unwrap_or(h_inv);
                let shift = without * scores[k];
                jack += shift * shift.transpose() * ((g - 1.0) / g);
            }
            larger = crate::vector::loewner_max(
                &larger,
                &DMatrix::from_column_slice(P, P, jack.as_slice()),
            );
        }
        // The halves' disagreement scales the claims, not what the coverage determines.
        let blocks_used = used(ncell..ncell + blocks);
        let dispersion = self.split_dispersion(sol, &scores, &blocks_used, &g.block_info, ncell);
        let mut claimed = &larger * dispersion.max(1.0);
        // The cluster-robust sandwich over blocks of time: residuals alike for a while (a field that drifts, a magnet's
        // tail as the sensor moves) share a block. Not the jackknife: a block can hold directions no other block
        // has, and the fit without it is then barely determined. It sees some of the halves' disagreement already,
        // so it is not scaled again.
        if blocks_used.len() > P {
            let g = blocks_used.len() as f64;
            let meat: SMatrix<f64, P, P> = blocks_used
                .iter()
                .map(|&k| scores[k] * scores[k].transpose())
                .sum();
            let sandwich =
                h_inv * (meat * (g / (g - 1.0)) + self.q * (sol.sigma2 * sol.sigma2)) * h_inv;
            let sandwich = DMatrix::from_column_slice(P, P, sandwich.as_slice());
            larger = crate::vector::loewner_max(&larger, &sandwich);
            claimed = crate::vector::loewner_max(&claimed, &sandwich);
        }
        let matrix = |m: DMatrix<f64>| SMatrix::<f64, P, P>::from_column_slice(m.as_slice());
        let (mut claimed, mut larger) = (matrix(claimed), matrix(larger));
        if let Some(extra) = self.second_centres_share(sol, &h, &h_inv) {
            claimed += extra * dispersion.max(1.0);
            larger += extra;
        }
        // How much the prior informs the shape: tr(H⁻¹·σ²Q) over the shape's five dimensions.
        let share = ((h_inv * self.q * sol.sigma2).trace() / 5.0).clamp(0.0, 1.0);
        Some(Covariance {
            claimed,
            determined: larger,
            prior_share: share,
            dispersion,
        })
    }

    /// What the second centres' shifts, fitted with the rest, add to the covariance of the parameters (model-based):
    /// each window's shift moves its readings as the centre does, so its information about the centre is spent on
    /// its own shift — `σ²·((H − Σ H_θd·H_dd⁻¹·H_dθ)⁻¹ − H⁻¹)`, `H_θd` the window's information between the
    /// parameters and its centre. `None` without second centres.
    fn second_centres_share(
        &self,
        sol: &Solution,
        h: &SMatrix<f64, P, P>,
        h_inv: &SMatrix<f64, P, P>,
    ) -> Option<SMatrix<f64, P, P>> {
        if self.windows == 0 {
            return None;
        }
        let (c, a) = unpack(&sol.p);
        let mut info = vec![[0.0; TRIANGLE]; self.windows];
        for ((m, &w), &k) in self.raw.iter().zip(&self.w).zip(&self.window) {
            if k == 0 || w == 0.0 {
                continue;
            }
            let (_, j, _) = residual(&Vector3::from(*m), &a, &c, self.target);
            add_upper(&mut info[usize::from(k) - 1], &j.map(|v| w * v), &j);
        }
        let mut marginal = *h;
        for window in &info {
            let i = mirror(window);
            let cross = i.fixed_columns::<3>(0).into_owned();
            let own = cross.fixed_rows::<3>(0).into_owned().try_inverse()?;
            marginal -= cross * own * cross.transpose();
        }
        let extra = (marginal.try_inverse()? - h_inv) * sol.sigma2;
        Some((extra + extra.transpose()) * 0.5)
    }

    /// How much more the fits of the recording's two halves in time disagree than their own covariances say (as
    /// the vector fit's, see [`crate::vector`]): `κ = dᵀ·(V₁ + V₂)⁻¹·d / P`, each half's fit one Gauss–Newton step from
    /// the whole one on its blocks' sums (`θ_h − θ = −H_h⁻¹·g_h`, the prior in each half), `V_h` the larger of its
    /// model-based covariance and its sandwich over its blocks ([`HalfFit`]). 1 when a half cannot determine the fit.
    fn split_dispersion(
        &self,
        sol: &Solution,
        scores: &[SVector<f64, P>],
        blocks_used: &[usize],
        block_info: &[[f64; TRIANGLE]],
        ncell: usize,
    ) -> f64 {
        if blocks_used.len() < 8 {
            return 1.0;
        }
        let prior = self.q * sol.sigma2;
        let prior_score = self.q * sol.p * sol.sigma2;
        let half = |blocks: &[usize]| -> Option<HalfFit> {
            let h = blocks
                .iter()
                .map(|&k| mirror(&block_info[k - ncell]))
                .sum::<SMatrix<f64, P, P>>()
                + prior;
            let h_inv = h.cholesky()?.inverse();
            let block_scores: Vec<SVector<f64, P>> = blocks.iter().map(|&k| scores[k]).collect();
            let score: SVector<f64, P> = block_scores.iter().sum();
            Some(HalfFit::new(
                h_inv,
                sol.sigma2,
                -(h_inv * (score + prior_score)),
                &block_scores,
            ))
        };
        let (first, second) = blocks_used.split_at(blocks_used.len() / 2);
        let (Some(first), Some(second)) = (half(first), half(second)) else {
            return 1.0;
        };
        first
            .disagreement(&second)
            .map_or(1.0, |statistic| statistic / P as f64)
    }

    /// From the plain fit: refuse what the coverage cannot determine, remove the noise's share of the score, and
    /// return the parameters' covariance with the prior's share of the shape.
    fn refine(
        &self,
        sol: &mut Solution,
        opts: &ScalarOptions<'_>,
        target: f64,
    ) -> Result<Covariance, FitError> {
        let singular =
            || FitError::Singular("the magnitude residual's normal matrix has no inverse");
        // Refuse what the coverage cannot determine before refining it: the noise correction is only meaningful
        // where the fit is.
        let first = self.covariance(sol).ok_or_else(singular)?;
        let plain_cov = first.determined;
        check_determined(
            weakest(&plain_cov),
            sol.p.fixed_rows::<3>(3).sum() / 3.0,
            target,
        )?;
        let noise = Vector3::from(opts.raw_noise_var_ut2);
        let Some(s2) = noise
            .iter()
            .any(|v| *v > 0.0)
            .then(|| self.bounded_noise(sol, noise))
        else {
            return Ok(first);
        };
        let plain = sol.p;
        let converged = self.correct(sol, &s2);
        let moved = sol.p - plain;
        let gain = plain.fixed_rows::<3>(3).sum() / 3.0;
        let small = moved.fixed_rows::<3>(0).norm() <= MAX_CORRECTION * target / gain
            && moved.fixed_rows::<6>(3).amax() <= MAX_CORRECTION * gain;
        if !converged || !small {
            let (direction, _) = weakest(&plain_cov);
            return Err(FitError::NoiseDominates {
                direction,
                noise_ut: (s2.sum() / 3.0).sqrt() * gain,
                centre_moved_ut: moved.fixed_rows::<3>(0).norm() * gain,
                centre_limit_ut: MAX_CORRECTION * target,
                gain_moved: moved.fixed_rows::<6>(3).amax() / gain,
                gain_limit: MAX_CORRECTION,
                converged,
                field_ut: target,
                advice: rotate_advice(direction),
            });
        }
        self.covariance(sol).ok_or_else(singular)
    }
}

/// The direction in which the centre is least certain, and its standard error there.
fn weakest(cov: &SMatrix<f64, P, P>) -> ([f64; 3], f64) {
    let eig = SymmetricEigen::new(cov.fixed_view::<3, 3>(0, 0).into_owned());
    let k = eig.eigenvalues.imax();
    let v = eig.eigenvectors.column(k);
    let sign = v[v.iamax()].signum();
    (
        [v[0] * sign, v[1] * sign, v[2] * sign],
        eig.eigenvalues[k].max(0.0).sqrt(),
    )
}

/// The readings a fit can use (finite, with a positive weight) and their weights: the caller's own when every
/// reading is usable, copies otherwise.
struct Usable<'a> {
    /// The usable readings, µT.
    raw: Cow<'a, [[f64; 3]]>,
    /// Their weights (ones without the caller's).
    base: Cow<'a, [f64]>,
    /// How many there are.
    n: usize,
    /// Which of the `second_centres` each usable reading lies in, counted from 1 (0: none); empty without any.
    window: Vec<u8>,
}

/// The readings of `raw_ut` usable with the weights of `opts`; fewer than [`MIN_SAMPLES`] is an error.
fn usable_readings<'a>(
    raw_ut: &'a [[f64; 3]],
    opts: &ScalarOptions<'a>,
) -> Result<Usable<'a>, FitError> {
    if let Some(w) = opts.weights {
        assert_eq!(w.len(), raw_ut.len(), "one weight per reading");
    }
    let usable = |i: usize| {
        raw_ut[i].iter().all(|v| v.is_finite()) && opts.weights.is_none_or(|w| w[i] > 0.0)
    };
    let n = chunks::fold(
        raw_ut.len(),
        |range| range.filter(|&i| usable(i)).count(),
        |x, y| x + y,
    )
    .unwrap_or(0);
    if n < MIN_SAMPLES {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: n,
        });
    }
    let (mut raw, base): (Cow<'_, [[f64; 3]]>, Cow<'_, [f64]>) = if n == raw_ut.len() {
        (
            Cow::Borrowed(raw_ut),
            opts.weights
                .map_or_else(|| Cow::Owned(vec![1.0; n]), Cow::Borrowed),
        )
    } else {
        let rows = (0..raw_ut.len()).filter(|&i| usable(i));
        (
            rows.clone().map(|i| raw_ut[i]).collect(),
            rows.map(|i| opts.weights.map_or(1.0, |w| w[i])).collect(),
        )
    };
    let mut window = Vec::new();
    if !opts.second_centres.is_empty() {
        let of = |i: usize| {
            opts.second_centres
                .iter()
                .position(|w| (w.range.0..w.range.1).contains(&i))
                .map_or(0, |k| k as u8 + 1)
        };
        window = (0..raw_ut.len()).filter(|&i| usable(i)).map(of).collect();
        let raw = raw.to_mut();
        for (m, k) in raw.iter_mut().zip(&window) {
            if let Some(w) = k.checked_sub(1) {
                *m = frames::sub(*m, opts.second_centres[usize::from(w)].shift_ut);
            }
        }
    }
    Ok(Usable {
        raw,
        base,
        n,
        window,
    })
}

/// The solver's start: the centre and matrix of `start`, the matrix scaled from its magnitude to `target` (µT),
/// or else the sphere's centre `c0_ut` and the mean gain `gain` on the diagonal.
fn start_parameters(
    start: Option<&ScalarFit>,
    c0_ut: &Vector3<f64>,
    gain: f64,
    target: f64,
) -> SVector<f64, P> {
    let mut p0 = SVector::<f64, P>::zeros();
    match start {
        // The start's matrix maps its centre's readings onto its own magnitude: scaled to this one's.
        Some(s) => {
            p0.fixed_rows_mut::<3>(0)
                .copy_from(&Vector3::from(s.centre_ut));
            for (idx, (r, c)) in SYM.iter().enumerate() {
                p0[3 + idx] = s.a[*r][*c] * target / s.field_ut;
            }
        }
        None => {
            p0.fixed_rows_mut::<3>(0).copy_from(c0_ut);
            for k in 0..3 {
                p0[3 + k] = gain;
            }
        }
    }
    p0
}

/// The direction in which the centre is least certain under the covariance `cov`, and its standard error there;
/// an error when the solution's matrix `a` is not positive definite or, unless `quick`, the centre is undetermined
/// for the magnitude `target` (µT).
fn checked_weakest(
    a: &Matrix3<f64>,
    cov: &SMatrix<f64, P, P>,
    target: f64,
    quick: bool,
) -> Result<([f64; 3], f64), FitError> {
    let positive = a.determinant() > 0.0;
    if !positive {
        return Err(FitError::NotAnEllipsoid(
            "the best fit has a matrix that is not positive definite",
        ));
    }
    let weakest = weakest(cov);
    if !quick {
        check_determined(weakest, a.trace() / 3.0, target)?;
    }
    Ok(weakest)
}

/// The calibration at the solution, divided by `κ` so that the raw ellipsoid keeps its volume when no magnitude
/// was given (`κ = 1` when one was).
struct Scaled {
    /// `A / κ`.
    a: Matrix3<f64>,
    /// `b = −(A / κ)·c`, µT.
    b_ut: Vector3<f64>,
    /// `κ`: `det(A)^⅓`, or 1 with a given magnitude.
    kappa: f64,
    /// The magnitude aimed at over `κ`, µT.
    field_ut: f64,
    /// Weighted RMS of the magnitude residual over `κ`, µT.
    residual_rms_ut: f64,
}

impl Scaled {
    /// The solution `sol` of `problem` (its matrix `a` and centre `c_ut`) scaled by `κ`; an error when the
    /// magnitude still varies by more than [`NOT_AN_ELLIPSOID`] of the field.
    fn new(
        problem: &Problem<'_>,
        sol: &Solution,
        a: Matrix3<f64>,
        c_ut: &Vector3<f64>,
        field_given: bool,
    ) -> Result<Scaled, FitError> {
        // Without a given magnitude, keep the raw ellipsoid's volume: det(A) = 1.
        let kappa = if field_given {
            1.0
        } else {
            a.determinant().cbrt()
        };
        let a = a / kappa;
        let field_ut = problem.target / kappa;
        let residual_rms_ut = (sol.at.rss / problem.w_sum).sqrt() / kappa;
        if residual_rms_ut > NOT_AN_ELLIPSOID * field_ut {
            return Err(FitError::NotAnEllipsoid(
                "the magnitude still varies by more than 20 % after the best ellipsoid",
            ));
        }
        let b_ut = -(a * *c_ut);
        Ok(Scaled {
            a,
            b_ut,
            kappa,
            field_ut,
            residual_rms_ut,
        })
    }

    /// The covariance of `b = −A·c` (µT²) from the parameters' covariance `cov`, through the Jacobian of `b` in
    /// (c, A entries) with `A` scaled by `1/κ`; `c_ut` is the centre.
    fn b_covariance(&self, c_ut: &Vector3<f64>, cov: &SMatrix<f64, P, P>) -> Matrix3<f64> {
        let (a, c) = (&self.a, c_ut);
        let mut jac_b = SMatrix::<f64, 3, P>::zeros();
        for j in 0..3 {
            for k in 0..3 {
                jac_b[(j, k)] = -a[(j, k)];
            }
            for (idx, (r, s)) in SYM.iter().enumerate() {
                let mut d = 0.0;
                if *r == j {
                    d += c[*s];
                }
                if *s == j && r != s {
                    d += c[*r];
                }
                jac_b[(j, 3 + idx)] = -d / self.kappa;
            }
        }
        jac_b * *cov * jac_b.transpose()
    }

    /// The standard errors of the entries of `A / κ` from the parameters' covariance `cov`.
    fn a_se(&self, cov: &SMatrix<f64, P, P>) -> Mat3 {
        let mut a_se = [[0.0; 3]; 3];
        for (idx, (r, s)) in SYM.iter().enumerate() {
            let se = cov[(3 + idx, 3 + idx)].max(0.0).sqrt() / self.kappa;
            a_se[*r][*s] = se;
            a_se[*s][*r] = se;
        }
        a_se
    }
}

/// Fits a symmetric `A` and `b` to raw readings (µT) so that the calibrated magnitude is constant.
pub fn fit(raw_ut: &[[f64; 3]], opts: &ScalarOptions<'_>) -> Result<ScalarFit, FitError> {
    let readings = usable_readings(raw_ut, opts)?;
    let n = readings.n;
    let coverage = Coverage::of(&readings.raw);
    if !opts.skip_coverage_check {
        coverage.check()?;
    }
    let (c0, r0) = sphere(&readings.raw, &readings.base).ok_or(FitError::NotAnEllipsoid(
        "the readings fit no sphere: they may lie on a plane",
    ))?;
    // The fit aims at the given magnitude, or at the sphere's radius (rescaled to the ellipsoid's volume after).
    let target = opts.field_ut.unwrap_or(r0);
    let gain = target / r0;
    let problem = Problem::new(readings, &c0, target, gain, !opts.quick);
    let p0 = start_parameters(opts.start, &c0, gain, target);
    let mut sol = problem.settle(p0, if opts.quick { 1 } else { MAX_ROUNDS });
    let covariance = if opts.quick {
        Covariance {
            claimed: SMatrix::zeros(),
            determined: SMatrix::zeros(),
            prior_share: 0.0,
            dispersion: 1.0,
        }
    } else {
        problem.refine(&mut sol, opts, target)?
    };
    let (cov, shape_prior_share) = (covariance.claimed, covariance.prior_share);
    let (c, a) = unpack(&sol.p);
    let weakest = checked_weakest(&a, &covariance.determined, target, opts.quick)?;
    let scaled = Scaled::new(&problem, &sol, a, &c, opts.field_ut.is_some())?;
    let cov_b = scaled.b_covariance(&c, &cov);
    let cov_c: Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
    let b = scaled.b_ut;
    Ok(ScalarFit {
        a: std::array::from_fn(|j| std::array::from_fn(|k| scaled.a[(j, k)])),
        b_ut: [b[0], b[1], b[2]],
        a_se: scaled.a_se(&cov),
        b_se_ut: std::array::from_fn(|j| cov_b[(j, j)].max(0.0).sqrt()),
        centre_ut: [c[0], c[1], c[2]],
        centre_cov_ut2: std::array::from_fn(|j| std::array::from_fn(|k| cov_c[(j, k)])),
        field_ut: scaled.field_ut,
        field_given: opts.field_ut.is_some(),
        residual_rms_ut: scaled.residual_rms_ut,
        iterations: sol.iterations,
        n,
        coverage,
        direction_cells: problem.cells,
        shape_prior_share,
        weakest,
        dispersion: covariance.dispersion,
    })
}

/// Refuses a centre the recording does not determine: its standard error along the weakest direction (raw units,
/// made calibrated by the mean gain) above [`REFUSE_CENTRE_SE`] of the field aimed at.
fn check_determined(
    (direction, se_raw): ([f64; 3], f64),
    gain: f64,
    target: f64,
) -> Result<(), FitError> {
    let se_ut = se_raw * gain;
    if se_ut <= REFUSE_CENTRE_SE * target && se_ut.is_finite() {
        return Ok(());
    }
    Err(FitError::Undetermined {
        direction,
        se_ut,
        field_ut: target,
        advice: rotate_advice(direction),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal, UnitSphere};

    fn ellipsoid(
        a_true: Matrix3<f64>,
        b_true: Vector3<f64>,
        sigma: f64,
        n: usize,
        seed: u64,
    ) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let inv = a_true.try_inverse().unwrap();
        (0..n)
            .map(|_| {
                let d: [f64; 3] = UnitSphere.sample(&mut rng);
                let m = inv * (Vector3::from(frames::scale(d, 50.0)) - b_true);
                [m.x, m.y, m.z].map(|v| v + noise.sample(&mut rng))
            })
            .collect()
    }

    /// 2000 readings of a distorted sensor in a 50 µT field, `change` applied to the raw readings 800–1600.
    fn with_a_window(
        change: impl Fn([f64; 3]) -> [f64; 3],
    ) -> (Vec<[f64; 3]>, Matrix3<f64>, Vector3<f64>) {
        let a_true = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.9, 0.03, -0.02, 0.03, 1.15);
        let b_true = Vector3::new(-30.0, 12.0, 44.0);
        let mut raw = ellipsoid(a_true, b_true, 0.1, 2000, 7);
        raw[800..1600].iter_mut().for_each(|m| *m = change(*m));
        (raw, a_true, b_true)
    }

    /// The fit of `raw` without the readings `[a, b)`, and the problem.
    fn without(raw: &[[f64; 3]], (a, b): (usize, usize)) -> (ScalarProblem<'_>, ScalarFit) {
        let problem = ScalarProblem {
            raw_ut: Cow::Borrowed(raw),
            field_ut: Some(50.0),
            raw_noise_var_ut2: [0.01; 3],
        };
        let kept: Vec<bool> = (0..raw.len()).map(|i| !(a..b).contains(&i)).collect();
        let fit = problem.final_fit(&kept, None).unwrap();
        (problem, fit)
    }

    #[test]
    fn a_field_on_the_board_is_a_second_centre_located_and_fitted_with_the_rest() {
        let shift = [8.0, -5.0, 3.0];
        let (raw, a_true, b_true) = with_a_window(|m| frames::add(m, shift));
        // The window as a scan might give it, 50 readings too wide on each side.
        let (problem, rest_only) = without(&raw, (750, 1650));
        let kept = vec![true; raw.len()];
        let robust::OwnStates {
            fit: joint,
            residual_ut: e,
            windows: located,
        } = problem
            .with_windows(&rest_only, &kept, &[(750, 1650)])
            .expect("a second centre");
        assert_eq!(located, vec![(800, 1600)]);
        let centres = problem
            .joint(&rest_only, &kept, &[(750, 1650)], true)
            .unwrap()
            .1;
        for k in 0..3 {
            assert!(
                (centres[0].shift_ut[k] - shift[k]).abs() < 0.05,
                "{centres:?}"
            );
        }
        // Every reading explained to the noise, the window's in its own state.
        assert!(robust::median(&e) < 0.1, "{}", robust::median(&e));
        for j in 0..3 {
            assert!((joint.b_ut[j] - b_true[j]).abs() < 5.0 * joint.b_se_ut[j] + 1e-3);
            for k in 0..3 {
                assert!((joint.a[j][k] - a_true[(j, k)]).abs() < 5.0 * joint.a_se[j][k] + 1e-4);
            }
        }
        // The window's readings tell the shape, not the sensor's centre: the centre's uncertainty is at least the one
        // the same readings give when all are in one state, and the shape's less than the rest's alone.
        let (one_state, ..) = with_a_window(|m| m);
        let (_, all) = without(&one_state, (0, 0));
        for k in 0..3 {
            assert!(joint.centre_cov_ut2[k][k] > all.centre_cov_ut2[k][k]);
            assert!(joint.a_se[k][k] < rest_only.a_se[k][k]);
        }
    }

    #[test]
    fn a_field_in_the_room_is_no_second_centre() {
        // The magnitude raised by 4 µT in the window whatever the attitude: a field fixed in the room.
        let centre = {
            let a_true = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.9, 0.03, -0.02, 0.03, 1.15);
            -(a_true.try_inverse().unwrap() * Vector3::new(-30.0, 12.0, 44.0))
        };
        let (raw, ..) = with_a_window(|m| {
            let d = Vector3::from(m) - centre;
            (centre + d * (54.0 / 50.0)).into()
        });
        let (problem, rest_only) = without(&raw, (800, 1600));
        assert!(
            problem
                .joint(&rest_only, &vec![true; raw.len()], &[(800, 1600)], true)
                .is_none()
        );
    }

    #[test]
    fn the_best_run_is_the_largest_positive_sum() {
        let x = [-1.0, 2.0, -0.5, 3.0, -10.0, 4.0];
        assert_eq!(best_run(x.iter().copied()), Some((1, 4)));
        assert_eq!(best_run([-1.0, -2.0].iter().copied()), None);
    }

    #[test]
    fn recovers_a_symmetric_distortion() {
        let a_true = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.9, 0.03, -0.02, 0.03, 1.15);
        let b_true = Vector3::new(-30.0, 12.0, 44.0);
        let raw = ellipsoid(a_true, b_true, 0.0, 400, 4);
        let fit = fit(
            &raw,
            &ScalarOptions {
                field_ut: Some(50.0),
                ..Default::default()
            },
        )
        .unwrap();
        for j in 0..3 {
            assert!((fit.b_ut[j] - b_true[j]).abs() < 1e-6, "{:?}", fit.b_ut);
            for k in 0..3 {
                assert!((fit.a[j][k] - a_true[(j, k)]).abs() < 1e-8);
            }
        }
        assert!(fit.residual_rms_ut < 1e-8);
        assert!(fit.shape_prior_share < 1e-6, "{}", fit.shape_prior_share);
    }

    #[test]
    fn readings_seen_from_a_wrong_centre_lie_in_a_cap() {
        // Readings all round a sphere: from the right fit they cover the sphere of directions; from a fit whose
        // centre lies far outside them (a huge sphere through a band of them, at a tiny gain), a cap.
        let a_true = Matrix3::from_diagonal(&Vector3::new(1.05, 0.95, 1.0));
        let b_true = Vector3::new(10.0, -20.0, 5.0);
        let raw = ellipsoid(a_true, b_true, 0.2, 4000, 8);
        let problem = ScalarProblem {
            raw_ut: Cow::Borrowed(&raw),
            field_ut: Some(50.0),
            raw_noise_var_ut2: [0.04; 3],
        };
        let right = fit(
            &raw,
            &ScalarOptions {
                field_ut: Some(50.0),
                ..Default::default()
            },
        )
        .unwrap();
        let mut wrong = right.clone();
        wrong.a = [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]];
        wrong.b_ut = [30.0, 0.0, 0.0];
        let (from_right, from_wrong) = (problem.support(&right), problem.support(&wrong));
        assert!(from_right > 0.95, "{from_right}");
        assert!(from_wrong < 0.2, "{from_wrong}");
    }

    #[test]
    fn without_a_magnitude_the_sphere_keeps_the_ellipsoids_volume() {
        let a_true = Matrix3::from_diagonal(&Vector3::new(1.2, 1.0, 0.8));
        let raw = ellipsoid(a_true, Vector3::new(5.0, 5.0, 5.0), 0.0, 300, 5);
        let fit = fit(&raw, &ScalarOptions::default()).unwrap();
        // Raw radii 50/1.2, 50, 50/0.8: their geometric mean.
        let want = 50.0 / (1.2f64 * 0.8).cbrt();
        assert!((fit.field_ut - want).abs() < 1e-6, "{}", fit.field_ut);
        let radii = fit.radii_ut();
        for (r, w) in radii.iter().zip([50.0 / 0.8, 50.0, 50.0 / 1.2]) {
            assert!((r - w).abs() < 1e-6, "{radii:?}");
        }
        assert!(!fit.field_given);
    }

    #[test]
    fn points_on_a_hyperboloid_are_refused() {
        let raw: Vec<[f64; 3]> = (0..400)
            .map(|i| {
                let (u, v) = ((i % 20) as f64 * 0.3 - 3.0, (i / 20) as f64 * 0.314);
                [
                    10.0 * u.cosh() * v.cos(),
                    10.0 * u.cosh() * v.sin(),
                    10.0 * u.sinh(),
                ]
            })
            .collect();
        let opts = ScalarOptions {
            field_ut: Some(50.0),
            skip_coverage_check: true,
            ..Default::default()
        };
        assert!(fit(&raw, &opts).is_err());
    }
}
