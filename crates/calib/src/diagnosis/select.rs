//! Choosing the effects: each candidate is tested against the current model by a Wald test with a BIC complexity
//! penalty *and* by blocked cross-validation; the best passing candidate joins the model, greedily, until none passes.
//! Candidates the base model absorbs are set aside; candidates that explain the same residual as the one chosen are
//! reported as ambiguous.
//!
//! Every fit here carries the errors-in-variables correction. Without it, least squares shrinks `A` by σ²/spread²,
//! and any regressor built from the (noise-free) reference — a cubic in the field, say — acts as an instrument that
//! "explains" that shrinkage: on simulated null recordings uncorrected fits flagged a non-linearity 24 times in 60.
//! In the scalar method the observation (the magnitude's residual) shares the reading's noise with every regressor,
//! and the correction also takes out their covariance from `Xᵀy` (a cubic in the field, whose noise grows with the
//! field squared, otherwise "explained" it in 3 % of null recordings).
//! The corrected estimate is not the least-squares minimum, so a likelihood ratio of residual sums is not a valid
//! test for it; the Wald statistic of its parameters with their covariance is.
//!
//! Real recordings have residuals that are alike from one sample to the next (reference alignment and timing errors,
//! hand motion), and such residuals carry less evidence than independent ones: the Wald statistic is divided by the
//! residual's integrated autocorrelation factor, measured by batch means for each fitted model (about 1 on white
//! noise, so simulated white-noise recordings are judged as before).

use nalgebra::{DMatrix, DVector};

use crate::FitError;

use super::candidates::Candidate;
use super::setup::Setup;
use super::stats::{Problem, Solution};

/// Below this unabsorbed fraction a candidate is "absorbed — not testable with this data".
pub(crate) const ABSORBED_BELOW: f64 = 0.02;
/// A candidate must explain at least this share of the current residual's excess variance over the noise floor on
/// held-out data: a statistically clear but physically marginal fit to some structure of the residual is not offered
/// as the missing physics.
pub(crate) const MIN_EXCESS_SHARE: f64 = 0.05;
/// …at least this share in the scalar method's magnitude, where the excess is no reference's error but something
/// left in the recording (a magnet's tail over the whole path, the room's gradients): a candidate that explains
/// less of it may be fitting that instead. (Simulated disturbed benches: a current bias that explained 16 % of a
/// magnet's tail made the clean held-out fit 35 % worse than the base fit.)
pub(crate) const MIN_EXCESS_SHARE_MAGNITUDE: f64 = 0.25;
/// …and at least this share of the current held-out residual variance itself: an improvement nobody could notice
/// (0.357 → 0.356 µT) is not a finding, however significant.
const MIN_GAIN_SHARE: f64 = 0.01;
/// A local effect (a step, a window, a curve of the response) must be at least this many times the reference's
/// own error (the clean residual's excess over the sensor's noise): a smooth wander of the reference mimics one up
/// to about that size.
pub(crate) const LOCAL_OVER_REFERENCE: f64 = 3.0;
/// The noise floor is measured to a few per cent: a residual variance within this share above it is noise, not
/// the reference's error.
const NOISE_FLOOR_SLACK: f64 = 0.1;
/// Two candidates whose evidence differs by less than this (σ² units, plus a share of the evidence) are ambiguous.
const AMBIGUITY_MARGIN: f64 = 10.0;
const AMBIGUITY_SHARE: f64 = 0.02;

/// One accepted step of the greedy selection.
#[derive(Clone, Debug)]
pub(crate) struct Step {
    /// The candidate added.
    pub cand: usize,
    /// The candidate it replaced (a generalisation such as per-axis lags replacing one lag).
    pub replaced: Option<usize>,
    /// Residual sum of squares before and after.
    pub rss: (f64, f64),
    /// Held-out residual sum of squares before and after.
    pub cv: (f64, f64),
    /// Evidence: the Wald statistic minus the complexity penalty, σ² units.
    pub evidence: f64,
}

/// How a candidate fared when set aside.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum SetAside {
    /// Its regressor is zero throughout the recording.
    NotExcited,
    /// The base model absorbs all but this fraction of it; the base columns that take it up most.
    Absorbed {
        unabsorbed: f64,
        takes_up: &'static str,
    },
}

