//! Robust estimation: a base fit that gross disturbances cannot drag.
//!
//! A magnet passing the sensor, a magnet attached to the board for a minute, a glitch: such samples are off by tens
//! of µT where the rest sit at the noise and the reference's own error. Least squares follows them; this fit does
//! not:
//! 1. **Seeds from time spans.** Fits on contiguous spans of a sixth, a third, a half and two thirds of the recording
//!    (and on all of it), each refined first by concentration steps (fit the half of all samples it fits best, until
//!    that half settles: from a seed that is mostly clean this reaches the clean state even when every long span is
//!    disturbed somewhere), then by iteratively reweighted least squares with Tukey's biweight on the residual's size
//!    against a scale from its median. A disturbance covering up to half the recording leaves at least one seed
//!    clean or mostly clean. A problem may add one seed from the bulk of its samples ([`RobustProblem::bulk_weights`]:
//!    the scalar method's readings whose distance from the median reading is not far out), which a field many times
//!    the Earth's cannot capture however it is spread in time. The seeds run on a subsample of at most
//!    [`SEED_SAMPLES`] samples, on all threads.
//! 2. **The best seed** is the one with the smallest median residual over all samples — the state the recording is
//!    in most of the time, not the one that covers most directions. Seeds whose matrix is implausible (gains more
//!    than [`PLAUSIBLE_GAIN_RATIO`] apart: a fit to a still stretch that explains it with any matrix) lose to
//!    plausible ones, and so do seeds the samples do not support ([`RobustProblem::support`]): seen from a scalar
//!    seed fitted to a cap of the recording — a huge sphere through a band of the readings and a still stretch —
//!    the readings lie in a cap, and its median residual can be the smallest of all when the sensor rested for much
//!    of the recording (an undisturbed physical recording with a minute at rest at each end was refused when
//!    8–12 µT sat on its board for a third of it).
//! 3. **On all samples**, a few reweighting passes from the best seed (until the weights settle; on a subsample of at
//!    most [`REWEIGHT_SAMPLES`] samples, which fixes the fit far more closely than the spans need); then the samples
//!    of the whole recording whose residual exceeds [`GROSS_SIGMA`] times the scale make spans — merged across gaps
//!    of up to [`SPAN_GAP_S`] and widened over their ramps (neighbours above [`RAMP_SIGMA`], and on for
//!    [`RobustProblem::RAMP_TAIL`] times a ramp's length: a magnet's tail in the scalar method) — which are excluded,
//!    and the rest is fitted by plain (weighted 0/1) least squares, from the fit before (an iterative solver needs
//!    fewer passes); twice, with the spans of the new fit. A whole span goes, not only its gross samples: a
//!    magnet attached to a hand-held sensor shows in |B| only where the field points along its offset, and the
//!    samples in between are no cleaner. Without gross disturbances nothing is excluded and the fit *is* the
//!    least-squares fit.
//! 4. **Shifted windows** (a problem that has them, see [`RobustProblem::shifted`]): in the scalar method's
//!    magnitude a field fixed in the room for a while shows as a constant, one fixed to the sensor as `d·u` along
//!    the field's direction `u` (which averages out over a turning window), often too little to be gross — through
//!    |B| alone a second sphere centre with the same shape. Windows where the signed residual moves so are found by
//!    a scan ([`shifted_windows`]), each judged against the noise the residual keeps once the window is fitted: up
//!    to a quarter of the recording at the scan's false-alarm level, up to four fifths when the evidence is ten
//!    times as strong and the window came and went (it explains the samples better than the same shift reaching
//!    either end of the recording). A window is what comes and goes, so the state a recording starts and ends in
//!    is the sensor's own: when the fit kept the middle and left both ends out, and one calibration explains both
//!    ends, it is calibrated on them ([`prefer_the_ends`]). The windows are excluded and the rest fitted again,
//!    unless the rest would cover less than half the directions ([`SHIFT_KEEP_COVERAGE`]): then they stay in, and
//!    are reported ([`Robust::mixed`]): the fit mixes two states there.

use crate::FitError;
use crate::chunks;
use crate::frames::Mat3;
use crate::model::Model;
use rayon::prelude::*;

/// Gross samples closer than this in time are one span, s.
pub const SPAN_GAP_S: f64 = 0.5;
/// Without time, gross samples this close are one span.
pub const SPAN_GAP_SAMPLES: usize = 5;
/// A span's neighbours down to this many scales belong to it (the ramp of a magnet brought close by hand).
pub const RAMP_SIGMA: f64 = 3.0;
/// Neighbouring spans separated by less than this share of their mean length are one span: a magnet attached to a
/// turning sensor shows in |B| only while the field points along it, and the lulls in between are no cleaner.
pub const GAP_SHARE: f64 = 0.5;
/// Passes of excluding the spans of the current fit and fitting again.
const SPAN_PASSES: usize = 2;
/// Seeds are fitted on a subsample of at most this many samples.
pub const SEED_SAMPLES: usize = 8_000;
/// A residual beyond this many standard deviations (per axis) of the scale is gross.
pub const GROSS_SIGMA: f64 = 6.0;
/// Tukey's biweight cut-off, in the same units: samples beyond get no weight while reweighting.
const BIWEIGHT_SIGMA: f64 = 6.0;
/// A seed is supported when the samples cover at least this share of the directions, seen from it, that they cover
/// seen from the seed they cover most from.
const SUPPORT_SHARE: f64 = 0.75;
/// A matrix whose singular values differ by more than this factor is an implausible calibration.
pub const PLAUSIBLE_GAIN_RATIO: f64 = 2.5;
const SEED_ITERATIONS: usize = 20;
/// Concentration steps of a seed, at most.
const TRIM_STEPS: usize = 5;
/// Concentration steps stop when at most one sample in this many changed sides.
const TRIM_SETTLED: usize = 100;
/// The share of the samples a concentration step fits.
const TRIM_SHARE: f64 = 0.5;
const FULL_ITERATIONS: usize = 3;
/// The reweighting from the best seed runs on a subsample of at most this many samples: its fit only finds the gross
/// spans, which the residuals of all samples then make.
pub const REWEIGHT_SAMPLES: usize = 100_000;
/// Reweighting stops when no sample's weight changes by more than this.
const WEIGHTS_SETTLED: f64 = 1e-3;

/// A fitting problem that can be solved with per-sample weights: what the robust fit needs of the vector and the
/// scalar method.
pub trait RobustProblem: Sized + Sync {
    /// The fit it makes.
    type Fit: Send;
    /// The median size of a residual of pure noise of unit standard deviation per axis (≈1.538 for the norm of a
    /// 3-vector, 0.6745 for the absolute value of a scalar).
    const MEDIAN_OF_UNIT: f64;
    /// The same median among the sizes below [`MODE_WINDOW`] (≈1.513 for the norm of a 3-vector, 0.6724 for the
    /// absolute value of a scalar): the scale of a residual's mode ([`mode_scale`]).
    const MEDIAN_OF_UNIT_IN_MODE: f64;
    /// How far a gross span goes on beyond its ramp (the neighbours above [`RAMP_SIGMA`]), in the ramp's lengths:
    /// none unless a problem says otherwise.
    const RAMP_TAIL: f64 = 0.0;
    /// Number of samples.
    fn len(&self) -> usize;
    /// Whether there are no samples.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// A problem of every `stride`-th sample, for cheap seeds.
    fn every(&self, stride: usize) -> Self;
    /// A quick fit (estimates only) with per-sample weights in `[0, 1]`; an iterative solver may `start` from a fit
    /// of nearly the same samples.
    fn quick_fit(&self, weights: &[f64], start: Option<&Self::Fit>) -> Result<Self::Fit, FitError>;
    /// The full fit (uncertainties and checks) of the samples `kept`, maybe from `start` as [`Self::quick_fit`].
    fn final_fit(&self, kept: &[bool], start: Option<&Self::Fit>) -> Result<Self::Fit, FitError>;
    /// Each sample's residual size under a fit (NaN where the sample is unusable).
    fn residuals(&self, fit: &Self::Fit) -> Vec<f64>;
    /// The linear model of a fit.
    fn model(fit: &Self::Fit) -> Model;
    /// The windows (sample ranges) where the signed residual of the `kept` samples is shifted, too little to be
    /// gross, in a way the residual sizes do not show: none, unless a problem says otherwise.
    fn shifted(&self, _fit: &Self::Fit, _kept: &[bool]) -> Vec<(usize, usize)> {
        Vec::new()
    }
    /// The fit of the samples `kept` and those in `windows`, each window a state of its own, from the fit `without`
    /// them. `None` unless a problem can model such a state (the scalar method: a second centre).
    fn with_windows(
        &self,
        _without: &Self::Fit,
        _kept: &[bool],
        _windows: &[(usize, usize)],
    ) -> Option<OwnStates<Self::Fit>> {
        None
    }
    /// Weights of one more seed: the bulk of the samples by something a disturbance cannot hide in (none, unless a
    /// problem has such a thing).
    fn bulk_weights(&self) -> Option<Vec<f64>> {
        None
    }
    /// How much of the sphere of directions the samples `kept` cover as seen from a fit: all of it, unless a problem
    /// can tell.
    fn covered(&self, _fit: &Self::Fit, _kept: &[bool]) -> f64 {
        1.0
    }
    /// How much of the sphere of directions the samples cover as seen from a fit (see [`fit`]): all of it, unless a
    /// problem can tell.
    fn support(&self, _fit: &Self::Fit) -> f64 {
        1.0
    }
}

/// A fit in which windows of the samples have states of their own ([`RobustProblem::with_windows`]).
pub struct OwnStates<F> {
    /// The fit.
    pub fit: F,
    /// Each sample's residual size under it, the windows' in their own state.
    pub residual_ut: Vec<f64>,
    /// The windows, where the states explain the samples best.
    pub windows: Vec<(usize, usize)>,
}

