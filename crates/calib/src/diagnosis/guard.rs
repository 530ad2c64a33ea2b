//! The last stage before the report: an effect stays in the model only if the model stays physical, and the model
//! as a whole must fit the clean held-out data no worse than the base fit.
//!
//! - A sensor non-linearity worth more than [`NONLINEARITY_MAX_SHARE`] of the field at full field is not a
//!   non-linearity (a cubic that large is soaking up something else: a disturbance, a wrong field).
//! - `apply` must be able to invert the model over the whole measured range: the corrections' derivative with
//!   respect to the field must stay well below one ([`MAX_CONTRACTION`]) at every sample, or the fixed-point
//!   iteration diverges.
//! - The extended model's gains (`A`'s singular values) stay within [`MAX_GAIN_CHANGE`] of the base fit's: an effect
//!   that needs the gains bent by more is not the physics the data show. A timing effect corrects the reference,
//!   not the sensor: with one chosen, the base fit the gains are held to is the one with it.
//! - An effect that another explains about as well (ambiguous) and that lowers the held-out residual by less than
//!   [`NOTICEABLE_GAIN`] is a guess between two physics for a residual nobody would notice: the calibration is not
//!   bent to it (on simulated disturbed benches such an effect fitted a magnet's tails and fitted a clean recording
//!   of the same bench worse).

use crate::effects::{Context, Effect, EffectId, Frame};
use crate::frames::Mat3;

use super::findings::Rejected;
use super::fitted::linear_of;
use super::rounds::Round;
use super::samples::Samples;
use super::setup::Setup;
use super::stats::Rows;

/// A non-linearity may be worth at most this share of the field at full field.
pub(crate) const NONLINEARITY_MAX_SHARE: f64 = 0.03;
/// The corrections' derivative with respect to the field must stay below this for `apply` to converge surely.
const MAX_CONTRACTION: f64 = 0.3;
/// The gains may move by at most this share from the base fit's.
pub(crate) const MAX_GAIN_CHANGE: f64 = 0.05;
/// An effect lowers the held-out residual's RMS noticeably when by at least this share.
pub const NOTICEABLE_GAIN: f64 = 0.02;
/// Samples looked at for the invertibility check.
const CHECKED_SAMPLES: usize = 2_000;

/// Stage 6: drops the chosen effects that make the model unphysical, then, while the clean held-out samples fit
/// worse than with the base fit alone, the catalogue's effects last first (each with why, into `rejected`). Returns
/// whether the modelled spans themselves are not worth their rows (then they are to be left out): see
/// [`spans_worth_their_rows`].
pub(crate) fn guard(setup: &Setup<'_>, round: &mut Round, rejected: &mut Vec<Rejected>) -> bool {
    let linear: Vec<usize> = (0..setup.n_base).collect();
    let Some(base12) = round.problem.solve_on(Rows::Clean, &linear, None, true) else {
        return false;
    };
    let (a_base, _) = linear_of(&base12, setup.vector, &setup.base, setup.raw_mean);
    loop {
        let chosen = round.chosen_steps();
        let drop = unphysical(setup, round, &chosen)
            .or_else(|| unnoticeable_guess(round, &chosen))
            .or_else(|| gains_moved(setup, round, &chosen, &linear, a_base))
            .or_else(|| harms_clean(round, &chosen, &linear));
        let Some((c, why)) = drop else {
            return !spans_worth_their_rows(round);
        };
        rejected.push(Rejected {
            id: round.cands[c].id(),
            why,
        });
        round.remove(c);
    }
}

/// The first chosen effect that would make the model unphysical ([`implausible`]), with why.
fn unphysical(setup: &Setup<'_>, round: &Round, chosen: &[usize]) -> Option<(usize, String)> {
    chosen.iter().find_map(|&c| {
        let effect = round.fitted_effect(c, &round.sel.last);
        implausible(&effect, setup.samples, setup.field_ut).map(|why| (c, why))
    })
}

/// The first chosen effect that another explains about as well and that lowers the held-out residual by less
/// than [`NOTICEABLE_GAIN`], with why.
fn unnoticeable_guess(round: &Round, chosen: &[usize]) -> Option<(usize, String)> {
    chosen.iter().find_map(|&c| {
        let &(_, other) = round.sel.ambiguous.iter().find(|(a, _)| *a == c)?;
        let step = round.sel.steps.iter().find(|s| s.cand == c)?;
        let rows = round.problem.clean_total.rows.max(1) as f64;
        let (before, after) = ((step.cv.0 / rows).sqrt(), (step.cv.1 / rows).sqrt());
        (before - after < NOTICEABLE_GAIN * before).then(|| {
            let ids = (round.cands[c].id(), round.cands[other].id());
            (c, guess_why(ids.0, ids.1, before, after))
        })
    })
}

