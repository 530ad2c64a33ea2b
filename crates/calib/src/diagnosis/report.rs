//! Stage 7, the report of the settled round: the final linear part, each effect with its fitted parameters and
//! standard errors (scanned times located again on the final residual), the figures before and after it, the
//! ambiguities and the untestable effects, where the mismatch is, and the reference's own error.

use std::borrow::Cow;

use nalgebra::DMatrix;

use crate::effects::Effect;
use crate::frames::{self, Mat3};
use crate::model::Model;
use crate::scan;

use super::candidates::{self, Candidate, Untestable};
use super::explain::{self, Fate};
use super::findings::{
    Ambiguity, Diagnosis, FitSummary, FoundEffect, Glitch, GrossSpan, Rejected, Residuals, Verdict,
};
use super::fitted::{linear_of, linear_se, params_of};
use super::gross::Span;
use super::locate::{self, Components, Located, Segment};
use super::rounds::Round;
use super::samples::Samples;
use super::select::{self, SetAside, Step};
use super::setup::Setup;
use super::stats::{Problem, Rows, Solution};

/// An effect in the final model: its candidate, the effect with its fitted parameters, and their standard errors.
type Chosen = (usize, Effect, [f64; 3]);

/// The fits the report is made of.
struct Fits {
    /// The final model's solution.
    last: Solution,
    /// Rows of the problem, and of its clean part (at least one).
    rows: f64,
    clean_rows: f64,
    /// The final residual's autocorrelation factor.
    tau_last: f64,
    /// The base fit on the clean samples alone, and its held-out residual sum of squares there.
    base12: Solution,
    base_cv: f64,
    /// The final solution's covariance from its residual's variance ([`Problem::model_covariance`]) and its
    /// cluster-robust one ([`Problem::cluster_covariance`]).
    model_cov: DMatrix<f64>,
    cluster: Option<DMatrix<f64>>,
    /// The final linear part.
    ext_a: Mat3,
    ext_b: [f64; 3],
}

impl Fits {
    fn of(setup: &Setup<'_>, round: &Round) -> Fits {
        let problem = &round.problem;
        let linear: Vec<usize> = (0..setup.n_base).collect();
        let clean_rows = problem.clean_total.rows.max(1) as f64;
        let last = round.sel.last.clone();
        let rows = problem.total.rows as f64;
        // The residual's autocorrelation factor, for the scanned times' errors (the coefficients' covariances allow
        // for it themselves).
        let tau_last = problem.autocorrelation(&last);
        // The base fit on the clean samples alone, and its held-out residual there.
        let base12 = problem
            .solve_on(Rows::Clean, &linear, None, true)
            .unwrap_or_else(|| round.sel.base.clone());
        let base_cv = problem
            .cv_rss_on(Rows::Clean, &linear)
            .unwrap_or(round.sel.base_cv);
        let (ext_a, ext_b) = final_linear(setup, &last, &base12);
        let model_cov = problem.model_covariance(&last);
        let cluster = problem.cluster_covariance(&last);
        Fits {
            last,
            rows,
            clean_rows,
            tau_last,
            base12,
            base_cv,
            model_cov,
            cluster,
            ext_a,
            ext_b,
        }
    }

    /// The standard error of the final solution's coefficient of `column`: the larger of its two variances, as for
    /// the linear part ([`linear_se`]); NaN if the column is not in the solution.
    fn se(&self, column: usize) -> f64 {
        let Some(p) = self.last.columns.iter().position(|&c| c == column) else {
            return f64::NAN;
        };
        let robust = self.cluster.as_ref().map_or(0.0, |m| m[(p, p)]);
        self.model_cov[(p, p)].max(robust).max(0.0).sqrt()
    }

    /// The RMS of a residual sum of squares over the clean rows, µT.
    fn rms(&self, rss: f64) -> f64 {
        (rss / self.clean_rows).sqrt()
    }
}