/// A robust fit and what it left out.
#[derive(Clone, Debug, PartialEq)]
pub struct Robust<F> {
    /// The final fit, on the samples kept.
    pub fit: F,
    /// Per sample: kept (true), or excluded as grossly off (false; samples the fit cannot use are kept).
    pub kept: Vec<bool>,
    /// The scale of the residual: a standard deviation per axis from the median residual, µT.
    pub sigma_ut: f64,
    /// Each sample's residual size under the fit, µT (NaN where unusable).
    pub residual_ut: Vec<f64>,
    /// Shifted windows ([`RobustProblem::shifted`]) left in the fit because the samples left would cover less than
    /// [`SHIFT_KEEP_COVERAGE`] of the directions, as sample ranges `[start, end)`: the fit mixes two states there.
    pub mixed: Vec<(usize, usize)>,
}

impl<F> Robust<F> {
    /// Samples excluded.
    pub fn excluded(&self) -> usize {
        self.kept.iter().filter(|k| !**k).count()
    }
}

/// The robust fit of a problem (see the module docs); `t_s` is each sample's time, when known.
pub fn fit<P: RobustProblem>(problem: &P, t_s: Option<&[f64]>) -> Result<Robust<P::Fit>, FitError> {
    let Some(seed) = best_seed(problem) else {
        // No seed could be fitted: the full data decides (and its error says why).
        return fit_all(problem);
    };
    let (fit, residual_ut) = reweight_all(problem, seed);
    let mut robust = exclude_gross_spans(problem, fit, residual_ut, t_s)?;
    // Windows shifted too little to be gross (a field fixed in the room or to the sensor, in the magnitude) go too,
    // when the samples are in time order.
    if t_s.is_some() {
        exclude_shifted_windows(problem, &mut robust);
    }
    // Samples the fit cannot use inside a span are not excluded by it.
    for (k, e) in robust.kept.iter_mut().zip(&robust.residual_ut) {
        *k |= !e.is_finite();
    }
    Ok(robust)
}

/// The shares of the samples the consistent part's concentration steps fit ([`consistent_part`]): it must hold at
/// least one of them.
const PART_SHARES: [f64; 3] = [0.1, 0.2, 0.3];
/// The consistent part's seeds: contiguous spans of a 24th and a 12th of the recording.
const PART_SPANS: [usize; 2] = [24, 12];
/// Concentration steps of a consistent part's seed, at most.
const PART_STEPS: usize = 15;
/// A consistent part's samples cover at least this share of the directions all samples cover: a still stretch any
/// matrix explains is no consistent part.
const PART_COVERAGE: f64 = 0.4;
/// The window of a residual's mode, in its scales ([`mode_scale`]).
pub const MODE_WINDOW: f64 = 3.0;
/// Passes of the scale of the consistent part's residual, at most ([`mode_scale`]).
const MODE_PASSES: usize = 30;

/// The largest part of a recording one calibration explains to its own scale, when most of it is disturbed (a
/// recording carried past metal for most of the time): what the module's majority fit cannot give.
///
/// Seeds from short spans (a 24th and a 12th of the recording, on a subsample of at most [`SEED_SAMPLES`]) are
/// brought by concentration steps to the tenth, fifth or third of all samples they fit best (least trimmed squares
/// at a small share); each plausible one's scale is that of the mode of its residual ([`mode_scale`]), and the seed
/// with the smallest scale whose samples within [`GROSS_SIGMA`] of it are at least the share it was concentrated on
/// wins. On all samples, the runs of samples beyond [`GROSS_SIGMA`] scales of that fit, widened over their ramps,
/// are left out and the rest fitted (twice), as in the module's step 3 but without merging lulls: between the
/// disturbances of a mostly disturbed recording the lulls are the consistent part. `None` when no seed gives a
/// plausible part or its final fit is refused (too few directions, say).
pub fn consistent_part<P: RobustProblem>(
    problem: &P,
    t_s: Option<&[f64]>,
) -> Option<Robust<P::Fit>> {
    let stride = problem.len().div_ceil(SEED_SAMPLES).max(1);
    let sub = (stride > 1).then(|| problem.every(stride));
    let seeds = sub.as_ref().unwrap_or(problem);
    let m = seeds.len();
    let starts: Vec<((usize, usize), f64)> = PART_SPANS
        .iter()
        .flat_map(|&k| (0..k).map(move |i| (i * m / k, (i + 1) * m / k)))
        .flat_map(|span| PART_SHARES.iter().map(move |&q| (span, q)))
        .collect();
    let parts = chunks::parts(starts.len(), |k| {
        let ((a, b), share) = starts[k];
        concentrated(seeds, (a, b), share)
    });
    let (seed, _) = parts
        .into_iter()
        .flatten()
        .min_by(|x, y| x.1.total_cmp(&y.1))?;
    drop(sub);
    let mut fit = seed;
    let mut residual_ut = problem.residuals(&fit);
    let mut sigma_ut = mode_scale::<P>(&residual_ut);
    let n = problem.len();
    let mut kept = outside(&ramped_runs(&residual_ut, sigma_ut, t_s, P::RAMP_TAIL), n);
    for _ in 0..SPAN_PASSES {
        fit = problem.final_fit(&kept, Some(&fit)).ok()?;
        refresh(problem, &fit, &mut residual_ut);
        sigma_ut = mode_scale::<P>(&residual_ut);
        kept = outside(&ramped_runs(&residual_ut, sigma_ut, t_s, P::RAMP_TAIL), n);
    }
    let fit = problem.final_fit(&kept, Some(&fit)).ok()?;
    refresh(problem, &fit, &mut residual_ut);
    for (k, e) in kept.iter_mut().zip(&residual_ut) {
        *k |= !e.is_finite();
    }
    Some(Robust {
        fit,
        kept,
        sigma_ut,
        residual_ut,
        mixed: Vec::new(),
    })
}

/// Blocks of time a consistent part is cut into to check that it holds out ([`holds_out`]).
const HOLD_OUT_BLOCKS: usize = 10;
/// A consistent part holds out when, fitted on every other block of time, the other blocks' residual scale is at
/// most this many times its own.
const HOLD_OUT_RATIO: f64 = 1.5;

/// Whether a consistent part ([`consistent_part`]) of `problem` holds through the recording ([`PartCheck`]): the
/// time from the first usable sample to the last (of samples, without `t_s`) cut into [`HOLD_OUT_BLOCKS`] blocks,
/// the part has samples in at least half of them (disturbances come and go; an offset that drifts agrees with one calibration
/// only for a while), and its samples fitted on the even blocks and on the odd ones, each fit's residual scale on
/// the other blocks' samples is at most [`HOLD_OUT_RATIO`] times the part's. A calibration made up of a few
/// stretches it happens to fit (a still stretch, a slow arc) does not.
pub fn holds_out<P: RobustProblem>(
    problem: &P,
    part: &Robust<P::Fit>,
    t_s: Option<&[f64]>,
) -> PartCheck {
    let n = part.kept.len();
    let usable: Vec<usize> = (0..n)
        .filter(|&i| part.residual_ut[i].is_finite())
        .collect();
    let (Some(&first), Some(&last)) = (usable.first(), usable.last()) else {
        return PartCheck::Brief;
    };
    // Each usable kept sample's block of the time from the first usable sample to the last (of rank, without
    // times).
    let mut block: Vec<Option<usize>> = vec![None; n];
    let mut seen = [false; HOLD_OUT_BLOCKS];
    for (rank, &i) in usable.iter().enumerate() {
        let at = match t_s {
            Some(t) if t[last] > t[first] => (t[i] - t[first]) / (t[last] - t[first]),
            _ => rank as f64 / usable.len() as f64,
        };
        let b = ((at * HOLD_OUT_BLOCKS as f64) as usize).min(HOLD_OUT_BLOCKS - 1);
        if part.kept[i] {
            block[i] = Some(b);
            seen[b] = true;
        }
    }
    if 2 * seen.iter().filter(|s| **s).count() < HOLD_OUT_BLOCKS {
        return PartCheck::Brief;
    }
    let predicts = (0..2).all(|parity| {
        let fitted: Vec<f64> = block
            .iter()
            .map(|b| f64::from(u8::from(b.is_some_and(|b| b % 2 == parity))))
            .collect();
        let Ok(fit) = problem.quick_fit(&fitted, None) else {
            return false;
        };
        let e = problem.residuals(&fit);
        let held: Vec<f64> = (0..n)
            .filter(|&i| block[i].is_some_and(|b| b % 2 != parity))
            .map(|i| e[i])
            .collect();
        scale::<P>(&held) <= HOLD_OUT_RATIO * part.sigma_ut
    });
    if predicts {
        PartCheck::Holds
    } else {
        PartCheck::Misses
    }
}

/// What [`holds_out`] found of a consistent part.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PartCheck {
    /// Spread through the recording, and each half of its time predicts the other.
    Holds,
    /// Spread through the recording, but a half of its time misses the other: too few directions.
    Misses,
    /// In few stretches of the recording: one calibration explains it only for a while.
    Brief,
}