/// The last chosen effect, when the gains of the model with the chosen effects move by more than
/// [`MAX_GAIN_CHANGE`] from the base fit's (`a_base`, on the clean rows' `linear` columns), with why.
fn gains_moved(
    setup: &Setup<'_>,
    round: &Round,
    chosen: &[usize],
    linear: &[usize],
    a_base: Mat3,
) -> Option<(usize, String)> {
    let &last = chosen.last()?;
    let (a, _) = linear_of(&round.sel.last, setup.vector, &setup.base, setup.raw_mean);
    // A timing effect corrects the reference, not the sensor: the gains are judged against the base fit with it (a
    // lag of 64 ms bends the base fit's gains by more than the rule allows).
    let timing: Vec<usize> = chosen
        .iter()
        .filter(|&&c| round.cands[c].id().frame() == Frame::Timing)
        .flat_map(|&c| round.cands[c].columns())
        .collect();
    let a_base = if timing.is_empty() {
        a_base
    } else {
        let columns: Vec<usize> = linear.iter().copied().chain(timing).collect();
        match round.problem.solve_on(Rows::Clean, &columns, None, true) {
            Some(fit) => linear_of(&fit, setup.vector, &setup.base, setup.raw_mean).0,
            None => a_base,
        }
    };
    let change = gain_change(&a, &a_base);
    (change > MAX_GAIN_CHANGE).then(|| (last, gains_why(change)))
}

/// The last chosen effect, while the clean held-out samples fit worse than with the base fit (its `linear`
/// columns) alone, with why. Without one, the modelled spans answer for it ([`spans_worth_their_rows`]: a span
/// worse than the base is not worth its rows either).
fn harms_clean(round: &Round, chosen: &[usize], linear: &[usize]) -> Option<(usize, String)> {
    let &last = chosen.last()?;
    let problem = &round.problem;
    let cv_base = problem.cv_rss_on(Rows::Clean, linear)?;
    let cv_final = problem.cv_rss(&round.sel.last.columns)?;
    (cv_final > cv_base).then(|| {
        let rows = problem.clean_total.rows.max(1) as f64;
        let rms = |x: f64| (x / rows).sqrt();
        let id = round.cands[last].id();
        (last, harm_why(id, rms(cv_final), rms(cv_base)))
    })
}

/// Whether the modelled spans' rows are worth keeping: with them, the clean rows' held-out residual is noticeably
/// ([`NOTICEABLE_GAIN`]) lower than with the same model fitted on the clean rows alone. A gain nobody would notice
/// does not pay for a constant fitted to a disturbance whose edges and shape are only estimated (true when no span
/// is modelled).
pub(crate) fn spans_worth_their_rows(round: &Round) -> bool {
    if !round.spans.iter().any(|s| s.modelled()) {
        return true;
    }
    let forced: Vec<usize> = round
        .cands
        .iter()
        .filter(|c| c.forced)
        .flat_map(|c| c.columns())
        .collect();
    let without: Vec<usize> = round
        .sel
        .last
        .columns
        .iter()
        .copied()
        .filter(|c| !forced.contains(c))
        .collect();
    match (
        round.problem.cv_rss(&round.sel.last.columns),
        round.problem.cv_rss_on(Rows::Clean, &without),
    ) {
        (Some(with), Some(alone)) => with.sqrt() <= (1.0 - NOTICEABLE_GAIN) * alone.sqrt(),
        // Without the spans' rows the model cannot be fitted: they are needed.
        (Some(_), None) => true,
        _ => false,
    }
}

/// Why a found body-fixed effect would make the model unphysical, if it would.
pub(crate) fn implausible(effect: &Effect, samples: &Samples, field_ut: f64) -> Option<String> {
    if let Effect::Nonlinearity { cubic_per_ut2 } = *effect {
        let worst = cubic_per_ut2
            .iter()
            .map(|k| k.abs() * field_ut.powi(3))
            .fold(0.0, f64::max);
        if worst > NONLINEARITY_MAX_SHARE * field_ut {
            return Some(format!(
                "a cubic worth {worst:.2} µT at ±{field_ut:.0} µT ({:.1} % of the field) is more than a sensor's \
                 non-linearity ({:.0} % at most): it bends to something else in the residual",
                100.0 * worst / field_ut,
                100.0 * NONLINEARITY_MAX_SHARE
            ));
        }
    }
    if effect.id().frame() != Frame::Body || effect.id().is_transient() {
        return None;
    }
    let stride = (samples.len() / CHECKED_SAMPLES).max(1);
    let worst = (0..samples.len())
        .step_by(stride)
        .map(|i| contraction(effect, &samples.context(i)))
        .fold(0.0, f64::max);
    (worst >= MAX_CONTRACTION).then(|| {
        format!(
            "its correction changes by {worst:.2} µT per µT of field somewhere in the measured range: the model could \
             not be inverted there (apply would diverge)"
        )
    })
}