/// The final linear part: the base fit's moved by what the effects change in this problem's least squares (`last`
/// against `base12`, the clean rows' base fit). Without effects it is the base fit itself (whose scalar solver has a
/// shape prior and direction weights the linearised problem does not). In the vector method with effects, this
/// problem's fit is the base fit's least squares with the effects modelled, on the rows it includes, and is the
/// final one: moved from the base fit by the difference to the clean rows' fit, it took back in the pull of rows the
/// robust fit kept and this problem explains (a field on the board that the reference's own error hid in places) or
/// leaves out (it once did so for want of one row: a gross sample the diagnosis left out put A 0.058 off on BROAD 02
/// with 5.6 µT on its board).
fn final_linear(setup: &Setup<'_>, last: &Solution, base12: &Solution) -> (Mat3, [f64; 3]) {
    let (vector, base) = (setup.vector, &setup.base);
    if vector && last.columns.len() > setup.n_base {
        return linear_of(last, vector, base, setup.raw_mean);
    }
    let (a1, b1) = linear_of(last, vector, base, setup.raw_mean);
    let (a0, b0) = linear_of(base12, vector, base, setup.raw_mean);
    let a: Mat3 =
        std::array::from_fn(|j| std::array::from_fn(|k| base.a[j][k] + a1[j][k] - a0[j][k]));
    let b: [f64; 3] = std::array::from_fn(|j| base.b_ut[j] + b1[j] - b0[j]);
    (a, b)
}

/// Stage 7: the report of the settled round; `base_residual` is the base fit's per sample, `rejected` the effects
/// the guard dropped. The per-sample vectors the samples hold (`rows`, `t_s`, `direction`) are left for the caller
/// to move in.
pub(crate) fn report(
    setup: &Setup<'_>,
    mut round: Round,
    base_residual: Vec<[f64; 3]>,
    rejected: Vec<Rejected>,
) -> Diagnosis {
    let fits = Fits::of(setup, &round);
    let steps = steps_in_model(&round);
    let mut chosen = chosen(&round, &steps, &fits);
    relocate(
        setup,
        &mut round.cands,
        &round.clean,
        &mut chosen,
        (&fits.ext_a, fits.ext_b),
        fits.last.rss / fits.rows,
    );
    let all: Vec<Effect> = chosen.iter().map(|c| c.1).collect();
    let final_residual = setup.residual(&fits.ext_a, fits.ext_b, &all);
    let sizes = sizes(setup, &chosen, &final_residual);
    let dims = if setup.vector { 3 } else { 1 };
    let extended = Components::from_residuals(final_residual, dims);
    let (model, effects) = found_effects(setup, &round, &chosen, &steps, &sizes, &fits);
    let ambiguous = ambiguities(&round);
    let untestable = untestable(&mut round);
    let channels = setup.channels();
    let (located, base_rows, used) = located(setup, &round, base_residual, &channels);
    let spans: Vec<GrossSpan> = round
        .spans
        .iter()
        .map(|sp| gross_span(setup, sp, Fate::Calibration))
        .collect();
    let glitches: Vec<Glitch> = round.glitches.iter().map(|g| glitch(setup, g)).collect();
    let located = Located {
        segments: spans
            .iter()
            .map(|sp| Segment {
                t0_s: sp.t0_s,
                t1_s: sp.t1_s,
                rms_ut: sp.rms_ut,
            })
            .collect(),
        ..located
    };
    let problem = &round.problem;
    let reference_floor_ut = (fits.rms(problem.clean_rss(&fits.last)).powi(2)
        - setup.noise_floor_ut.powi(2))
    .max(0.0)
    .sqrt();
    let verdict = if effects.is_empty() && spans.is_empty() {
        Verdict::Consistent
    } else {
        Verdict::Mismatch
    };
    let n = setup.samples.len();
    let excluded: Vec<bool> = round.included.iter().map(|i| !i).collect();
    let extended_fit = summary(
        setup,
        problem,
        &fits.last,
        (&fits.ext_a, fits.ext_b),
        round.sel.last_cv,
    );
    let se = extended_fit.se;
    let modelled = !effects.is_empty();
    Diagnosis {
        verdict,
        effects,
        ambiguous,
        untestable,
        located,
        base: summary(
            setup,
            problem,
            &fits.base12,
            (&setup.base.a, setup.base.b_ut),
            fits.base_cv,
        ),
        extended: FitSummary {
            // On a thinned recording the problem's covariance is of the samples the diagnosis looked at: it
            // describes a model fitted on them, not the base fit of every row that stands when nothing was found.
            se: se.filter(|_| setup.samples.stride == 1 || modelled),
            ..extended_fit
        },
        model,
        noise_floor_ut: setup.noise_floor_ut,
        reference_floor_ut,
        spans,
        glitches,
        rejected,
        samples_used: used,
        samples_excluded: n - used,
        samples_left_out: setup.samples.left_out,
        // Filled by `diagnose`.
        residuals: Residuals {
            rows: Vec::new(),
            t_s: Vec::new(),
            direction: Vec::new(),
            base: base_rows,
            extended,
            channels,
            excluded,
            stride: 1,
        },
    }
}