/// The outcome of the selection.
#[derive(Clone, Debug)]
pub(crate) struct Selection {
    pub steps: Vec<Step>,
    /// Pairs (chosen, alternative) that explain the same residual.
    pub ambiguous: Vec<(usize, usize)>,
    pub set_aside: Vec<(usize, SetAside)>,
    pub base: Solution,
    pub base_cv: f64,
    /// The final model's solution.
    pub last: Solution,
    pub last_cv: f64,
}

struct Trial {
    cand: usize,
    replaced: Option<usize>,
    columns: Vec<usize>,
    sol: Solution,
    cv: f64,
    /// Wald statistic of the candidate's parameters.
    wald: f64,
    /// Parameters it adds.
    extra: f64,
    /// Autocorrelation factor of its residual.
    tau: f64,
    /// Evidence, once the round's autocorrelation factor is known.
    evidence: f64,
}

impl Trial {
    /// Evidence with the autocorrelation factor `tau`: neighbouring residuals that are alike carry less evidence
    /// than independent ones, so the Wald statistic and the sample count are divided by it.
    fn judge(&mut self, tau: f64, rows: f64, scan_penalty: f64) {
        self.evidence = self.wald / tau - self.extra * (rows / tau).ln() - scan_penalty;
    }
}

/// Stage 5 for a round: the base columns with the forced candidates' (the modelled spans'), then [`select`] with
/// the method's share of the excess.
pub(crate) fn stage(
    setup: &Setup<'_>,
    problem: &Problem,
    cands: &[Candidate],
) -> Result<Selection, FitError> {
    let mut base_columns: Vec<usize> = (0..setup.n_base).collect();
    for c in cands.iter().filter(|c| c.forced) {
        base_columns.extend(c.columns());
    }
    select(
        problem,
        &base_columns,
        cands,
        &setup.a_columns(),
        setup.noise_floor_ut.powi(2),
        if setup.vector {
            MIN_EXCESS_SHARE
        } else {
            MIN_EXCESS_SHARE_MAGNITUDE
        },
    )
    .ok_or(FitError::Singular(
        "the diagnosis' base problem has no solution",
    ))
}

/// Selects effects; `floor2` is the noise floor's variance per row (µT²), `min_excess_share` the share of the
/// excess over it a candidate must explain ([`MIN_EXCESS_SHARE`] or [`MIN_EXCESS_SHARE_MAGNITUDE`]).
pub(crate) fn select(
    problem: &Problem,
    base_columns: &[usize],
    cands: &[Candidate],
    a_columns: &[usize],
    floor2: f64,
    min_excess_share: f64,
) -> Option<Selection> {
    let base = problem.solve(base_columns, None, true)?;
    let base_cv = problem.cv_rss(base_columns)?;
    let (eligible, set_aside) = eligible(problem, base_columns, cands, a_columns);
    let trials = Trials { problem, cands };
    let mut columns = base_columns.to_vec();
    let (mut current, mut current_cv) = (base.clone(), base_cv);
    let mut chosen: Vec<usize> = Vec::new();
    let mut steps = Vec::new();
    let mut ambiguous = Vec::new();
    loop {
        let mut round: Vec<Trial> = eligible
            .iter()
            .copied()
            .filter(|c| !chosen.contains(c))
            .filter_map(|c| trials.try_add(&columns, &chosen, c))
            .collect();
        // One autocorrelation factor per round, so that candidates are compared on equal terms (each trial's own
        // estimate is noisy, ±15 % on white noise): the whitest residual's, that of the best explanation.
        let tau = round.iter().map(|t| t.tau).fold(f64::INFINITY, f64::min);
        for t in &mut round {
            t.judge(tau, trials.rows(), cands[t.cand].scan_penalty);
        }
        let significant: Vec<Trial> = round.into_iter().filter(|t| t.evidence > 0.0).collect();
        let Some(best) = significant
            .iter()
            .filter(|t| {
                t.cv < current_cv && trials.material(t, current_cv, floor2, min_excess_share)
            })
            .max_by(|a, b| a.evidence.total_cmp(&b.evidence))
        else {
            break;
        };
        for alt in significant.iter().filter(|t| t.cand != best.cand) {
            if trials.explains_the_same(best, alt, &chosen, tau, current_cv) {
                ambiguous.push((best.cand, alt.cand));
            }
        }
        steps.push(Step {
            cand: best.cand,
            replaced: best.replaced,
            rss: (current.rss, best.sol.rss),
            cv: (current_cv, best.cv),
            evidence: best.evidence,
        });
        if let Some(r) = best.replaced {
            chosen.retain(|&k| k != r);
        }
        chosen.push(best.cand);
        columns = best.columns.clone();
        current = best.sol.clone();
        current_cv = best.cv;
    }
    Some(Selection {
        steps,
        ambiguous,
        set_aside,
        base,
        base_cv,
        last: current,
        last_cv: current_cv,
    })
}