/// From the fit on the samples of `span`, concentration steps on the `share` of the samples it fits best: the fit and
/// the scale of its residual's mode ([`mode_scale`]), in raw units; `None` when a fit fails, is implausible, or
/// fewer than `share` of the samples lie within [`GROSS_SIGMA`] of that scale, or they cover less than
/// [`PART_COVERAGE`] of the directions all samples cover.
fn concentrated<P: RobustProblem>(
    p: &P,
    (a, b): (usize, usize),
    share: f64,
) -> Option<(P::Fit, f64)> {
    let mut w = vec![0.0; p.len()];
    w[a..b].fill(1.0);
    let mut fit = p.quick_fit(&w, None).ok()?;
    let mut kept_prev: Vec<bool> = Vec::new();
    for _ in 0..PART_STEPS {
        let e = p.residuals(&fit);
        let cut = quantile(&e, share);
        let kept: Vec<bool> = e.iter().map(|x| x.is_finite() && *x <= cut).collect();
        let moved = kept.iter().zip(&kept_prev).filter(|(a, b)| a != b).count();
        if !kept_prev.is_empty() && moved * TRIM_SETTLED <= kept.len() {
            break;
        }
        fit = p.quick_fit(&weights_of(&kept), None).ok()?;
        kept_prev = kept;
    }
    let a = P::model(&fit).a;
    if !plausible(&a) {
        return None;
    }
    let e = p.residuals(&fit);
    let sigma = mode_scale::<P>(&e);
    let usable: Vec<bool> = e.iter().map(|x| x.is_finite()).collect();
    let within: Vec<bool> = e.iter().map(|x| *x <= GROSS_SIGMA * sigma).collect();
    let count = |k: &[bool]| k.iter().filter(|k| **k).count() as f64;
    let held = count(&within) >= share * count(&usable);
    let spread = p.covered(&fit, &within) >= PART_COVERAGE * p.covered(&fit, &usable);
    (held && spread).then(|| (fit, sigma / mean_gain(&a)))
}

/// The scale of the mode of residual sizes `e` that hold a consistent part and disturbed samples of every size:
/// from the scale of their smallest tenth, the scale of the samples within [`MODE_WINDOW`] of the last (their
/// median against [`RobustProblem::MEDIAN_OF_UNIT_IN_MODE`]), until it settles (at most [`MODE_PASSES`] times).
/// A wider window creeps: on BROAD 02 with 83 % disturbed, within six scales it grew pass by pass from 1.1 to
/// 9.2 µT, the disturbed samples' spread.
fn mode_scale<P: RobustProblem>(e: &[f64]) -> f64 {
    mode_scale_of(e, P::MEDIAN_OF_UNIT_IN_MODE)
}

/// [`mode_scale`] for residual sizes of which, for pure noise of unit standard deviation, those below
/// [`MODE_WINDOW`] have the median `median_in_mode`.
fn mode_scale_of(e: &[f64], median_in_mode: f64) -> f64 {
    let mut sigma = quantile(e, PART_SHARES[0]) / median_in_mode;
    for _ in 0..MODE_PASSES {
        let within: Vec<f64> = e
            .iter()
            .copied()
            .filter(|x| x.is_finite() && *x <= MODE_WINDOW * sigma)
            .collect();
        let next = median(&within) / median_in_mode;
        let settled = (next - sigma).abs() <= 1e-3 * sigma;
        sigma = next;
        if settled || !sigma.is_finite() {
            break;
        }
    }
    sigma
}

/// A seed's fit, the scale of its residual and how much of the sphere of directions the samples cover seen from it
/// ([`RobustProblem::support`]).
struct Seed<F> {
    /// The seed's fit.
    fit: F,
    /// The scale of its residual (see [`scale`]).
    scale: f64,
    /// The share of the directions the samples cover seen from it.
    support: f64,
}

/// The best seed (steps 1 and 2 of the module docs), fitted on a subsample of at most [`SEED_SAMPLES`] samples;
/// `None` when no seed could be fitted.
fn best_seed<P: RobustProblem>(problem: &P) -> Option<P::Fit> {
    let stride = problem.len().div_ceil(SEED_SAMPLES).max(1);
    let sub = (stride > 1).then(|| problem.every(stride));
    let seeds = sub.as_ref().unwrap_or(problem);
    let fitted = fit_seeds(seeds);
    pick_seed(seeds, fitted)
}

/// Each seed's fit and the scale of its residual (`None` where it could not be fitted), on all threads: one per
/// span of [`seed_spans`], then one from the problem's bulk weights when it has them.
fn fit_seeds<P: RobustProblem>(seeds: &P) -> Vec<Option<(P::Fit, f64)>> {
    let m = seeds.len();
    let spans = seed_spans(m);
    let bulk = seeds.bulk_weights();
    chunks::parts(spans.len() + usize::from(bulk.is_some()), |k| {
        let Some(&(a, b)) = spans.get(k) else {
            return reweight(seeds, bulk.as_deref()?, SEED_ITERATIONS);
        };
        let mut w = vec![0.0; m];
        w[a..b].fill(1.0);
        reweight(seeds, &w, SEED_ITERATIONS)
    })
}

/// The best of the `fitted` seeds, compared in order: plausible seeds first, then those the samples support, then
/// the smallest scale (see the module docs).
fn pick_seed<P: RobustProblem>(seeds: &P, fitted: Vec<Option<(P::Fit, f64)>>) -> Option<P::Fit> {
    // Seeds compare in raw units: a fit that shrinks the readings (a scalar fit's huge sphere through a cap, at a
    // tiny gain) shrinks its residuals with them.
    let fitted: Vec<Seed<P::Fit>> = fitted
        .into_iter()
        .flatten()
        .map(|(fit, scale)| {
            let support = seeds.support(&fit);
            Seed {
                fit,
                scale,
                support,
            }
        })
        .collect();
    let most_support = fitted.iter().map(|s| s.support).fold(0.0, f64::max);
    // The merit, compared in order: plausible, supported, the smallest scale in raw units.
    let mut best: Option<((bool, bool, f64), P::Fit)> = None;
    for Seed {
        fit,
        scale,
        support,
    } in fitted
    {
        let a = P::model(&fit).a;
        let merit = (
            plausible(&a),
            support >= SUPPORT_SHARE * most_support,
            -scale / mean_gain(&a),
        );
        if best.as_ref().is_none_or(|(m, _)| merit > *m) {
            best = Some((merit, fit));
        }
    }
    best.map(|(_, fit)| fit)
}

/// The plain fit of all samples, nothing excluded: what is left when no seed could be fitted.
fn fit_all<P: RobustProblem>(problem: &P) -> Result<Robust<P::Fit>, FitError> {
    let n = problem.len();
    let fit = problem.final_fit(&vec![true; n], None)?;
    let residual_ut = problem.residuals(&fit);
    let sigma_ut = scale::<P>(&residual_ut);
    Ok(Robust {
        fit,
        kept: vec![true; n],
        sigma_ut,
        residual_ut,
        mixed: Vec::new(),
    })
}

/// From `seed`, a few reweighting passes on (at most [`REWEIGHT_SAMPLES`] of) all samples, until the weights
/// settle: the fit, and the residuals of all samples under it.
fn reweight_all<P: RobustProblem>(problem: &P, seed: P::Fit) -> (P::Fit, Vec<f64>) {
    let mut fit = seed;
    let stride = problem.len().div_ceil(REWEIGHT_SAMPLES).max(1);
    let thin = (stride > 1).then(|| problem.every(stride));
    let reweighted = thin.as_ref().unwrap_or(problem);
    // Each per-sample vector is dropped before the next is made: memory stays at about two of them.
    let mut residual_ut = reweighted.residuals(&fit);
    for _ in 0..FULL_ITERATIONS {
        let w = biweight(&residual_ut, scale::<P>(&residual_ut));
        let quick = reweighted.quick_fit(&w, Some(&fit));
        drop(w);
        match quick {
            Ok(f) if plausible(&P::model(&f).a) || !plausible(&P::model(&fit).a) => fit = f,
            _ => break,
        }
        let residual_new = reweighted.residuals(&fit);
        // Settled: the next weights are within 1e-3 of those the fit was made with, so another fit would repeat it
        // (the seeds' reweighting stops by the same rule).
        let settled = weight_change::<P>(&residual_ut, &residual_new) < WEIGHTS_SETTLED;
        residual_ut = residual_new;
        if settled {
            break;
        }
    }
    drop(thin);
    if stride > 1 {
        refresh(problem, &fit, &mut residual_ut);
    }
    (fit, residual_ut)
}

/// The gross spans of all samples under `fit` (whose residuals are `residual_ut`) excluded and the rest fitted
/// plainly, from the fit before; again with the spans of the new fit, up to [`SPAN_PASSES`] times, until they
/// settle. Nothing is mixed yet.
fn exclude_gross_spans<P: RobustProblem>(
    problem: &P,
    fit: P::Fit,
    mut residual_ut: Vec<f64>,
    t_s: Option<&[f64]>,
) -> Result<Robust<P::Fit>, FitError> {
    let n = problem.len();
    let mut sigma_ut = scale::<P>(&residual_ut);
    let mut kept = outside(&gross_spans(&residual_ut, sigma_ut, t_s, P::RAMP_TAIL), n);
    let mut final_fit: Option<P::Fit> = None;
    for pass in 0..SPAN_PASSES {
        let start = final_fit.as_ref().unwrap_or(&fit);
        let (f, k) = fit_outside(problem, &residual_ut, sigma_ut, t_s, kept, start)?;
        refresh(problem, &f, &mut residual_ut);
        sigma_ut = scale::<P>(&residual_ut);
        final_fit = Some(f);
        let again = gross_spans(&residual_ut, sigma_ut, t_s, P::RAMP_TAIL);
        // The spans returned are those the final fit left out.
        let settled = is_outside(&k, &again);
        kept = if settled || pass + 1 == SPAN_PASSES {
            k
        } else {
            outside(&again, n)
        };
        if settled {
            break;
        }
    }
    Ok(Robust {
        fit: final_fit.expect("at least one pass"),
        kept,
        sigma_ut,
        residual_ut,
        mixed: Vec::new(),
    })
}