/// A fit's summary: its linear part `(a, b)`, their standard errors from `sol`, and its residual and held-out
/// residual (`cv`, a sum of squares) on the clean rows.
fn summary(
    setup: &Setup<'_>,
    problem: &Problem,
    sol: &Solution,
    (a, b): (&Mat3, [f64; 3]),
    cv: f64,
) -> FitSummary {
    let clean_rows = problem.clean_total.rows.max(1) as f64;
    let rms = |rss: f64| (rss / clean_rows).sqrt();
    FitSummary {
        a: *a,
        b_ut: b,
        se: Some(linear_se(
            problem,
            sol,
            setup.vector,
            (a, b),
            setup.raw_mean,
        )),
        rms_ut: rms(problem.clean_rss(sol)),
        holdout_rms_ut: rms(cv),
    }
}

/// The selection's steps still in the model (not replaced by a generalisation), in the order chosen.
fn steps_in_model(round: &Round) -> Vec<Step> {
    round
        .sel
        .steps
        .iter()
        .filter(|st| !round.sel.steps.iter().any(|o| o.replaced == Some(st.cand)))
        .cloned()
        .collect()
}

/// The effects with their fitted parameters and standard errors: the modelled spans', then the catalogue's in the
/// order chosen (`steps`).
fn chosen(round: &Round, steps: &[Step], fits: &Fits) -> Vec<Chosen> {
    let forced: Vec<usize> = (0..round.cands.len())
        .filter(|&c| round.cands[c].forced)
        .collect();
    forced
        .iter()
        .copied()
        .chain(steps.iter().map(|st| st.cand))
        .map(|c| {
            let cand = &round.cands[c];
            let mut se = [0.0; 3];
            for (k, x) in se.iter_mut().enumerate().take(cand.n) {
                *x = fits.se(cand.first + k);
            }
            (c, round.fitted_effect(c, &fits.last), se)
        })
        .collect()
}

/// The final model (the body-fixed effects as corrections) and each effect as found, with its figures.
fn found_effects(
    setup: &Setup<'_>,
    round: &Round,
    chosen: &[Chosen],
    steps: &[Step],
    sizes: &[(f64, f64)],
    fits: &Fits,
) -> (Model, Vec<FoundEffect>) {
    let mut model = Model::linear(fits.ext_a, fits.ext_b);
    let mut effects = Vec::new();
    for (k, (c, effect, se)) in chosen.iter().enumerate() {
        let cand = &round.cands[*c];
        if effect.id().is_correction() {
            model
                .add_correction(*effect)
                .expect("candidates are limited so that every body-fixed effect fits in a model");
        }
        let (rss, cv, evidence) = match steps.iter().find(|st| st.cand == *c) {
            Some(st) => (st.rss, st.cv, st.evidence),
            None => span_figures(setup, round, cand, effect, sizes[k].1, fits),
        };
        let holdout = (fits.rms(cv.0), fits.rms(cv.1));
        let what = explain::what(effect, cand.channel.as_deref(), setup.field_ut);
        effects.push(FoundEffect {
            explanation: explain::explain(&what, holdout, setup.noise_floor_ut),
            what,
            params: params_of(effect, *se, cand, fits.last.rss / fits.rows * fits.tau_last),
            effect: *effect,
            channel: cand.channel.clone(),
            rms_before_ut: fits.rms(rss.0),
            rms_after_ut: fits.rms(rss.1),
            holdout_rms_before_ut: holdout.0,
            holdout_rms_after_ut: holdout.1,
            evidence,
            size_ut: sizes[k].0,
        });
    }
    (model, effects)
}