/// The candidates that may be selected, and those set aside: not excited (their regressors are zero throughout), or
/// absorbed by the base model (`base_columns`; `a_columns` are `A`'s, to say which part takes them up).
fn eligible(
    problem: &Problem,
    base_columns: &[usize],
    cands: &[Candidate],
    a_columns: &[usize],
) -> (Vec<usize>, Vec<(usize, SetAside)>) {
    let rows = problem.total.rows as f64;
    let mut set_aside = Vec::new();
    let mut eligible = Vec::new();
    for (c, cand) in cands.iter().enumerate().filter(|(_, c)| !c.forced) {
        let cols: Vec<usize> = cand.columns().collect();
        let energy: f64 = cols.iter().map(|&i| problem.total.xtx[(i, i)]).sum();
        if energy <= 1e-18 * rows {
            set_aside.push((c, SetAside::NotExcited));
            continue;
        }
        let unabsorbed = problem.unabsorbed_fraction(base_columns, &cols);
        if unabsorbed < ABSORBED_BELOW {
            let takes_up = takes_up(problem, base_columns, &cols, a_columns);
            set_aside.push((
                c,
                SetAside::Absorbed {
                    unabsorbed,
                    takes_up,
                },
            ));
        } else {
            eligible.push(c);
        }
    }
    (eligible, set_aside)
}

/// Trial fits of candidates added to a model.
struct Trials<'p> {
    problem: &'p Problem,
    cands: &'p [Candidate],
}

impl Trials<'_> {
    /// Rows of the problem.
    fn rows(&self) -> f64 {
        self.problem.total.rows as f64
    }

    /// Candidate `c` added to the model of `columns` (the `chosen` candidates'), replacing the one it generalises.
    fn try_add(&self, columns: &[usize], chosen: &[usize], c: usize) -> Option<Trial> {
        let (problem, cands) = (self.problem, self.cands);
        let cand = &cands[c];
        let replaced = cand
            .supersedes
            .and_then(|id| chosen.iter().copied().find(|&k| cands[k].id() == id));
        let mut cols: Vec<usize> = columns
            .iter()
            .copied()
            .filter(|i| replaced.is_none_or(|r| !cands[r].columns().contains(i)))
            .collect();
        cols.extend(cand.columns());
        let sol = problem.solve(&cols, None, true)?;
        let extra = cand.n as f64 - replaced.map_or(0.0, |r| cands[r].n as f64);
        let wald = wald(&sol, cand, replaced.is_some(), self.rows());
        let tau = problem.autocorrelation(&sol);
        let cv = problem.cv_rss(&cols)?;
        Some(Trial {
            cand: c,
            replaced,
            columns: cols,
            sol,
            cv,
            wald,
            extra,
            tau,
            evidence: f64::NAN,
        })
    }

    /// Whether a trial is material, beyond significant, against the model's held-out residual `current_cv`: it
    /// explains [`MIN_EXCESS_SHARE`] (or `min_excess_share`) of the excess over the noise floor `floor2` and
    /// [`MIN_GAIN_SHARE`] of the residual itself, and a local effect stands [`LOCAL_OVER_REFERENCE`] times above
    /// the reference's own error.
    fn material(&self, t: &Trial, current_cv: f64, floor2: f64, min_excess_share: f64) -> bool {
        let problem = self.problem;
        let clean_rows = problem.clean_total.rows.max(1) as f64;
        let excess = (current_cv / clean_rows - floor2).max(0.0);
        // The reference's own error with the candidate in the model: what would remain beyond the noise (less the
        // noise floor's own uncertainty).
        let reference2 =
            (problem.clean_rss(&t.sol) / clean_rows - (1.0 + NOISE_FLOOR_SLACK) * floor2).max(0.0);
        let gain = current_cv - t.cv;
        gain / clean_rows >= min_excess_share * excess
            && gain >= MIN_GAIN_SHARE * current_cv
            && (!self.cands[t.cand].local()
                || size2(&t.sol, &self.cands[t.cand], problem)
                    >= LOCAL_OVER_REFERENCE.powi(2) * reference2)
    }

    /// Whether `alt` explains the same residual as `best`, chosen over it: about as strong as the chosen one (or
    /// stronger, but not borne out on held-out data against `current_cv`), and explained away by it or failing
    /// cross-validation. A candidate that generalises the other is not an alternative.
    fn explains_the_same(
        &self,
        best: &Trial,
        alt: &Trial,
        chosen: &[usize],
        tau: f64,
        current_cv: f64,
    ) -> bool {
        let cands = self.cands;
        let close =
            best.evidence - alt.evidence < AMBIGUITY_MARGIN + AMBIGUITY_SHARE * best.evidence;
        let nested = cands[alt.cand].supersedes == Some(cands[best.cand].id())
            || cands[best.cand].supersedes == Some(cands[alt.cand].id());
        if !close || nested {
            return false;
        }
        let mut with_best = chosen.to_vec();
        with_best.push(best.cand);
        let explained = self
            .try_add(&best.columns, &with_best, alt.cand)
            .is_none_or(|mut t| {
                t.judge(tau, self.rows(), cands[alt.cand].scan_penalty);
                t.evidence <= 0.0
            });
        explained || alt.cv >= current_cv
    }
}