/// The windows of `robust`'s fit shifted too little to be gross ([`RobustProblem::shifted`]) set aside too, up to
/// [`SPAN_PASSES`] times, and the long runs of gross samples: each a state of its own fitted with the rest when the
/// problem can model one and that fit holds ([`own_states`]); else the shifted windows' fit without them replaces
/// the last one if it can be made, unless the samples left would cover too few of the directions
/// ([`SHIFT_KEEP_COVERAGE`]); then the windows stay in, as `robust.mixed`.
fn exclude_shifted_windows<P: RobustProblem>(problem: &P, robust: &mut Robust<P::Fit>) {
    prefer_the_ends(problem, robust);
    // The states found so far: a magnet on the board for a third of the recording is a gross run.
    let mut states: Vec<(usize, usize)> = Vec::new();
    let n = robust.kept.len();
    let mut runs = excluded_runs(&robust.kept);
    runs.retain(|(a, b)| (b - a) as f64 >= STATE_MIN_SHARE * n as f64);
    runs.sort_by_key(|(a, b)| std::cmp::Reverse(b - a));
    for run in runs.into_iter().take(MAX_SHIFTS) {
        let windows: Vec<_> = states.iter().copied().chain([run]).collect();
        if let Some((own, rest)) = own_states(problem, robust, &windows, None) {
            (robust.fit, robust.residual_ut, robust.kept) = (own.fit, own.residual_ut, rest);
            states = own.windows;
            robust.sigma_ut = scale::<P>(&robust.residual_ut);
        }
    }
    for _ in 0..SPAN_PASSES {
        let windows = problem.shifted(&robust.fit, &robust.kept);
        if windows.is_empty() {
            break;
        }
        let mut k = robust.kept.clone();
        for &(a, b) in &windows {
            k[a..b].fill(false);
        }
        let without = problem.final_fit(&k, Some(&robust.fit)).ok();
        let all: Vec<_> = states.iter().chain(&windows).copied().collect();
        if let Some((own, rest)) = own_states(problem, robust, &all, without.as_ref()) {
            (robust.fit, robust.residual_ut, robust.kept) = (own.fit, own.residual_ut, rest);
            states = own.windows;
            robust.sigma_ut = scale::<P>(&robust.residual_ut);
            continue;
        }
        let Some(f) = without else {
            break;
        };
        // Windows that hold most of the directions are where the recording calibrates: what is left of it,
        // and the shift it shows against them, are those of a partial recording.
        if problem.covered(&f, &k) < SHIFT_KEEP_COVERAGE * problem.covered(&f, &robust.kept) {
            robust.mixed = windows;
            break;
        }
        refresh(problem, &f, &mut robust.residual_ut);
        robust.sigma_ut = scale::<P>(&robust.residual_ut);
        robust.fit = f;
        robust.kept = k;
        states.clear();
    }
}

/// A run of gross samples is tried as a state of its own when it holds at least this share of the recording:
/// enough turning to determine one.
const STATE_MIN_SHARE: f64 = 0.05;

/// The fit in which each of `windows` has a state of its own ([`RobustProblem::with_windows`]), of the samples
/// `robust` kept and those in the windows, from `without` (the fit without the windows, or `robust`'s): taken when
/// it keeps the gains ([`JOINT_GAIN_CHANGE`]), explains the windows' samples as well as the rest's ([`ENDS_SCALE`],
/// their medians) and the rest's nearly as well as `without` does ([`JOINT_REST_SCALE`]). The fit and the samples
/// kept (the windows' left out).
fn own_states<P: RobustProblem>(
    problem: &P,
    robust: &Robust<P::Fit>,
    windows: &[(usize, usize)],
    without: Option<&P::Fit>,
) -> Option<(OwnStates<P::Fit>, Vec<bool>)> {
    let own = problem.with_windows(without.unwrap_or(&robust.fit), &robust.kept, windows)?;
    let (j, e, located) = (&own.fit, &own.residual_ut, &own.windows);
    let mut rest = robust.kept.clone();
    let mut inside = vec![false; rest.len()];
    for &(a, b) in located {
        rest[a..b].fill(false);
        inside[a..b].fill(true);
    }
    let at_rest = median_where(e, &rest);
    let before = without.map_or(at_rest, |f| median_where(&problem.residuals(f), &rest));
    // A field on the board moves the centre; the sensor's gains stay as they were.
    let (a_joint, a_start) = (P::model(j).a, P::model(without.unwrap_or(&robust.fit)).a);
    let same_gains = plausible(&a_joint)
        && (mean_gain(&a_joint) / mean_gain(&a_start) - 1.0).abs() <= JOINT_GAIN_CHANGE;
    let one_sensor = same_gains
        && median_where(e, &inside) <= ENDS_SCALE * at_rest
        && at_rest <= JOINT_REST_SCALE * before;
    one_sensor.then_some((own, rest))
}

/// A fit that gives the shifted windows states of their own may explain the rest's samples this many times worse
/// (their median residual) than the fit without the windows: what the windows add to the shape costs the rest
/// nearly nothing when they are one sensor with it.
const JOINT_REST_SCALE: f64 = 1.02;

/// The fit with states of their own may change the mean gain from the fit it started from by at most this share: a
/// shape that keeps the rest's magnitude only by turning into a far larger sphere (a recording that turned through
/// few directions) is no second state of one sensor.
const JOINT_GAIN_CHANGE: f64 = 0.1;

/// The median of the finite `e` where `keep`.
fn median_where(e: &[f64], keep: &[bool]) -> f64 {
    let v: Vec<f64> = e
        .iter()
        .zip(keep)
        .filter(|(x, k)| **k && x.is_finite())
        .map(|(x, _)| *x)
        .collect();
    median(&v)
}

/// At most this share of the ends' samples may have been kept by the robust fit.
const ENDS_KEPT_SHARE: f64 = 0.1;
/// The ends' residuals may be this many times the kept state's (their medians) and be one state with it.
const ENDS_SCALE: f64 = 1.5;

/// A window is what comes and goes: when the samples `robust` kept lie between spans it left out at the start and
/// at the end of the recording (but for [`ENDS_KEPT_SHARE`] of theirs), and one calibration explains both ends
/// (their median residual within [`ENDS_SCALE`] of the kept samples' under the robust fit) from enough directions
/// ([`SHIFT_KEEP_COVERAGE`]), the ends are the sensor's own state and what lies between them a window (at most
/// [`SHIFT_LONG_MAX_SHARE`] of the samples), however much of the recording it holds: a magnet on the board for the
/// middle 60 % of it.
fn prefer_the_ends<P: RobustProblem>(problem: &P, robust: &mut Robust<P::Fit>) {
    let n = robust.kept.len();
    let runs = excluded_runs(&robust.kept);
    let (Some(&(_, head)), Some(&(tail, _))) = (runs.first(), runs.last()) else {
        return;
    };
    if tail <= head || (tail - head) as f64 > SHIFT_LONG_MAX_SHARE * n as f64 {
        return;
    }
    let mut ends = vec![false; n];
    ends[..head].fill(true);
    ends[tail..].fill(true);
    // The ends must be the other state: left out but for a few samples where it hardly showed.
    let ends_kept = robust.kept[..head]
        .iter()
        .chain(&robust.kept[tail..])
        .filter(|k| **k)
        .count();
    if ends_kept as f64 > ENDS_KEPT_SHARE * (head + n - tail) as f64 {
        return;
    }
    let Ok(f) = problem.final_fit(&ends, None) else {
        return;
    };
    let e = problem.residuals(&f);
    let one_state =
        median_where(&e, &ends) <= ENDS_SCALE * median_where(&robust.residual_ut, &robust.kept);
    if one_state
        && problem.covered(&f, &ends)
            >= SHIFT_KEEP_COVERAGE * problem.covered(&robust.fit, &robust.kept)
    {
        robust.sigma_ut = scale::<P>(&e);
        robust.residual_ut = e;
        robust.fit = f;
        robust.kept = ends;
    }
}

/// `problem`'s residuals under `fit` in place of `e`, whose memory goes first (one per-sample vector at a time).
fn refresh<P: RobustProblem>(problem: &P, fit: &P::Fit, e: &mut Vec<f64>) {
    drop(std::mem::take(e));
    *e = problem.residuals(fit);
}

/// The final fit without the samples not `kept`, from `start`. Excluding a span must never leave the recording
/// undetermined (its coverage is what a calibration stands on): if the fit without them is refused, the spans are
/// taken again at twice the scale, and so on, down to excluding nothing.
fn fit_outside<P: RobustProblem>(
    problem: &P,
    residual_ut: &[f64],
    sigma_ut: f64,
    t_s: Option<&[f64]>,
    mut kept: Vec<bool>,
    start: &P::Fit,
) -> Result<(P::Fit, Vec<bool>), FitError> {
    let mut factor = 1.0;
    loop {
        match problem.final_fit(&kept, Some(start)) {
            Ok(f) => return Ok((f, kept)),
            Err(e) if kept.iter().all(|k| *k) => return Err(e),
            Err(_) => {
                factor *= 2.0;
                kept = outside(
                    &gross_spans(residual_ut, factor * sigma_ut, t_s, P::RAMP_TAIL),
                    kept.len(),
                );
            }
        }
    }
}

/// The 0/1 weights of the samples `kept`.
pub fn weights_of(kept: &[bool]) -> Vec<f64> {
    kept.iter().map(|k| f64::from(u8::from(*k))).collect()
}

/// Whether `kept` is what [`outside`] makes of `spans` (in order of start and end, as [`gross_spans`] gives them),
/// without making it.
fn is_outside(kept: &[bool], spans: &[(usize, usize)]) -> bool {
    let mut at = 0;
    for &(a, b) in spans {
        debug_assert!(a <= b && at <= b, "spans in order");
        if kept[at.min(a)..a].contains(&false) || kept[a.max(at)..b].contains(&true) {
            return false;
        }
        at = b;
    }
    !kept[at..].contains(&false)
}

/// Per sample of `n`, whether it lies outside every span.
pub fn outside(spans: &[(usize, usize)], n: usize) -> Vec<bool> {
    let mut kept = vec![true; n];
    for &(a, b) in spans {
        kept[a..b].fill(false);
    }
    kept
}