/// A span's effect's figures as a selected effect's are (residual and held-out sums of squares before and after,
/// evidence): its samples are not in the clean held-out set, so its figures are the residual inside the span under
/// the base fit and under the final model (`inside`, µT), and its evidence the Wald statistic less the BIC penalty.
fn span_figures(
    setup: &Setup<'_>,
    round: &Round,
    cand: &Candidate,
    effect: &Effect,
    inside: f64,
    fits: &Fits,
) -> ((f64, f64), (f64, f64), f64) {
    let before = round
        .spans
        .iter()
        .find(|sp| {
            sp.modelled() && {
                let (t0, t1) = span_time(setup.samples, sp);
                t0 <= effect_t1(effect) && effect_t0(effect) <= t1
            }
        })
        .map_or(inside, |sp| sp.rms_ut);
    let sq = |x: f64| x * x * fits.clean_rows;
    let (rows, tau) = (fits.rows, fits.tau_last);
    let evidence =
        select::wald(&fits.last, cand, false, rows) / tau - cand.n as f64 * (rows / tau).ln();
    ((sq(before), sq(inside)), (sq(before), sq(inside)), evidence)
}

/// The pairs of effects that explain the same residual, with why and the experiment that would separate them.
fn ambiguities(round: &Round) -> Vec<Ambiguity> {
    round
        .sel
        .ambiguous
        .iter()
        .map(|&(a, b)| {
            let ids = [round.cands[a].id(), round.cands[b].id()];
            let (why, experiment) = explain::separate(ids[0], ids[1]);
            Ambiguity {
                ids,
                why,
                experiment,
            }
        })
        .collect()
}

/// The effects this recording cannot test: those no candidate was offered for, then those set aside (not excited,
/// or absorbed by the base model).
fn untestable(round: &mut Round) -> Vec<Untestable> {
    let mut untestable = std::mem::take(&mut round.untestable);
    for (c, why) in &round.sel.set_aside {
        let cand = &round.cands[*c];
        let name = cand
            .channel
            .as_deref()
            .map_or(String::new(), |ch| format!(" ({ch})"));
        untestable.push(Untestable {
            id: cand.id(),
            why: match why {
                SetAside::NotExcited => {
                    format!("not excited{name}: {}", cand.id().descriptor().not_excited)
                }
                SetAside::Absorbed {
                    unabsorbed,
                    takes_up,
                } => format!(
                    "absorbed — not testable with this data{name}: the base fit takes up {:.1} % of it, so it would \
                     bias {takes_up}",
                    100.0 * (1.0 - unabsorbed)
                ),
            },
        });
    }
    untestable
}

/// Where the mismatch is, on the samples the calibration used (the samples themselves when all are; its segments are
/// left for the gross spans); the base residual's components (`base_residual`, moved in); and how many samples were
/// used.
fn located(
    setup: &Setup<'_>,
    round: &Round,
    base_residual: Vec<[f64; 3]>,
    channels: &[(String, Vec<f64>)],
) -> (Located, Components, usize) {
    let s = setup.samples;
    let n = s.len();
    let dims = if setup.vector { 3 } else { 1 };
    let floor_axes: Vec<f64> = if setup.vector {
        setup.input.noise.calibrated_ut(&setup.base.a).to_vec()
    } else {
        vec![setup.noise_floor_ut]
    };
    // The rows used, listed only when some are not (a list of every row is as large as a column).
    let all_used = round.included.iter().all(|&i| i);
    let used: Vec<usize> = if all_used {
        Vec::new()
    } else {
        (0..n).filter(|&i| round.included[i]).collect()
    };
    let used_only =
        (!all_used).then(|| Components::of(used.iter().map(|&i| &base_residual[i]), dims));
    let base_rows = Components::from_residuals(base_residual, dims);
    let used_rows = match used_only {
        Some(rows) => Cow::Owned(rows),
        None => Cow::Borrowed(&base_rows),
    };
    let pick = |v: &'_ [f64]| -> Vec<f64> { used.iter().map(|&i| v[i]).collect() };
    let used_channels: Vec<(&str, Cow<[f64]>)> = channels
        .iter()
        .map(|(name, v)| {
            let v = if all_used {
                Cow::Borrowed(v.as_slice())
            } else {
                Cow::Owned(pick(v))
            };
            (name.as_str(), v)
        })
        .collect();
    let used_dirs: Cow<[[f64; 3]]> = if all_used {
        Cow::Borrowed(&setup.unit)
    } else {
        Cow::Owned(used.iter().map(|&i| setup.unit[i]).collect())
    };
    let used_t: Option<Cow<[f64]>> = s.has_time.then(|| {
        if all_used {
            Cow::Borrowed(&s.t[..])
        } else {
            Cow::Owned(pick(&s.t))
        }
    });
    let channel_values: Vec<(&str, &[f64])> = used_channels
        .iter()
        .map(|(name, v)| (*name, &v[..]))
        .collect();
    let located = locate::locate(
        &used_rows,
        &floor_axes,
        used_t.as_deref(),
        &used_dirs,
        &channel_values,
    );
    drop(used_rows);
    (located, base_rows, if all_used { n } else { used.len() })
}

