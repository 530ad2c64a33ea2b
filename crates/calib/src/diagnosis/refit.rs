//! Stage 8, the refit around the spans: the diagnosis locates spans around those the robust fit excluded (with
//! their fading edges) and may leave out rows the base fit kept. When it does, the base method's fit is made again
//! without those rows — if that predicts held-out rows better — and the diagnosis again on it, so that what the
//! report says is left out of the calibration is. The base fit itself stays what it was, for the comparison.

use crate::FitError;
use crate::model::Model;
use crate::robust::RobustProblem;

use super::guard::NOTICEABLE_GAIN;
use super::{Diagnosis, DiagnosisInput, diagnose};

/// A stretch whose residual RMS is within this factor of the clean rows' is as clean, not disturbed.
const NOISE_LIKE: f64 = 2.0;
/// Time blocks of the held-out comparison: fits on every other block predict the rest.
const HELD_OUT_BLOCKS: usize = 10;

/// Diagnoses a recording against its robust base fit `base` (`start`, whose kept rows are `input.kept`; all kept
/// when absent), then refits around the spans it located: `problem` makes the base method's problem for the refit,
/// only when it is needed (it holds per-row data the diagnosis does without; `None` when it cannot be made: the
/// first diagnosis then stands).
pub fn diagnose_around_spans<P: RobustProblem>(
    input: &DiagnosisInput<'_>,
    base: &Model,
    problem: impl FnOnce() -> Option<P>,
    start: &P::Fit,
) -> Result<Diagnosis, FitError> {
    let first = diagnose(input, base)?;
    let robust_kept = match input.kept {
        Some(kept) => kept.to_vec(),
        None => vec![true; input.raw_ut.len()],
    };
    let mut kept = robust_kept.clone();
    for row in first.residuals.excluded_rows() {
        kept[row] = false;
    }
    if kept == robust_kept {
        return Ok(first);
    }
    let refit = problem().and_then(|p| refit_if_better(&p, &robust_kept, &kept, start));
    // Without the rows, the fit is not determined or predicts the clean rows worse: the first diagnosis stands, and
    // the rows it located that the base fit kept stay in the calibration. The first diagnosis ran on these rows and
    // more: if the second cannot, the first stands.
    let (mut d, kept) = match refit {
        Some((model, kept)) => {
            let again = DiagnosisInput {
                kept: Some(&kept),
                ..input.clone()
            };
            match diagnose(&again, &model) {
                Ok(d) => (d, kept),
                Err(_) => (first, robust_kept),
            }
        }
        None => (first, robust_kept),
    };
    d.kept_after_all(&kept);
    Ok(d)
}

/// The fit on the rows `kept` (from `start`), if it predicts the rows both masks keep better, held out, than the
/// fit on the rows `before`: each fitted on every other time block of [`HELD_OUT_BLOCKS`] and evaluated on the
/// others, both ways. Only stretches the fit leaves well above its residual on the rows both keep go
/// ([`NOISE_LIKE`]): a stretch at that level is as clean, and the directions it covers would be missed.
fn refit_if_better<P: RobustProblem>(
    problem: &P,
    before: &[bool],
    kept: &[bool],
    start: &P::Fit,
) -> Option<(Model, Vec<bool>)> {
    let n = kept.len();
    let kept = noisy_stretches_only(problem, before, kept, start);
    if kept == before {
        return None;
    }
    let block = |i: usize| i * HELD_OUT_BLOCKS / n.max(1) % 2;
    let held_out_rss = |rows: &[bool]| -> Option<f64> {
        let mut rss = 0.0;
        for fold in 0..2 {
            let weights: Vec<f64> = (0..n)
                .map(|i| f64::from(u8::from(rows[i] && block(i) == fold)))
                .collect();
            let fit = problem.quick_fit(&weights, Some(start)).ok()?;
            let e = problem.residuals(&fit);
            rss += (0..n)
                .filter(|&i| kept[i] && block(i) != fold && e[i].is_finite())
                .map(|i| e[i] * e[i])
                .sum::<f64>();
        }
        Some(rss)
    };
    // As for an effect: a gain nobody would notice is not worth the rows.
    let (old, new) = (held_out_rss(before)?, held_out_rss(&kept)?);
    if new.sqrt() > (1.0 - NOTICEABLE_GAIN) * old.sqrt() {
        return None;
    }
    let fit = problem.final_fit(&kept, Some(start)).ok()?;
    Some((P::model(&fit), kept))
}

