//! The disturbed spans of a recording under a model fitted elsewhere — how a calibration is checked on a second
//! recording: stages 1–3 of the diagnosis with the model fixed. The rows its residual leaves grossly off make the
//! spans, as the robust fit's do in a fit ([`crate::robust::gross_spans`]), and each is classified and worded as the
//! diagnosis does (a field fixed to the sensor, to the room, one that moved with the sensor…); all of them are left
//! out of the check, since nothing is modelled there.

use crate::FitError;
use crate::effects::Effect;
use crate::model::Model;

use super::explain::Fate;
use super::findings::{Glitch, GrossSpan, rows_of};
use super::report::{glitch, gross_span};
use super::samples::Samples;
use super::setup::Setup;
use super::{DiagnosisInput, MIN_SAMPLES, gross};

/// What a model fitted elsewhere leaves disturbed in a recording.
#[derive(Clone, Debug, PartialEq)]
pub struct Disturbed {
    /// The spans, in time order, in words.
    pub spans: Vec<GrossSpan>,
    /// The glitches (spans too short to be a field, or within what the noise makes by chance), also left out.
    pub glitches: Vec<Glitch>,
    /// Per recording row, whether it lies in one of them (and is left out of the check).
    pub left_out: Vec<bool>,
}

impl Disturbed {
    /// Rows left out.
    pub fn rows_left_out(&self) -> usize {
        self.left_out.iter().filter(|l| **l).count()
    }
}

/// The spans `model` leaves grossly off in the recording of `input` (its `kept` and `scale_ut` are not used: the
/// gross rows and their scale are this model's).
pub fn disturbed(input: &DiagnosisInput<'_>, model: &Model) -> Result<Disturbed, FitError> {
    let samples = Samples::gather(input, model, false);
    if samples.len() < MIN_SAMPLES {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: samples.len(),
        });
    }
    let setup = Setup::new(input, &samples, model);
    let corrections: Vec<Effect> = model.corrections().copied().collect();
    let residual = setup.residual(&model.a, model.b_ut, &corrections);
    let (scale, kept) = setup.state_kept(&residual);
    let stage = gross::stage(&setup, &residual, &kept, scale, &[]);
    let mut left_out = vec![false; input.raw_ut.len()];
    for row in rows_of(&samples.rows, |k| !stage.clean[k], samples.stride) {
        left_out[row] = true;
    }
    Ok(Disturbed {
        spans: stage
            .spans
            .iter()
            .map(|sp| gross_span(&setup, sp, Fate::Check))
            .collect(),
        glitches: stage.glitches.iter().map(|g| glitch(&setup, g)).collect(),
        left_out,
    })
}

#[cfg(test)]
mod tests {
    use super::super::testbench::{Bench, on_board, true_model};
    use super::*;

    #[test]
    fn a_field_on_the_board_is_located_and_left_out_of_a_check_of_the_true_model() {
        let bench = Bench::new(1500, &[on_board(10.0, 20.0, [15.0, 0.0, -5.0])], 21);
        let d = disturbed(&bench.input(None, f64::NAN), &true_model()).unwrap();
        assert_eq!(d.spans.len(), 1, "{:?}", d.spans);
        let span = &d.spans[0];
        assert!(
            span.explanation
                .ends_with("fixed to the sensor — left out of the check")
                && !span.modelled,
            "{}",
            span.explanation
        );
        assert!((span.t0_s - 10.0).abs() < 0.1 && (span.t1_s - 20.0).abs() < 0.1);
        let left: Vec<usize> = (0..1500).filter(|&i| d.left_out[i]).collect();
        assert!(
            left.len() >= 495 && left.len() < 520,
            "{} left out",
            left.len()
        );
        assert!(left.iter().all(|&i| (9.9..20.1).contains(&bench.t_s[i])));
        // A recording the model fits has nothing to leave out.
        let clean = Bench::new(1500, &[], 22);
        let d = disturbed(&clean.input(None, f64::NAN), &true_model()).unwrap();
        assert!(d.spans.is_empty() && d.rows_left_out() == 0);
    }
}
