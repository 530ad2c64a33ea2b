//! Stages 2–6 in rounds: the gross spans of a residual, the candidates, the problem and the selection make a
//! [`Round`]; the guard then keeps the model physical and no worse on clean held-out samples. When modelling the spans
//! harms the clean fit, they are left out and the round made again; in the vector method the spans are looked for
//! again once the catalogue's effects are out of the residual (a timing lag's residual is not a disturbance), at
//! most [`ROUNDS`] times.

use std::borrow::Cow;

use crate::FitError;
use crate::effects::Effect;
use crate::robust;

use super::candidates::{self, Candidate, Untestable};
use super::findings::Rejected;
use super::fitted::{coefficient, linear_of};
use super::gross::{self, Declined, Span};
use super::select::{self, Selection};
use super::setup::Setup;
use super::stats::{Problem, Solution};
use super::{ROUNDS, guard, problem};

/// One pass of stages 2–5: the spans, which samples the fits include, the candidates and the selection.
pub(crate) struct Round {
    /// The gross spans that are findings, classified.
    pub spans: Vec<Span>,
    /// The gross spans that are glitches (too short, or within what the noise makes by chance).
    pub glitches: Vec<Span>,
    /// Per sample: in the fits (clean, or in a modelled span's window).
    pub included: Vec<bool>,
    /// Per sample: outside every gross span.
    pub clean: Vec<bool>,
    /// The candidates: the modelled spans' effects (forced), then the catalogue's.
    pub cands: Vec<Candidate>,
    /// The effects this recording cannot test, and why.
    pub untestable: Vec<Untestable>,
    /// The normal equations of the included samples.
    pub problem: Problem,
    /// The effects chosen.
    pub sel: Selection,
}

/// What the rounds settle on: the last round, and the effects the guard rejected on the way.
pub(crate) struct Settled {
    /// The last round, guarded.
    pub round: Round,
    /// Effects suggested by the data but rejected, with why.
    pub rejected: Vec<Rejected>,
}

/// Runs rounds from the base fit's residual `base_residual` until the spans settle (see the module's doc).
pub(crate) fn settle(setup: &Setup<'_>, base_residual: &[[f64; 3]]) -> Result<Settled, FitError> {
    let mut search = Search::new(setup, base_residual);
    let mut round = search.round()?;
    for _ in 1..ROUNDS {
        // Guard first: effects that make the model unphysical go, and if modelling the spans harms the clean
        // held-out fit, they are left out instead.
        if guard::guard(setup, &mut round, &mut search.rejected) {
            round = search.without_modelled_spans(&round)?;
            continue;
        }
        // The scalar method's exclusions are the base fit's (its scan for shifted windows sees more than the gross
        // spans of one residual).
        if !setup.vector || !search.spans_moved(&round) {
            break;
        }
        round = search.round()?;
    }
    if guard::guard(setup, &mut round, &mut search.rejected) {
        round = search.without_modelled_spans(&round)?;
        guard::guard(setup, &mut round, &mut search.rejected);
    }
    Ok(Settled {
        round,
        rejected: search.rejected,
    })
}

/// The state the rounds carry from one to the next.
struct Search<'s> {
    setup: &'s Setup<'s>,
    /// The residual whose gross samples make the spans.
    residual: Cow<'s, [[f64; 3]]>,
    /// Per sample, outside the gross spans.
    kept: Vec<bool>,
    /// The residual's scale (per axis, or of |B|), µT.
    scale: f64,
    /// Spans whose modelling was declined, and why.
    left_out: Vec<(usize, usize, Declined)>,
    rejected: Vec<Rejected>,
}