/// A scanned time was located on the base residual, which the base fit had partly bent to the effect; locate it
/// again on the extended fit's residual (`(ext_a, ext_b)` with every other effect removed; `sigma2` its variance per
/// row).
fn relocate(
    setup: &Setup<'_>,
    cands: &mut [Candidate],
    clean: &[bool],
    chosen: &mut [Chosen],
    (ext_a, ext_b): (&Mat3, [f64; 3]),
    sigma2: f64,
) {
    let s = setup.samples;
    for k in 0..chosen.len() {
        let (c, effect, _) = chosen[k];
        let scanned = matches!(effect, Effect::BiasStep { .. } | Effect::Disturbance { .. })
            && !cands[c].forced;
        if !scanned {
            continue;
        }
        let others: Vec<Effect> = chosen
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != k)
            .map(|(_, x)| x.1)
            .collect();
        let partial = setup.residual(ext_a, ext_b, &others);
        let clean_idx: Vec<usize> = (0..s.len()).filter(|&i| clean[i]).collect();
        let Some(w) = rescan(setup, effect, &partial, &clean_idx, sigma2) else {
            continue;
        };
        let w = w.through(&clean_idx, s.len());
        let is_window = matches!(effect, Effect::Disturbance { .. });
        cands[c].scan = Some(candidates::scan_times(s, &w, is_window));
        match &mut chosen[k].1 {
            Effect::BiasStep { t_s, .. } => *t_s = candidates::between(s, w.start),
            Effect::Disturbance { t0_s, t1_s, .. } => {
                *t0_s = candidates::between(s, w.start);
                *t1_s = candidates::between(s, w.end);
            }
            _ => {}
        }
    }
}

/// The scan of a step or window effect again, on the `clean_idx` samples of the residual `partial` (in their own
/// indices).
fn rescan(
    setup: &Setup<'_>,
    effect: Effect,
    partial: &[[f64; 3]],
    clean_idx: &[usize],
    sigma2: f64,
) -> Option<scan::Scan> {
    let e: Vec<[f64; 3]> = clean_idx.iter().map(|&i| partial[i]).collect();
    match (effect, setup.vector) {
        (Effect::BiasStep { .. }, true) => scan::step_vector(&e, sigma2),
        (Effect::BiasStep { .. }, false) => {
            let rho: Vec<f64> = e.iter().map(|x| x[0]).collect();
            let u: Vec<[f64; 3]> = clean_idx.iter().map(|&i| setup.unit[i]).collect();
            scan::step_scalar(&rho, &u, sigma2)
        }
        _ => setup.samples.rot().and_then(|rot| {
            let world: Vec<[f64; 3]> = clean_idx
                .iter()
                .map(|&i| frames::mat_vec(&rot.at(i), partial[i]))
                .collect();
            scan::window(&world, sigma2)
        }),
    }
}

/// Each effect's size (RMS per axis of its perturbation where it acts), and the final model's residual RMS per axis
/// where it acts (`residual`: the final model's, per sample).
fn sizes(setup: &Setup<'_>, chosen: &[Chosen], residual: &[[f64; 3]]) -> Vec<(f64, f64)> {
    let s = setup.samples;
    let dims = if setup.vector { 3.0 } else { 1.0 };
    chosen
        .iter()
        .map(|(_, effect, _)| {
            let (mut sum, mut left, mut count) = (0.0, 0.0, 0usize);
            for i in 0..s.len() {
                let d = effect.perturbation_ut(&s.context(i));
                let d2 = frames::dot(d, d);
                if d2 > 0.0 && d2.is_finite() {
                    sum += d2 / 3.0;
                    left += frames::dot(residual[i], residual[i]) / dims;
                    count += 1;
                }
            }
            let c = count.max(1) as f64;
            ((sum / c).sqrt(), (left / c).sqrt())
        })
        .collect()
}