/// The scale of residual sizes `e` and their gross spans ([`gross_spans`], with `t_s` and `tail`), for the state
/// most samples are in: `median_scale`, their median's. When fewer than half the usable samples lie within
/// [`GROSS_SIGMA`] of the scale of their mode ([`mode_scale`]; `median_in_mode` is the median size of unit noise
/// below [`MODE_WINDOW`]) — a consistent part of a mostly disturbed recording ([`consistent_part`]) — the mode's
/// scale, and the runs without lulls merged.
pub fn state_spans(
    e: &[f64],
    median_scale: f64,
    median_in_mode: f64,
    t_s: Option<&[f64]>,
    tail: f64,
) -> (f64, Vec<(usize, usize)>) {
    let mode = mode_scale_of(e, median_in_mode);
    let usable = e.iter().filter(|x| x.is_finite()).count();
    let within = e.iter().filter(|x| **x <= GROSS_SIGMA * mode).count();
    if 2 * within < usable {
        (mode, ramped_runs(e, mode, t_s, tail))
    } else {
        (median_scale, gross_spans(e, median_scale, t_s, tail))
    }
}

/// The gross spans of residual sizes `e` against the scale `sigma` (per axis): the samples beyond [`GROSS_SIGMA`],
/// merged across gaps of up to [`SPAN_GAP_S`] (or [`SPAN_GAP_SAMPLES`] without time), widened over their ramps
/// (neighbours beyond [`RAMP_SIGMA`], and on beyond them for `tail` times a ramp's length: see
/// [`RobustProblem::RAMP_TAIL`]), and merged across lulls shorter than [`GAP_SHARE`] of the mean of the spans around
/// them, as sample ranges `[start, end)`.
pub fn gross_spans(e: &[f64], sigma: f64, t_s: Option<&[f64]>, tail: f64) -> Vec<(usize, usize)> {
    let widened = ramped_runs(e, sigma, t_s, tail);
    // Lulls shorter than a share of the spans around them are part of one disturbance.
    let length = |(a, b): (usize, usize)| match t_s {
        Some(t) => t[b - 1] - t[a],
        None => (b - a) as f64,
    };
    let gap = |(_, b): (usize, usize), (c, _): (usize, usize)| match t_s {
        Some(t) => t[c] - t[b - 1],
        None => (c - b) as f64,
    };
    let mut out: Vec<(usize, usize)> = Vec::with_capacity(widened.len());
    for span in widened {
        match out.last_mut() {
            Some(last) if gap(*last, span) <= GAP_SHARE * (length(*last) + length(span)) / 2.0 => {
                last.1 = span.1
            }
            _ => out.push(span),
        }
    }
    out
}

/// The runs of gross samples of [`gross_spans`], widened over their ramps, before lulls between them are merged.
fn ramped_runs(e: &[f64], sigma: f64, t_s: Option<&[f64]>, tail: f64) -> Vec<(usize, usize)> {
    let gross = |i: usize| e[i].is_finite() && e[i] > GROSS_SIGMA * sigma;
    let ramp = |i: usize| e[i].is_finite() && e[i] > RAMP_SIGMA * sigma;
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for i in (0..e.len()).filter(|&i| gross(i)) {
        let near = |end: usize| match t_s {
            Some(t) => t[i] - t[end - 1] <= SPAN_GAP_S,
            None => i - end < SPAN_GAP_SAMPLES,
        };
        match runs.last_mut() {
            Some(run) if near(run.1) => run.1 = i + 1,
            _ => runs.push((i, i + 1)),
        }
    }
    let mut widened: Vec<(usize, usize)> = Vec::with_capacity(runs.len());
    for k in 0..runs.len() {
        let (mut a, mut b) = runs[k];
        let floor = widened.last().map_or(0, |s| s.1);
        let ceiling = runs.get(k + 1).map_or(e.len(), |r| r.0);
        while a > floor && ramp(a - 1) {
            a -= 1;
        }
        while b < ceiling && ramp(b) {
            b += 1;
        }
        // The ramp goes on below the threshold, `tail` times as far again.
        let (ra, rb) = runs[k];
        a = a
            .saturating_sub(((ra - a) as f64 * tail) as usize)
            .max(floor);
        b = (b + ((b - rb) as f64 * tail) as usize).min(ceiling);
        widened.push((a, b));
    }
    widened
}

/// The seeds' spans: all samples, and contiguous sixths, thirds, halves and two-thirds at offsets of a sixth.
fn seed_spans(n: usize) -> Vec<(usize, usize)> {
    let mut spans = vec![(0, n)];
    for len6 in [1usize, 2, 3, 4] {
        for start6 in 0..=(6 - len6) {
            spans.push((start6 * n / 6, (start6 + len6) * n / 6));
        }
    }
    spans
}

/// From the fit on `w0`: concentration steps (the fit on the half of the samples it fits best, at most
/// [`TRIM_STEPS`] times), then IRLS with the biweight: the fit and the scale of its residual, or `None` if the
/// first fit fails.
fn reweight<P: RobustProblem>(p: &P, w0: &[f64], iterations: usize) -> Option<(P::Fit, f64)> {
    let mut fit = p.quick_fit(w0, None).ok()?;
    let mut kept_prev: Vec<bool> = Vec::new();
    for _ in 0..TRIM_STEPS {
        let e = p.residuals(&fit);
        let cut = quantile(&e, TRIM_SHARE);
        let kept: Vec<bool> = e.iter().map(|x| x.is_finite() && *x <= cut).collect();
        // Settled: at most 1 % of the samples changed sides (the biweight's passes take it from there).
        let moved = kept.iter().zip(&kept_prev).filter(|(a, b)| a != b).count();
        if !kept_prev.is_empty() && moved * TRIM_SETTLED <= kept.len() {
            break;
        }
        let w = weights_of(&kept);
        let Ok(next) = p.quick_fit(&w, None) else {
            break;
        };
        if plausible(&P::model(&fit).a) && !plausible(&P::model(&next).a) {
            break;
        }
        fit = next;
        kept_prev = kept;
    }
    let mut w_prev = w0.to_vec();
    for _ in 0..iterations {
        let e = p.residuals(&fit);
        let w = biweight(&e, scale::<P>(&e));
        let change = w
            .iter()
            .zip(&w_prev)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let Ok(next) = p.quick_fit(&w, None) else {
            break;
        };
        // Reweighting can wander off to a matrix that explains a still stretch and part of a disturbance: a
        // plausible fit is not given up for an implausible one.
        if plausible(&P::model(&fit).a) && !plausible(&P::model(&next).a) {
            break;
        }
        fit = next;
        if change < WEIGHTS_SETTLED {
            break;
        }
        w_prev = w;
    }
    let e = p.residuals(&fit);
    Some((fit, scale::<P>(&e)))
}

/// The residual's scale: the median residual size over the usable samples, as a standard deviation per axis. Each
/// sample counts as much as the next, so the state the recording is in most of the time sets it — still stretches
/// included, which is what tells a clean state from a magnet attached while the sensor was turned most.
pub(crate) fn scale<P: RobustProblem>(e: &[f64]) -> f64 {
    median(e) / P::MEDIAN_OF_UNIT
}

/// Values up to which the median is taken from a copy; above, by [`median_by_bins`].
const MEDIAN_COPY_MAX: usize = 1 << 16;

/// The median of the finite values of `e` (the `len / 2`-th smallest by `f64::total_cmp`; NaN if none).
pub(crate) fn median(e: &[f64]) -> f64 {
    if e.len() > MEDIAN_COPY_MAX {
        return median_by_bins(e);
    }
    let mut v: Vec<u64> = e
        .iter()
        .filter(|x| x.is_finite())
        .map(|x| order_key(*x))
        .collect();
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    from_order_key(*v.select_nth_unstable(mid).1)
}

/// [`median`] without a copy of `e`: the finite values are counted by the leading bits of their key (bins a
/// sixteenth of an octave wide), and only those of the bin the median falls in are kept and ordered.
fn median_by_bins(e: &[f64]) -> f64 {
    const BITS: u32 = 16;
    const SLICE: usize = 1 << 18;
    let bin = |x: f64| (order_key(x) >> (64 - BITS)) as usize;
    let counts = e
        .par_chunks(SLICE)
        .map(|part| {
            let mut c = vec![0u32; 1 << BITS];
            for x in part.iter().filter(|x| x.is_finite()) {
                c[bin(*x)] += 1;
            }
            c
        })
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
            a
        })
        .unwrap_or_default();
    let finite: usize = counts.iter().map(|c| *c as usize).sum();
    if finite == 0 {
        return f64::NAN;
    }
    let mut rank = finite / 2;
    let mut at = 0;
    while rank >= counts[at] as usize {
        rank -= counts[at] as usize;
        at += 1;
    }
    let mut v: Vec<u64> = e
        .par_iter()
        .filter(|x| x.is_finite() && bin(**x) == at)
        .map(|x| order_key(*x))
        .collect();
    from_order_key(*v.select_nth_unstable(rank).1)
}

/// A key whose order as an unsigned integer is the order of `f64::total_cmp`.
fn order_key(x: f64) -> u64 {
    let bits = x.to_bits();
    if bits >> 63 == 1 {
        !bits
    } else {
        bits | 1 << 63
    }
}

/// The value of an [`order_key`].
fn from_order_key(key: u64) -> f64 {
    f64::from_bits(if key >> 63 == 1 {
        key & !(1 << 63)
    } else {
        !key
    })
}