/// The mean square per row of a candidate's perturbation in a fit, over the rows where it acts (µT²).
pub(crate) fn size2(sol: &Solution, cand: &Candidate, problem: &Problem) -> f64 {
    let idx: Vec<(usize, usize)> = cand
        .columns()
        .filter_map(|c| sol.columns.iter().position(|&x| x == c).map(|p| (p, c)))
        .collect();
    let x = &problem.total.xtx;
    let mut quad = 0.0;
    for &(p, i) in &idx {
        for &(q, j) in &idx {
            quad += sol.beta[p] * x[(i, j)] * sol.beta[q];
        }
    }
    quad / cand.active_rows.max(1) as f64
}

/// The Wald statistic of a candidate's parameters in a fit: all zero, or — when it replaces an effect it generalises
/// (per-axis lags replacing one lag) — all equal.
pub(crate) fn wald(sol: &Solution, cand: &Candidate, generalises: bool, rows: f64) -> f64 {
    let idx: Vec<usize> = cand
        .columns()
        .filter_map(|c| sol.columns.iter().position(|&x| x == c))
        .collect();
    if idx.is_empty() {
        return 0.0;
    }
    let s2 = sol.rss / (rows - sol.columns.len() as f64).max(1.0);
    let theta = DVector::from_iterator(idx.len(), idx.iter().map(|&p| sol.beta[p]));
    let cov = DMatrix::from_fn(idx.len(), idx.len(), |r, c| {
        sol.inverse[(idx[r], idx[c])] * s2
    });
    // Restriction R·θ = 0: θ = 0, or successive differences θ_k − θ_(k+1) = 0.
    let r = if generalises {
        DMatrix::from_fn(idx.len() - 1, idx.len(), |i, j| {
            if j == i {
                1.0
            } else if j == i + 1 {
                -1.0
            } else {
                0.0
            }
        })
    } else {
        DMatrix::identity(idx.len(), idx.len())
    };
    let rt = &r * &theta;
    let Some(inv) = (&r * cov * r.transpose()).try_inverse() else {
        return 0.0;
    };
    (rt.transpose() * inv * rt)[(0, 0)]
}