impl<'s> Search<'s> {
    fn new(setup: &'s Setup<'s>, base_residual: &'s [[f64; 3]]) -> Search<'s> {
        let scale = if setup.input.scale_ut > 0.0 {
            setup.input.scale_ut
        } else {
            setup.scale(base_residual)
        };
        Search {
            setup,
            residual: Cow::Borrowed(base_residual),
            kept: setup.samples.kept.clone(),
            scale,
            left_out: Vec::new(),
            rejected: Vec::new(),
        }
    }

    /// A round on the current spans; if the spans' effects leave its base problem without a solution (a field in
    /// the room while the sensor hardly turned is nearly the offset), every span is left out instead.
    fn round(&mut self) -> Result<Round, FitError> {
        match round(
            self.setup,
            &self.residual,
            &self.kept,
            self.scale,
            &self.left_out,
        ) {
            Err(FitError::Singular(_)) => {
                self.left_out.extend(
                    robust::excluded_runs(&self.kept)
                        .into_iter()
                        .map(|(a, b)| (a, b, Declined::Undetermined)),
                );
                round(
                    self.setup,
                    &self.residual,
                    &self.kept,
                    self.scale,
                    &self.left_out,
                )
            }
            other => other,
        }
    }

    /// The round again with the modelled spans of `round` left out: they were not worth their rows.
    fn without_modelled_spans(&mut self, round: &Round) -> Result<Round, FitError> {
        self.left_out.extend(
            round
                .spans
                .iter()
                .filter(|s| s.modelled())
                .map(|s| (s.start, s.end, Declined::NoGain)),
        );
        self.round()
    }

    /// Looks for the spans again on the residual with the catalogue's effects of `round` out of it; whether they
    /// moved (the state then holds them).
    fn spans_moved(&mut self, round: &Round) -> bool {
        let setup = self.setup;
        let (a, b) = linear_of(&round.sel.last, setup.vector, &setup.base, setup.raw_mean);
        let effects = round.catalogue_effects();
        let residual = setup.residual(&a, b, &effects);
        let (scale, kept) = setup.state_kept(&residual);
        if kept == self.kept {
            return false;
        }
        (self.kept, self.scale, self.residual) = (kept, scale, Cow::Owned(residual));
        true
    }
}

/// Stages 2–5 on the spans of `residual`'s gross samples (those not `kept`), with the spans overlapping `left_out`
/// not modelled.
fn round(
    setup: &Setup<'_>,
    residual: &[[f64; 3]],
    kept: &[bool],
    scale: f64,
    left_out: &[(usize, usize, Declined)],
) -> Result<Round, FitError> {
    let gross = gross::stage(setup, residual, kept, scale, left_out);
    let offer = candidates::offer(setup, residual, &gross.clean, gross.span_effects);
    let (mut cands, untestable) = candidates::candidates(&offer, setup.n_base);
    let problem = problem::accumulate(setup, &mut cands, &gross.included, &gross.clean);
    let sel = select::stage(setup, &problem, &cands)?;
    Ok(Round {
        spans: gross.spans,
        glitches: gross.glitches,
        included: gross.included,
        clean: gross.clean,
        cands,
        untestable,
        problem,
        sel,
    })
}

impl Round {
    /// The selected catalogue candidates still in the model, in the order they were chosen.
    pub fn chosen_steps(&self) -> Vec<usize> {
        self.sel
            .steps
            .iter()
            .filter(|step| !self.sel.steps.iter().any(|s| s.replaced == Some(step.cand)))
            .map(|step| step.cand)
            .collect()
    }

    /// Candidate `c` with its parameters from a solution.
    pub fn fitted_effect(&self, c: usize, sol: &Solution) -> Effect {
        let cand = &self.cands[c];
        let p: [f64; 3] = std::array::from_fn(|k| {
            if k < cand.n {
                coefficient(sol, cand.first + k, 0.0).map_or(0.0, |(v, _)| v)
            } else {
                0.0
            }
        });
        cand.template.with_params(p)
    }

    /// The catalogue's effects in the final model (not the spans').
    pub fn catalogue_effects(&self) -> Vec<Effect> {
        self.chosen_steps()
            .into_iter()
            .map(|c| self.fitted_effect(c, &self.sel.last))
            .collect()
    }

    /// Takes candidate `c` out of the model: its step goes, and the last solution is solved again without it.
    pub fn remove(&mut self, c: usize) {
        let cols: Vec<usize> = self.cands[c].columns().collect();
        let keep: Vec<usize> = self
            .sel
            .last
            .columns
            .iter()
            .copied()
            .filter(|x| !cols.contains(x))
            .collect();
        self.sel.steps.retain(|s| s.cand != c);
        if let Some(sol) = self.problem.solve(&keep, None, true) {
            self.sel.last_cv = self.problem.cv_rss(&keep).unwrap_or(self.sel.last_cv);
            self.sel.last = sol;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::gross::SpanKind;
    use super::super::testbench::{Bench, on_board, with_setup};
    use super::*;
    #[test]
    fn a_null_recording_settles_on_nothing() {
        let bench = Bench::new(1500, &[], 15);
        with_setup(&bench, |setup, residual| {
            let settled = settle(setup, residual).unwrap();
            assert!(settled.round.spans.is_empty());
            assert!(settled.round.chosen_steps().is_empty());
            assert!(settled.rejected.is_empty());
            assert!(settled.round.included.iter().all(|i| *i));
        });
    }

    #[test]
    fn a_field_on_the_board_the_rest_does_not_need_is_left_out_not_modelled() {
        // The sensor tumbles throughout: the clean part determines the calibration on its own, so the window's
        // constant is not worth its rows (the guard finds no noticeable gain) and the round is made again with the
        // span left out.
        let bench = Bench::new(1500, &[on_board(10.0, 20.0, [15.0, 0.0, -5.0])], 16);
        with_setup(&bench, |setup, residual| {
            let settled = settle(setup, residual).unwrap();
            let round = &settled.round;
            assert_eq!(round.spans.len(), 1, "{:?}", round.spans);
            let span = round.spans[0];
            assert!(matches!(
                span.kind,
                SpanKind::SensorFixed {
                    told_apart: true,
                    ..
                }
            ));
            assert_eq!(span.declined, Some(Declined::NoGain));
            assert!(!span.modelled());
            assert!(round.cands.iter().all(|c| !c.forced));
            // Its samples are out of the fit and of the clean ones.
            let inside = |i: usize| (10.05..19.95).contains(&setup.samples.t[i]);
            let n = setup.samples.len();
            assert!(
                (0..n)
                    .filter(|&i| inside(i))
                    .all(|i| !round.clean[i] && !round.included[i])
            );
            assert!(round.chosen_steps().is_empty());
        });
    }
}