/// The largest absolute entry of `∂δ/∂B` at one sample (central differences of 1 µT).
fn contraction(effect: &Effect, ctx: &Context<'_>) -> f64 {
    let mut worst: f64 = 0.0;
    for k in 0..3 {
        let shifted = |d: f64| {
            let mut c = *ctx;
            c.field_ut[k] += d;
            effect.perturbation_ut(&c)
        };
        let (plus, minus) = (shifted(1.0), shifted(-1.0));
        for j in 0..3 {
            worst = worst.max(((plus[j] - minus[j]) / 2.0).abs());
        }
    }
    if worst.is_nan() { 0.0 } else { worst }
}

/// The largest relative change of `A`'s singular values from the base fit's.
pub(crate) fn gain_change(a: &Mat3, base: &Mat3) -> f64 {
    let sv = |m: &Mat3| {
        let mut v: Vec<f64> = nalgebra::Matrix3::from_fn(|j, k| m[j][k])
            .singular_values()
            .iter()
            .copied()
            .collect();
        v.sort_by(f64::total_cmp);
        v
    };
    let (now, was) = (sv(a), sv(base));
    (0..3)
        .map(|k| (now[k] / was[k] - 1.0).abs())
        .fold(0.0, f64::max)
}

/// The words for an effect rejected because the gains would move.
pub(crate) fn gains_why(change: f64) -> String {
    format!(
        "with it, the gains would move by {:.1} % from the base fit's (more than {:.0} %): the data do not show it \
         as physics of the sensor",
        100.0 * change,
        100.0 * MAX_GAIN_CHANGE
    )
}

/// The words for an ambiguous effect too small to notice, left out of the model.
pub(crate) fn guess_why(id: EffectId, other: EffectId, before: f64, after: f64) -> String {
    format!(
        "{other} explains the same residual about as well, and {id} would lower the residual on data the fit did not \
         see only from {before:.3} to {after:.3} µT (less than {:.0} %): left out, so the calibration is not bent to \
         a guess",
        100.0 * NOTICEABLE_GAIN
    )
}

/// The words for effects dropped so that the clean held-out data fit no worse than with the base fit.
pub(crate) fn harm_why(id: EffectId, with: f64, without: f64) -> String {
    format!(
        "with {id} the clean part of the recording, held out, fits worse than with the base fit alone ({with:.3} \
         against {without:.3} µT): left out, so the calibration is no worse for the diagnosis"
    )
}

#[cfg(test)]
mod tests {
    use super::super::rounds::settle;
    use super::super::testbench::{Bench, with_setup};
    use super::*;
    use crate::frames::IDENTITY;

    #[test]
    fn a_cubic_worth_more_than_a_few_percent_of_the_field_is_implausible() {
        let bench = Bench::new(300, &[], 13);
        with_setup(&bench, |setup, _| {
            let cubic = |k: f64| Effect::Nonlinearity {
                cubic_per_ut2: [k, 0.0, 0.0],
            };
            // 1e-5/µT² at 50 µT: 1.25 µT, 2.5 % of the field; ten times that is not a sensor's.
            assert_eq!(implausible(&cubic(1e-5), setup.samples, 50.0), None);
            let why = implausible(&cubic(1e-4), setup.samples, 50.0).unwrap();
            assert!(why.contains("more than a sensor's non-linearity"), "{why}");
            // A correction whose derivative approaches one cannot be inverted by apply.
            let scale = Effect::TemperatureScale {
                coef_per_c: [0.05, 0.0, 0.0],
                t_ref_c: 0.0,
            };
            let why = implausible(&scale, setup.samples, 50.0);
            assert!(why.is_some_and(|w| w.contains("could not be inverted")));
            // Effects of the world or of one recording are not the sensor's: not judged so.
            let window = Effect::BiasWindow {
                t0_s: 0.0,
                t1_s: 1.0,
                offset_ut: [1e3; 3],
            };
            assert_eq!(implausible(&window, setup.samples, 50.0), None);
        });
    }

    #[test]
    fn the_gain_change_is_the_largest_relative_change_of_a_singular_value() {
        let mut a = IDENTITY;
        a[1][1] = 1.1;
        a[2][2] = 0.97;
        assert!((gain_change(&a, &IDENTITY) - 0.1).abs() < 1e-12);
        assert_eq!(gain_change(&IDENTITY, &IDENTITY), 0.0);
    }

    #[test]
    fn an_effect_that_helps_stays_and_the_spans_of_a_null_recording_need_no_judging() {
        let effect = Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: [0.3, 0.0, -0.2],
        };
        let bench = Bench::new(3000, &[effect], 14);
        with_setup(&bench, |setup, residual| {
            let mut settled = settle(setup, residual).unwrap();
            let before = settled.round.chosen_steps();
            assert_eq!(before.len(), 1);
            let mut rejected = Vec::new();
            assert!(!guard(setup, &mut settled.round, &mut rejected));
            assert!(rejected.is_empty(), "{rejected:?}");
            assert_eq!(settled.round.chosen_steps(), before);
            assert!(spans_worth_their_rows(&settled.round));
        });
    }
}