/// Which part of the base model takes up an absorbed candidate: the share of the projected candidate's energy carried
/// by the `A` columns against the offset columns.
fn takes_up(
    problem: &Problem,
    base: &[usize],
    cand: &[usize],
    a_columns: &[usize],
) -> &'static str {
    let Some(coef) = problem.absorption_coefficients(base, cand) else {
        return "the base fit";
    };
    let x = &problem.total.xtx;
    let energy = |subset: &dyn Fn(usize) -> bool| -> f64 {
        let mut e = 0.0;
        for k in 0..cand.len() {
            for (r, &i) in base.iter().enumerate() {
                for (s, &j) in base.iter().enumerate() {
                    if subset(i) && subset(j) {
                        e += coef[(r, k)] * x[(i, j)] * coef[(s, k)];
                    }
                }
            }
        }
        e
    };
    let in_a = |i: usize| a_columns.contains(&i);
    let e_a = energy(&in_a);
    let e_b = energy(&|i| !in_a(i));
    if e_b >= e_a {
        "the offset b"
    } else {
        "the matrix A (scale, soft iron, misalignment)"
    }
}

#[cfg(test)]
mod tests {
    use super::super::candidates::{self, candidates};
    use super::super::problem::accumulate;
    use super::super::testbench::{Bench, with_setup};
    use super::*;
    use crate::effects::{Effect, EffectId};

    /// The selection on a bench with `effects`, and the candidates' ids.
    fn selection(effects: &[Effect], seed: u64) -> (Selection, Vec<EffectId>) {
        let bench = Bench::new(3000, effects, seed);
        with_setup(&bench, |setup, residual| {
            let all = vec![true; setup.samples.len()];
            let offer = candidates::offer(setup, residual, &all, Vec::new());
            let (mut cands, _) = candidates(&offer, setup.n_base);
            let problem = accumulate(setup, &mut cands, &all, &all);
            let sel = stage(setup, &problem, &cands).unwrap();
            (sel, cands.iter().map(Candidate::id).collect())
        })
    }

    #[test]
    fn the_effect_in_the_recording_is_chosen_and_nothing_in_a_null_one() {
        let (sel, ids) = selection(
            &[Effect::CurrentBias {
                channel: 0,
                coef_ut_per_a: [0.3, 0.0, -0.2],
            }],
            9,
        );
        assert_eq!(sel.steps.len(), 1, "{:?}", sel.steps);
        let step = &sel.steps[0];
        assert_eq!(ids[step.cand], EffectId::CurrentBias);
        assert!(step.evidence > 0.0 && step.cv.1 < step.cv.0 && step.rss.1 < step.rss.0);
        assert!(sel.last_cv < sel.base_cv);
        let (sel, _) = selection(&[], 10);
        assert!(sel.steps.is_empty(), "{:?}", sel.steps);
        assert_eq!(sel.last_cv, sel.base_cv);
    }

    #[test]
    fn the_wald_statistic_is_the_squared_coefficients_over_their_variance() {
        // Fifteen columns, the candidate's the last three, with unit inverse and a residual variance of 0.25.
        let rows = 1015.0;
        let sol = Solution {
            columns: (0..15).collect(),
            beta: DVector::from_fn(15, |k, _| {
                if k >= 12 {
                    [1.0, -2.0, 2.0][k - 12]
                } else {
                    0.5
                }
            }),
            inverse: DMatrix::identity(15, 15),
            rss: 0.25 * (rows - 15.0),
        };
        let cand = Candidate {
            template: Effect::BiasDrift {
                rate_ut_per_s: [0.0; 3],
                t_ref_s: 0.0,
            },
            n: 3,
            first: 12,
            channel: None,
            supersedes: None,
            scan_penalty: 0.0,
            scan: None,
            forced: false,
            active_rows: 0,
        };
        assert!((wald(&sol, &cand, false, rows) - 9.0 / 0.25).abs() < 1e-9);
        // As a generalisation, only the differences count: (1 − (−2))² + (−2 − 2)² under their covariance.
        let diffs = wald(&sol, &cand, true, rows);
        let want = (DMatrix::from_row_slice(1, 2, &[3.0, -4.0])
            * DMatrix::from_row_slice(2, 2, &[2.0, -1.0, -1.0, 2.0])
                .try_inverse()
                .unwrap()
            * DMatrix::from_row_slice(2, 1, &[3.0, -4.0]))[(0, 0)]
            / 0.25;
        assert!((diffs - want).abs() < 1e-9, "{diffs} against {want}");
    }
}