/// A span as the report gives it, in words ([`explain::span`]), with its `fate`.
pub(crate) fn gross_span(setup: &Setup<'_>, sp: &Span, fate: Fate) -> GrossSpan {
    let s = setup.samples;
    let (t0_s, t1_s) = span_time(s, sp);
    let when = if s.has_time {
        format!("{t0_s:.2}–{t1_s:.2} s")
    } else {
        format!("samples {}–{}", sp.start, sp.end)
    };
    GrossSpan {
        t0_s,
        t1_s,
        samples: sp.end - sp.start,
        peak_ut: sp.peak_ut,
        rms_ut: sp.rms_ut,
        kind: sp.kind,
        modelled: fate == Fate::Calibration && sp.modelled(),
        explanation: explain::span(sp, &when, setup.vector, fate),
        kept_samples: 0,
    }
}

/// A glitch as the report gives it.
pub(crate) fn glitch(setup: &Setup<'_>, g: &Span) -> Glitch {
    let (t0_s, t1_s) = span_time(setup.samples, g);
    Glitch {
        t0_s,
        t1_s,
        samples: g.end - g.start,
        peak_ut: g.peak_ut,
    }
}

/// A span's first and last sample's time (their indices without a time column).
fn span_time(s: &Samples, sp: &Span) -> (f64, f64) {
    if s.has_time {
        (s.t[sp.start], s.t[sp.end - 1])
    } else {
        (sp.start as f64, (sp.end - 1) as f64)
    }
}

/// The start of a windowed effect, s.
fn effect_t0(e: &Effect) -> f64 {
    match *e {
        Effect::BiasWindow { t0_s, .. } | Effect::Disturbance { t0_s, .. } => t0_s,
        _ => f64::INFINITY,
    }
}

/// The end of a windowed effect, s.
fn effect_t1(e: &Effect) -> f64 {
    match *e {
        Effect::BiasWindow { t1_s, .. } | Effect::Disturbance { t1_s, .. } => t1_s,
        _ => f64::NEG_INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::super::rounds::settle;
    use super::super::testbench::{Bench, on_board, with_setup};
    use super::*;
    #[test]
    fn the_report_of_a_field_on_the_board_left_out_says_what_it_was_and_why() {
        let bench = Bench::new(1500, &[on_board(10.0, 20.0, [15.0, 0.0, -5.0])], 17);
        with_setup(&bench, |setup, residual| {
            let settled = settle(setup, residual).unwrap();
            let d = report(setup, settled.round, residual.to_vec(), settled.rejected);
            assert_eq!(d.verdict, Verdict::Mismatch);
            assert_eq!(d.spans.len(), 1);
            let span = &d.spans[0];
            assert!(!span.modelled);
            assert!(
                span.explanation.starts_with("10.")
                    && span.explanation.contains("fixed to the sensor — left out of the calibration: with its \
                                                  samples kept and modelled, the clean part fitted no better"),
                "{}",
                span.explanation
            );
            // Where the mismatch is: its segment (the samples used fit to the noise, on every axis).
            assert_eq!(d.located.segments.len(), 1);
            assert!(d.located.axes.is_empty(), "{:?}", d.located.axes);
            // The residuals for the plots: one component per axis, per sample, the span's flagged.
            assert_eq!(d.residuals.extended.len(), setup.samples.len());
            let out = d.residuals.excluded.iter().filter(|x| **x).count();
            assert!((495..530).contains(&out), "{out}");
            assert_eq!(d.samples_used + d.samples_excluded, setup.samples.len());
            // The final model is the clean part's, with standard errors.
            assert!(d.effects.is_empty() && d.model.corrections().count() == 0);
            let se = d.extended.se.unwrap();
            assert!(se.a[0][0] > 0.0 && se.offset_ut[0] > 0.0);
        });
    }

    #[test]
    fn without_effects_the_final_model_is_the_base_fit() {
        let bench = Bench::new(1500, &[], 18);
        with_setup(&bench, |setup, residual| {
            let settled = settle(setup, residual).unwrap();
            let d = report(setup, settled.round, residual.to_vec(), settled.rejected);
            assert_eq!(d.verdict, Verdict::Consistent);
            for j in 0..3 {
                for k in 0..3 {
                    assert!((d.extended.a[j][k] - setup.base.a[j][k]).abs() < 1e-12);
                }
                assert!((d.extended.b_ut[j] - setup.base.b_ut[j]).abs() < 1e-9);
            }
            // The reference's own error is what the residual holds beyond the noise: none here.
            assert!(d.reference_floor_ut < 0.1, "{}", d.reference_floor_ut);
        });
    }
}