/// The `q` quantile of the finite values of `e` (NaN if none).
pub(crate) fn quantile(e: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = e.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    let k = ((v.len() - 1) as f64 * q) as usize;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// Tukey's biweight of residual sizes `e` against the scale `s`.
fn biweight(e: &[f64], s: f64) -> Vec<f64> {
    let c = BIWEIGHT_SIGMA * s.max(f64::MIN_POSITIVE);
    e.iter().map(|x| tukey(x / c)).collect()
}

/// Tukey's biweight of a residual in units of the cut-off.
fn tukey(u: f64) -> f64 {
    if u.is_finite() && u < 1.0 {
        (1.0 - u * u).powi(2)
    } else {
        0.0
    }
}

/// The largest change of a sample's biweight from residual sizes `before` to `after` (each against its own scale),
/// without making either vector of weights.
fn weight_change<P: RobustProblem>(before: &[f64], after: &[f64]) -> f64 {
    let c = |e: &[f64]| BIWEIGHT_SIGMA * scale::<P>(e).max(f64::MIN_POSITIVE);
    let (c0, c1) = (c(before), c(after));
    chunks::fold(
        before.len(),
        |range| {
            before[range.clone()]
                .iter()
                .zip(&after[range])
                .map(|(x, y)| (tukey(x / c0) - tukey(y / c1)).abs())
                .fold(0.0, f64::max)
        },
        f64::max,
    )
    .unwrap_or(0.0)
}

/// The runs of samples not `kept`, as ranges `[start, end)`.
pub fn excluded_runs(kept: &[bool]) -> Vec<(usize, usize)> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for (i, k) in kept.iter().enumerate() {
        match runs.last_mut() {
            _ if *k => {}
            Some(run) if run.1 == i => run.1 = i + 1,
            _ => runs.push((i, i + 1)),
        }
    }
    runs
}

/// A window of the residual is shifted when its scan statistic exceeds this (in units of the residual's long-run
/// variance, see [`long_run_variance`]; the χ² quantile of four degrees of freedom at 1e-6, one per term the scan
/// fits)…
const SHIFT_SCAN_PENALTY: f64 = 30.7;
/// …and the shift it fits is at least this many times the sensor's noise (RMS over the window): smaller ones are
/// within the field's own wander across a room as the sensor moves (up to 2.2 times in |B| on the physical
/// recordings), not a disturbance…
pub const SHIFT_MIN_NOISE: f64 = 3.0;
/// …and it holds at most this share of the samples scanned: a longer one is a drift of the offset or the room's
/// gradients along the path (on an undisturbed phone recording, windows of a third and a half of it), not a field
/// that came and went.
const SHIFT_MAX_SHARE: f64 = 0.25;
/// A window of more than [`SHIFT_MAX_SHARE`] and up to this share of the samples is a field on the board or in the
/// room only when its statistic exceeds [`SHIFT_LONG_PENALTY`] and it came and went (one that reaches an end of the
/// recording is a lasting change of the offset, which the diagnosis tests as a step); then the state the recording
/// starts and ends in is the sensor's own, however long the window between (a magnet on the board for the middle
/// 60 % of a recording; beyond this share, the ends are too short to calibrate on). A field of 8 µT on the board of
/// a hand-held sensor for a third of the recording stands at 1700, the offset drift of an undisturbed phone at 120.
const SHIFT_LONG_MAX_SHARE: f64 = 0.8;
/// The statistic a window longer than [`SHIFT_MAX_SHARE`] must exceed…
const SHIFT_LONG_PENALTY: f64 = 10.0 * SHIFT_SCAN_PENALTY;
/// Shifted windows are left out only if the samples left cover at least this share of the directions the samples
/// covered with them (seen from the fit without them): on the physical BROAD 02 recording, a 4 µT pass by a magnet
/// made the scan take 88 s holding most of the turning for a window (its statistic 313 against 307, its shift 3.6
/// times the noise against 3), and the minutes at rest left fitted A 0.4 off with a confident verdict.
const SHIFT_KEEP_COVERAGE: f64 = 0.5;
/// At most this many shifted windows are looked for.
const MAX_SHIFTS: usize = 4;

/// The windows where a signed residual `e` (in time order, the scalar method's magnitude) is shifted among the
/// `kept` samples, each found by a window scan on the samples the previous ones left, as sample ranges
/// `[start, end)`: while a field is fixed in the room for a while, |B| moves by a constant; while one is fixed to
/// the sensor, by `d·u` (`u`: the field's direction per sample, sensor axes), which averages out over a turning
/// window; either may be too small to be gross. `noise` is the noise of `e`. A method that can fit a window in a
/// state of its own gives `own_state`: the variance of the residual it then leaves ([`variance_with_wander`]),
/// which judges a long window when it is below what the scan's terms leave (a fit between the two states bends with
/// the shape, which those terms cannot follow).
pub fn shifted_windows(
    e: &[f64],
    u: &[[f64; 3]],
    kept: &[bool],
    noise: f64,
    own_state: Option<&dyn Fn((usize, usize)) -> Option<f64>>,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut free: Vec<bool> = kept
        .iter()
        .zip(e)
        .map(|(k, x)| *k && x.is_finite())
        .collect();
    for _ in 0..MAX_SHIFTS {
        let values = || e.iter().zip(&free).filter(|(_, f)| **f).map(|(x, _)| *x);
        let m = values().count() as f64;
        let sigma2 = variance_with_wander(values);
        let Some(found) = crate::scan::window_with_directions(e, u, &free, sigma2) else {
            break;
        };
        // The statistic against the noise the window leaves once fitted, when what it leaves turned through the
        // directions as the whole did (each state then determines its own terms): a long window shifts most blocks
        // of the residual it is scanned on (the fit without it sits between the two states), which the long-run
        // variance would otherwise count as the recording's own wander.
        let (a, b) = (found.scan.start, found.scan.end);
        let Some(inside) = window_fit(e, u, &free, (a, b)) else {
            break;
        };
        let len = free[a..b].iter().filter(|f| **f).count() as f64;
        let stat = if turned_outside(u, &free, (a, b)) {
            let own = own_state
                .filter(|_| len > SHIFT_MAX_SHARE * m)
                .and_then(|f| f((a, b)))
                .unwrap_or(f64::INFINITY);
            found.scan.stat * sigma2 / inside.variance.min(own).max(f64::MIN_POSITIVE)
        } else {
            found.scan.stat
        };
        // A long window must come and go: it explains the samples better than the same shift from its start to
        // the end of the recording, or from the beginning to its end, by as much as a short one must explain.
        let came_and_went = || {
            [(a, e.len()), (0, b)].iter().all(|&w| {
                window_fit(e, u, &free, w).is_some_and(|one_sided| {
                    (one_sided.rss - inside.rss) / inside.variance >= SHIFT_SCAN_PENALTY
                })
            })
        };
        let acceptable = if len <= SHIFT_MAX_SHARE * m {
            stat >= SHIFT_SCAN_PENALTY
        } else {
            len <= SHIFT_LONG_MAX_SHARE * m && stat >= SHIFT_LONG_PENALTY && came_and_went()
        };
        if !acceptable || found.terms_rms < SHIFT_MIN_NOISE * noise {
            break;
        }
        // The window from its first to its last free sample.
        let Some(first) = (a..b).find(|&i| free[i]) else {
            break;
        };
        let last = (a..b).rev().find(|&i| free[i]).expect("a free sample");
        free[first..=last].fill(false);
        out.push((first, last + 1));
        if len > SHIFT_MAX_SHARE * m {
            // The residual was of a fit between the two states: what else it shows needs the fit without this one.
            break;
        }
    }
    out
}

/// The variance per sample of the residual `x()` yields (in time order) about its mean: the sample variance, or the
/// long-run one ([`long_run_variance`]) when the residual wanders, the larger.
pub fn variance_with_wander<I: Iterator<Item = f64>>(x: impl Fn() -> I) -> f64 {
    let n = x().count() as f64;
    let mean = x().sum::<f64>() / n;
    let sample = x().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    sample.max(long_run_variance(x().map(|v| v - mean)))
}

/// Samples per block of [`long_run_variance`].
const LONG_RUN_BLOCK: usize = 50;

/// The variance of a mean of `x` per sample, from the spread of its means over blocks of
/// [`LONG_RUN_BLOCK`] samples (their median absolute size, as a standard deviation): a residual that wanders slowly
/// (a hand-held sensor moved through a room's field gradients) has one above its sample variance, and a few shifted
/// blocks do not raise it.
fn long_run_variance(x: impl Iterator<Item = f64>) -> f64 {
    let mut means = Vec::new();
    let (mut sum, mut count) = (0.0, 0);
    for v in x {
        sum += v;
        count += 1;
        if count == LONG_RUN_BLOCK {
            means.push((sum / LONG_RUN_BLOCK as f64).abs());
            (sum, count) = (0.0, 0);
        }
    }
    if means.is_empty() {
        return 0.0;
    }
    let mid = means.len() / 2;
    let sd = *means.select_nth_unstable_by(mid, f64::total_cmp).1 / 0.674_49;
    sd * sd * LONG_RUN_BLOCK as f64
}

/// Whether the samples `free` outside the window `[a, b)` turned through the directions as all of them did: the
/// smallest principal variance of the field's direction `u` outside it at least [`SHIFT_KEEP_COVERAGE`] of all the
/// samples'. A window that holds the turning leaves rests, whose few poses the scan's terms fit whatever they hold:
/// on the undisturbed physical BROAD 02 recording the turning between two rests stood at 1455 against the noise they
/// left (163 against the residual's).
fn turned_outside(u: &[[f64; 3]], free: &[bool], (a, b): (usize, usize)) -> bool {
    let spread = |keep: &dyn Fn(usize) -> bool| {
        let (mut n, mut sum, mut outer) =
            (0.0, nalgebra::Vector3::zeros(), nalgebra::Matrix3::zeros());
        for i in (0..u.len()).filter(|&i| free[i] && keep(i)) {
            let x = nalgebra::Vector3::from(u[i]);
            n += 1.0;
            sum += x;
            outer += x * x.transpose();
        }
        let mean: nalgebra::Vector3<f64> = sum / f64::max(n, 1.0);
        let cov: nalgebra::Matrix3<f64> = outer / f64::max(n, 1.0) - mean * mean.transpose();
        cov.symmetric_eigenvalues().min()
    };
    spread(&|i| !(a..b).contains(&i)) >= SHIFT_KEEP_COVERAGE * spread(&|_| true)
}