/// `kept`, with the stretches it leaves out beyond `before` put back where the fit `start` leaves them within
/// [`NOISE_LIKE`] of its residual on the rows `kept` keeps.
fn noisy_stretches_only<P: RobustProblem>(
    problem: &P,
    before: &[bool],
    kept: &[bool],
    start: &P::Fit,
) -> Vec<bool> {
    let n = kept.len();
    let e0 = problem.residuals(start);
    let mean_square = |rows: &mut dyn Iterator<Item = f64>| {
        let (ss, m) = rows
            .filter(|e| e.is_finite())
            .fold((0.0, 0usize), |(s, m), e| (s + e * e, m + 1));
        ss / m.max(1) as f64
    };
    let clean = mean_square(&mut e0.iter().zip(kept).filter(|(_, k)| **k).map(|(e, _)| *e));
    let mut kept = kept.to_vec();
    let mut i = 0;
    while i < n {
        if before[i] == kept[i] {
            i += 1;
            continue;
        }
        let end = (i..n).find(|&j| before[j] == kept[j]).unwrap_or(n);
        if mean_square(&mut e0[i..end].iter().copied()) <= NOISE_LIKE.powi(2) * clean {
            kept[i..end].fill(true);
        }
        i = end;
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::super::testbench::{Bench, on_board};
    use super::*;
    use crate::robust::{self, RobustProblem};
    use crate::vector::VectorProblem;

    #[test]
    fn a_stretch_left_out_that_fits_like_the_rest_is_put_back_and_one_that_does_not_stays_out() {
        let bench = Bench::new(1500, &[on_board(10.0, 14.0, [6.0, 0.0, 0.0])], 19);
        let problem = bench.problem();
        let all = vec![true; 1500];
        let fit = problem.final_fit(&all, None).unwrap();
        let mut kept = all.clone();
        // Samples 100–200 (2–4 s) are clean; 500–700 (10–14 s) carry the field on the board.
        kept[100..200].fill(false);
        kept[500..700].fill(false);
        let back = noisy_stretches_only(&problem, &all, &kept, &fit);
        assert!(back[100..200].iter().all(|k| *k));
        assert!(back[500..700].iter().all(|k| !*k));
        // Leaving the board's stretch out predicts the rest better: the refit is made without it.
        let (model, rows) = refit_if_better(&problem, &all, &kept, &fit).unwrap();
        assert_eq!(rows, back);
        assert!((model.b_ut[0] - VectorProblem::model(&fit).b_ut[0]).abs() > 0.1);
        // Nothing new left out: nothing to refit.
        assert!(refit_if_better(&problem, &all, &all, &fit).is_none());
    }

    #[test]
    fn around_spans_on_a_null_recording_is_the_diagnosis_itself() {
        let bench = Bench::new(1500, &[], 20);
        let problem = bench.problem();
        let r = robust::fit(&problem, Some(&bench.t_s)).unwrap();
        let input = bench.input(Some(&r.kept), r.sigma_ut);
        let base = VectorProblem::model(&r.fit);
        let mut made = false;
        let d = diagnose_around_spans(
            &input,
            &base,
            || {
                made = true;
                Some(bench.problem())
            },
            &r.fit,
        )
        .unwrap();
        assert_eq!(d, diagnose(&input, &base).unwrap());
        assert!(
            !made,
            "the refit's problem was made though nothing was left out"
        );
    }
}