/// A window `[a, b)` of [`shifted_windows`]' terms fitted to the residual `e` among the samples `free`: `e`
/// regressed on a constant and the field's direction `u` everywhere and again inside the window. `None` if the fit
/// is singular.
fn window_fit(
    e: &[f64],
    u: &[[f64; 3]],
    free: &[bool],
    (a, b): (usize, usize),
) -> Option<WindowFit> {
    type Terms = nalgebra::SVector<f64, 8>;
    let terms = |i: usize| {
        let [x, y, z] = u[i];
        let inside = f64::from(u8::from((a..b).contains(&i)));
        Terms::from([1.0, x, y, z, inside, inside * x, inside * y, inside * z])
    };
    let used = || (0..e.len()).filter(|&i| free[i]);
    let (mut xx, mut xr) = (nalgebra::SMatrix::<f64, 8, 8>::zeros(), Terms::zeros());
    for i in used() {
        let x = terms(i);
        xx += x * x.transpose();
        xr += x * e[i];
    }
    let beta = xx.try_inverse()? * xr;
    let left = || used().map(|i| e[i] - terms(i).dot(&beta));
    let rss = left().map(|x| x * x).sum::<f64>();
    let variance = (rss / used().count() as f64).max(long_run_variance(left()));
    Some(WindowFit { rss, variance })
}

/// What a window's fit leaves ([`window_fit`]): the residual's sum of squares and its variance per sample (the
/// sample variance or the long-run one, the larger).
struct WindowFit {
    rss: f64,
    variance: f64,
}

/// Whether a matrix's gains are within [`PLAUSIBLE_GAIN_RATIO`] of each other.
pub fn plausible(a: &Mat3) -> bool {
    let m = nalgebra::Matrix3::from_fn(|j, k| a[j][k]);
    let sv = m.singular_values();
    sv.min() > 0.0 && sv.max() / sv.min() <= PLAUSIBLE_GAIN_RATIO
}

/// The geometric mean of `A`'s singular values: the gain from raw to calibrated units.
fn mean_gain(a: &Mat3) -> f64 {
    let m = nalgebra::Matrix3::from_fn(|j, k| a[j][k]);
    m.determinant().abs().cbrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line fit `y = a·x + b` as a robust problem (a 1-D stand-in for the calibration).
    struct Line {
        x: Vec<f64>,
        y: Vec<f64>,
    }

    impl RobustProblem for Line {
        type Fit = (f64, f64);
        const MEDIAN_OF_UNIT: f64 = 0.6745;
        const MEDIAN_OF_UNIT_IN_MODE: f64 = 0.6724;
        fn len(&self) -> usize {
            self.x.len()
        }
        fn every(&self, stride: usize) -> Line {
            Line {
                x: self.x.iter().step_by(stride).copied().collect(),
                y: self.y.iter().step_by(stride).copied().collect(),
            }
        }
        fn quick_fit(&self, w: &[f64], _: Option<&(f64, f64)>) -> Result<(f64, f64), FitError> {
            let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for i in 0..self.len() {
                sw += w[i];
                sx += w[i] * self.x[i];
                sy += w[i] * self.y[i];
                sxx += w[i] * self.x[i] * self.x[i];
                sxy += w[i] * self.x[i] * self.y[i];
            }
            let det = sw * sxx - sx * sx;
            if det.abs() < 1e-12 {
                return Err(FitError::Singular("line"));
            }
            let a = (sw * sxy - sx * sy) / det;
            Ok((a, (sy - a * sx) / sw))
        }
        fn final_fit(
            &self,
            kept: &[bool],
            start: Option<&(f64, f64)>,
        ) -> Result<(f64, f64), FitError> {
            self.quick_fit(&weights_of(kept), start)
        }
        fn residuals(&self, f: &(f64, f64)) -> Vec<f64> {
            (0..self.len())
                .map(|i| (self.y[i] - f.0 * self.x[i] - f.1).abs())
                .collect()
        }
        fn model(f: &(f64, f64)) -> Model {
            Model::linear(
                [[f.0, 0.0, 0.0], [0.0, f.0, 0.0], [0.0, 0.0, f.0]],
                [f.1; 3],
            )
        }
    }

    fn line(n: usize, disturbed: std::ops::Range<usize>) -> Line {
        let x: Vec<f64> = (0..n).map(|i| ((i * 37) % 101) as f64 / 10.0).collect();
        let noise = |i: usize| ((i * 7919) % 13) as f64 / 13.0 - 0.5;
        let y = (0..n)
            .map(|i| {
                let clean = 2.0 * x[i] + 1.0 + 0.1 * noise(i);
                if disturbed.contains(&i) {
                    clean + 30.0
                } else {
                    clean
                }
            })
            .collect();
        Line { x, y }
    }

    /// 2x + 1 with a little noise, and for 80 % of the samples, in ten stretches spread through them, a field that
    /// grows from 10 to 50 as a source comes closer, one way or the other: the majority follows the disturbances,
    /// the consistent part is the line.
    fn mostly_disturbed(n: usize) -> Line {
        let mut l = line(n, 0..0);
        for i in 0..n {
            let stretch = i / (n / 10);
            let within = (i % (n / 10)) as f64 / (n / 10) as f64;
            if within >= 0.2 {
                let u = (within - 0.2) / 0.8;
                let sign = if stretch.is_multiple_of(2) { 1.0 } else { -1.0 };
                l.y[i] += sign * (10.0 + 40.0 * u);
            }
        }
        l
    }

    #[test]
    fn the_consistent_part_of_a_mostly_disturbed_line_is_found_and_holds() {
        let l = mostly_disturbed(5000);
        let part = consistent_part(&l, None).expect("a part");
        assert!(
            (part.fit.0 - 2.0).abs() < 0.01 && (part.fit.1 - 1.0).abs() < 0.05,
            "{:?}",
            part.fit
        );
        let kept = part.kept.iter().filter(|k| **k).count();
        assert!((900..=1100).contains(&kept), "{kept}");
        assert_eq!(holds_out(&l, &part, None), PartCheck::Holds);
        // The diagnosis' spans of that fit's residual are the mode's: the lulls are not merged away.
        let (scale, spans) = state_spans(
            &part.residual_ut,
            f64::NAN,
            Line::MEDIAN_OF_UNIT_IN_MODE,
            None,
            0.0,
        );
        assert!(scale < 0.1 && spans.len() == 10, "{scale} {}", spans.len());
    }

    #[test]
    fn a_clean_line_keeps_the_median_scale_and_its_spans() {
        let clean = line(5000, 0..0);
        let e = clean.residuals(&(2.0, 1.0));
        let median_scale = scale::<Line>(&e);
        let (s, spans) = state_spans(&e, median_scale, Line::MEDIAN_OF_UNIT_IN_MODE, None, 0.0);
        assert_eq!(
            (s, spans),
            (median_scale, gross_spans(&e, median_scale, None, 0.0))
        );
    }

    #[test]
    fn a_disturbance_over_45_percent_of_the_samples_cannot_capture_the_fit() {
        let p = line(2000, 500..1400);
        let r = fit(&p, None).unwrap();
        assert!(
            (r.fit.0 - 2.0).abs() < 0.01 && (r.fit.1 - 1.0).abs() < 0.05,
            "{:?}",
            r.fit
        );
        assert_eq!(r.excluded(), 900);
        assert!(r.kept[..500].iter().all(|k| *k) && r.kept[500..1400].iter().all(|k| !*k));
    }

    #[test]
    fn the_state_a_recording_starts_and_ends_in_is_its_own_though_the_middle_holds_most() {
        // The middle 60 % on another state (something on the board while the sensor turned): the majority's fit
        // leaves out both ends, which one line explains — they are the calibration, the middle the window.
        let p = line(2000, 400..1600);
        let t: Vec<f64> = (0..2000).map(|i| i as f64 * 0.01).collect();
        let r = fit(&p, Some(&t)).unwrap();
        assert!(
            (r.fit.0 - 2.0).abs() < 0.01 && (r.fit.1 - 1.0).abs() < 0.05,
            "{:?}",
            r.fit
        );
        assert!(r.kept[..400].iter().chain(&r.kept[1600..]).all(|k| *k));
        assert!(r.kept[400..1600].iter().all(|k| !*k));
        // Without time (no order to tell the ends by), the majority's state stands.
        let r = fit(&p, None).unwrap();
        assert!((r.fit.1 - 31.0).abs() < 0.05, "{:?}", r.fit);
    }

    #[test]
    fn disturbances_in_every_third_of_the_recording_cannot_capture_the_fit() {
        // 48 % disturbed, every seed of a third or more holds some of it; the sixth 1500..2000 is clean.
        let disturbed = [200..450, 600..900, 1100..1400, 2100..2400, 2600..2900];
        let mut p = line(3000, 0..0);
        for r in disturbed {
            for i in r {
                p.y[i] += 30.0;
            }
        }
        let r = fit(&p, None).unwrap();
        assert!(
            (r.fit.0 - 2.0).abs() < 0.01 && (r.fit.1 - 1.0).abs() < 0.05,
            "{:?}",
            r.fit
        );
        assert_eq!(r.excluded(), 1450);
    }

    #[test]
    fn the_median_by_bins_is_the_median_of_a_copy() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [1, 2, 3, 1000, MEDIAN_COPY_MAX + 1, 300_001] {
            // Residual sizes, signed values, ties, non-finite values and values spread over many octaves.
            let sizes: Vec<f64> = (0..n)
                .map(|_| rng.random_range(0.0..3.0_f64).powi(2))
                .collect();
            let signed: Vec<f64> = (0..n).map(|_| rng.random_range(-1e3..1e3)).collect();
            let ties: Vec<f64> = (0..n).map(|i| (i % 7) as f64).collect();
            let holes: Vec<f64> = sizes
                .iter()
                .enumerate()
                .map(|(i, x)| match i % 5 {
                    0 => f64::NAN,
                    1 => f64::INFINITY,
                    _ => *x,
                })
                .collect();
            let spread: Vec<f64> = (0..n)
                .map(|_| 10f64.powf(rng.random_range(-30.0..30.0)))
                .collect();
            for e in [sizes, signed, ties, holes, spread] {
                let mut v: Vec<f64> = e.iter().copied().filter(|x| x.is_finite()).collect();
                let want = if v.is_empty() {
                    f64::NAN
                } else {
                    let mid = v.len() / 2;
                    *v.select_nth_unstable_by(mid, f64::total_cmp).1
                };
                let got = median_by_bins(&e);
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "n {n}: {got} {want}"
                );
                assert!(median(&e).to_bits() == want.to_bits() || want.is_nan());
            }
        }
        assert!(median_by_bins(&[f64::NAN; 10]).is_nan());
    }

    #[test]
    fn a_magnets_tail_goes_with_its_span_and_a_steps_edge_does_not_widen() {
        // Noise-free residual sizes against a scale of 1: a magnet passed at constant speed (40 at closest, falling
        // off as the distance cubed) at sample 500, and a step of 20 from 800 to 900.
        let pass = |i: usize| {
            let u = (i as f64 - 500.0) / 20.0;
            40.0 / (1.0 + u * u).powf(1.5)
        };
        let e: Vec<f64> = (0..1000)
            .map(|i| pass(i) + if (800..900).contains(&i) { 20.0 } else { 0.0 })
            .collect();
        let first_below = |level: f64| (500..800).find(|&i| pass(i) < level).unwrap();
        let bare = gross_spans(&e, 1.0, None, 0.0);
        let tailed = gross_spans(&e, 1.0, None, 2.0);
        assert_eq!(bare.len(), 2, "{bare:?}");
        assert_eq!(tailed.len(), 2, "{tailed:?}");
        // Without a tail the span ends where the pass falls below 3; with twice the ramp, near 1.
        assert_eq!(bare[0].1, first_below(RAMP_SIGMA));
        let reached = pass(tailed[0].1);
        assert!((0.8..1.3).contains(&reached), "{tailed:?}: {reached}");
        assert!(
            (500 - tailed[0].0).abs_diff(tailed[0].1 - 1 - 500) <= 1,
            "symmetric: {tailed:?}"
        );
        // The step has no ramp: its span is the step, tail or not.
        assert_eq!(bare[1], (800, 900));
        assert_eq!(tailed[1], (800, 900));
    }

    #[test]
    fn is_outside_says_whether_kept_is_outside_the_spans() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..2000 {
            let n: usize = rng.random_range(0..40);
            // Spans in order, some touching or overlapping the one before.
            let mut spans: Vec<(usize, usize)> = Vec::new();
            let mut at: usize = 0;
            while n > 0 && rng.random_bool(0.6) {
                let start = spans.last().map_or(0, |s| s.0);
                let a = (at + rng.random_range(0..4))
                    .saturating_sub(2)
                    .clamp(start, n);
                let b = (a + rng.random_range(0..6)).clamp(at, n);
                spans.push((a, b));
                at = b;
            }
            let exact = outside(&spans, n);
            assert!(is_outside(&exact, &spans), "{spans:?}");
            let mut other = exact.clone();
            if n > 0 {
                let i = rng.random_range(0..n);
                other[i] = !other[i];
                assert!(!is_outside(&other, &spans), "{spans:?} with {i} flipped");
            }
        }
    }

    /// White noise of unit variance, `n` samples.
    fn white(n: usize, seed: u64) -> Vec<f64> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| StandardNormal.sample(&mut rng)).collect()
    }

    /// A field direction that turns about a tilted axis once every `period` samples, `n` samples.
    fn turning(n: usize, period: f64) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / period;
                let (s, c) = a.sin_cos();
                [0.8 * c, 0.8 * s, 0.6]
            })
            .collect()
    }

    #[test]
    fn a_shifted_window_is_found_and_noise_alone_finds_none() {
        let kept = vec![true; 4000];
        let u = turning(4000, 500.0);
        for seed in 0..5 {
            assert_eq!(
                shifted_windows(&white(4000, seed), &u, &kept, 1.0, None),
                vec![]
            );
        }
        let mut e = white(4000, 9);
        for x in &mut e[1200..1600] {
            *x += 5.0;
        }
        let found = shifted_windows(&e, &u, &kept, 1.0, None);
        assert_eq!(found.len(), 1, "{found:?}");
        let (a, b) = found[0];
        assert!(a.abs_diff(1200) <= 5 && b.abs_diff(1600) <= 5, "{found:?}");
        // The samples not kept are not looked at: the window there is not found.
        let mut kept = kept;
        kept[1100..1700].fill(false);
        assert_eq!(shifted_windows(&e, &u, &kept, 1.0, None), vec![]);
    }

    #[test]
    fn a_field_fixed_to_the_sensor_is_a_shifted_window_though_it_averages_out() {
        // 6 noise along the sensor's x axis: in |B| it is 6·u_x, which turns through ±4.8 and averages to zero
        // over each turn of the window.
        let u = turning(4000, 200.0);
        let mut e = white(4000, 4);
        for (x, d) in e[2000..2600].iter_mut().zip(&u[2000..2600]) {
            *x += 6.0 * d[0];
        }
        let found = shifted_windows(&e, &u, &vec![true; 4000], 1.0, None);
        assert_eq!(found.len(), 1, "{found:?}");
        let (a, b) = found[0];
        assert!(
            a.abs_diff(2000) <= 20 && b.abs_diff(2600) <= 20,
            "{found:?}"
        );
    }

    #[test]
    fn a_slow_wander_is_not_a_shifted_window() {
        // A residual that wanders by ±6 noise over 2000 samples: as a hand-held sensor moved through a room's field.
        let e: Vec<f64> = white(8000, 3)
            .iter()
            .enumerate()
            .map(|(i, x)| x + 6.0 * (i as f64 * std::f64::consts::TAU / 2000.0).sin())
            .collect();
        let u = turning(8000, 700.0);
        assert_eq!(
            shifted_windows(&e, &u, &vec![true; 8000], 1.0, None),
            vec![]
        );
    }

    #[test]
    fn a_field_on_the_board_for_a_third_of_the_recording_is_a_shifted_window() {
        // 8 noise along x from 3000 to 5700 of 8000 samples: longer than a quarter, but it came and went and stands
        // far above the residual's wander (a magnet 3 cm from a hand-held sensor's chip for a minute).
        let n = 8000;
        let u = turning(n, 400.0);
        let mut e = white(n, 6);
        for (x, d) in e[3000..5700].iter_mut().zip(&u[3000..5700]) {
            *x += 8.0 * d[0];
        }
        let found = shifted_windows(&e, &u, &vec![true; n], 1.0, None);
        assert_eq!(found.len(), 1, "{found:?}");
        let (a, b) = found[0];
        assert!(
            a.abs_diff(3000) <= 20 && b.abs_diff(5700) <= 20,
            "{found:?}"
        );
    }

    #[test]
    fn a_field_on_the_board_for_three_fifths_of_the_recording_is_a_shifted_window() {
        // 8 noise along x from 1600 to 6400 of 8000 samples, the residual of a fit between the two states (the
        // window's shift less its mean): it came and went, and the noise it leaves once fitted is the sensor's.
        let n = 8000;
        let u = turning(n, 400.0);
        let mut e = white(n, 7);
        for (i, (x, d)) in e.iter_mut().zip(&u).enumerate() {
            *x += 8.0 * d[0] * if (1600..6400).contains(&i) { 0.4 } else { -0.6 };
        }
        let found = shifted_windows(&e, &u, &vec![true; n], 1.0, None);
        assert_eq!(found.len(), 1, "{found:?}");
        let (a, b) = found[0];
        assert!(
            a.abs_diff(1600) <= 20 && b.abs_diff(6400) <= 20,
            "{found:?}"
        );
    }

    #[test]
    fn a_lasting_change_of_the_offset_is_not_a_shifted_window() {
        // The offset moves by 6 noise along x for the last 40 % of the recording (a drift, or a step the diagnosis
        // tests): no window to leave out.
        let n = 8000;
        let u = turning(n, 400.0);
        let mut e = white(n, 5);
        for (x, d) in e[4800..].iter_mut().zip(&u[4800..]) {
            *x += 6.0 * d[0];
        }
        assert_eq!(shifted_windows(&e, &u, &vec![true; n], 1.0, None), vec![]);
    }

    #[test]
    fn the_scale_is_the_median_by_total_order() {
        let e: Vec<f64> = (0..1001)
            .map(|i| ((i * 7919) % 1009) as f64 * 0.37 - 50.0)
            .chain([f64::NAN, f64::INFINITY, -0.0, 0.0])
            .collect();
        let mut v: Vec<f64> = e.iter().copied().filter(|x| x.is_finite()).collect();
        let mid = v.len() / 2;
        let median = *v.select_nth_unstable_by(mid, f64::total_cmp).1;
        assert_eq!(scale::<Line>(&e), median / Line::MEDIAN_OF_UNIT);
    }

    #[test]
    fn without_disturbances_it_is_least_squares() {
        let p = line(2000, 0..0);
        let r = fit(&p, None).unwrap();
        assert_eq!(r.excluded(), 0);
        assert_eq!(r.fit, p.quick_fit(&vec![1.0; 2000], None).unwrap());
    }
}
