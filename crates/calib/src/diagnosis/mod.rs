//! The diagnosis: when a recording and the fitted model differ, find where, say which physics the model left out,
//! model it, and show the fit improve on held-out data — and never make the calibration worse.
//!
//! A pipeline of stages, each in the module named for it, with typed hand-offs:
//! 1. **Robust base fit** ([`crate::robust`], run by the caller): the 12-parameter (or scalar) fit that gross
//!    disturbances cannot drag, and which samples it kept. **Samples** ([`samples`]): the rows where every channel
//!    the diagnosis uses is present, with the field, its rate and the attitude worked out once; a timing lag too
//!    large for `time_lag`'s first-order term is found coarsely first and the field linearised there ([`timing`]).
//!    What every later stage shares ([`setup`]): the field's direction, the noise floor in calibrated units, the
//!    residual of a model with effects.
//! 2. **Gross spans** and 3. **their classification** ([`gross`]): the runs of samples the base fit could not keep,
//!    each a field fixed to the sensor (modelled: `bias_window`), fixed to the room (modelled: `disturbance`),
//!    changing as the sensor moves (a magnet nearby: left out), or unexplained (left out).
//! 4. **Candidates** ([`candidates`]): every effect of the catalogue ([`crate::effects`]) the recording can observe,
//!    its regressors computed by the effect's own definition (the one the simulator injects), plus the modelled
//!    spans' effects, a step and a disturbance window scanned on the clean samples ([`crate::scan`]). Effects the
//!    recording cannot observe are untestable, with the reason. **Problem** ([`problem`]): their normal equations,
//!    summed once per time block and batch ([`stats`]).
//! 5. **Selection** ([`select`](mod@select)): a Wald test with a BIC penalty, blocked cross-validation on the clean
//!    samples, a share of the residual it must explain, and for local effects a size above the reference's own
//!    error; greedy, with ambiguity; candidates the base model absorbs are reported as absorbed.
//! 6. **Plausibility and no harm** ([`guard`]): an effect stays only if the model stays physical (a non-linearity of
//!    a few per cent at most, `apply` invertible over the measured range, gains near the base fit's) and it is not an
//!    unnoticeable guess between two ambiguous effects, and the model must fit the clean held-out samples no worse
//!    than the base fit. Stages 2–6 run in [`rounds`]: in the vector method the catalogue effects then come out of
//!    the residual and the spans are looked for again (a timing lag's residual is not a disturbance), at most
//!    [`ROUNDS`] times; the scalar method's spans stay the base fit's exclusions, whose window scan sees more than
//!    one residual's gross samples.
//! 7. **Report** ([`report`]): parameters with standard errors ([`fitted`]), findings in words ([`explain`]), where
//!    the mismatch is ([`locate`]), the reference's own error as a figure of its own ([`findings`]: what is handed
//!    back).
//! 8. **Refit around the spans** ([`refit`]): when the diagnosis left out rows the base fit kept, the base fit
//!    again without them — if that predicts held-out rows better — and the diagnosis again on it.
//!
//! Parameters fitted elsewhere are checked on a recording through stages 1–3 with the model fixed
//! ([`disturbed()`]): the spans it leaves grossly off, classified and worded the same way, left out of the check.
//!
//! A bench motor test (one orientation, the throttle raised and lowered) is fitted for `current_bias` alone against
//! a constant field ([`fit_motors`]), on the same problem, selection and covariances.
//!
//! The vector method's problem has three rows per sample (`A·B̂ + b − Σ G·θ = B0`, the raw readings centred and the
//! errors-in-variables correction applied as in [`crate::vector`]); the scalar method's has one (the magnitude
//! residual linearised at the base fit, so body-fixed effects enter through `u·δ`, `u` the field direction).

mod candidates;
mod chance;
mod disturbed;
mod explain;
mod findings;
mod fitted;
mod gross;
mod guard;
mod locate;
mod motors;
mod problem;
mod refit;
mod report;
mod rounds;
mod samples;
mod select;
mod setup;
mod stats;
mod timing;

pub use candidates::Untestable;
pub use disturbed::{Disturbed, disturbed};
pub use findings::{
    Ambiguity, Diagnosis, FitSummary, FoundEffect, Glitch, GrossSpan, LinearSe, Param, ParamValue,
    Rejected, Residuals, Verdict,
};
pub use gross::SpanKind;
pub use guard::NOTICEABLE_GAIN;
pub use locate::{Components, Located, Orientation, Segment};
pub use motors::{
    CurrentTerm, Lag, MAX_CURRENT_UPDATE_INTERVALS, MAX_LAG_HALF_WIDTH_S, MotorFit, MotorInput,
    fit_motors, heading_error_deg,
};
pub use refit::diagnose_around_spans;

use crate::FitError;
use crate::effects::Frame;
use crate::model::Model;
use crate::noise::NoiseFloor;
use samples::Samples;
use setup::Setup;

/// Fewest samples the diagnosis works on.
pub const MIN_SAMPLES: usize = 50;
/// Contiguous time blocks of the cross-validation.
const CV_BLOCKS: usize = 5;
/// Contiguous batches for the residual's autocorrelation (method of batch means).
const AUTOCORRELATION_BATCHES: usize = 100;
const _: () = assert!(
    AUTOCORRELATION_BATCHES.is_multiple_of(CV_BLOCKS),
    "each batch lies within one block"
);
/// Passes of looking for gross spans (again after the catalogue's effects are out of the residual).
pub const ROUNDS: usize = 3;

/// The reference a recording offers.
#[derive(Clone, Copy, Debug)]
pub enum Reference<'a> {
    /// Attitude quaternions (sensor → NED) and the world field: the vector method; world and timing effects testable.
    Attitude {
        /// Per sample, `[w, x, y, z]` (NaN = missing).
        quat: &'a [[f64; 4]],
        /// The assumed world field, NED, µT.
        field_ned_ut: [f64; 3],
    },
    /// The expected field in sensor axes (`rx,ry,rz`): the vector method without world-frame effects.
    Field {
        /// Per sample, µT (NaN = missing).
        expected_ut: &'a [[f64; 3]],
    },
    /// The field magnitude only: the scalar method.
    Magnitude {
        /// |B|, µT.
        field_ut: f64,
    },
}

/// What the diagnosis is given.
#[derive(Clone, Debug)]
pub struct DiagnosisInput<'a> {
    /// Raw readings, µT.
    pub raw_ut: &'a [[f64; 3]],
    /// Time, s.
    pub t_s: Option<&'a [f64]>,
    /// Temperature, °C.
    pub temp_c: Option<&'a [f64]>,
    /// Current channels: name (`i_<name>`) and values, A.
    pub currents: Vec<(&'a str, &'a [f64])>,
    /// The reference.
    pub reference: Reference<'a>,
    /// The raw noise floor.
    pub noise: NoiseFloor,
    /// Per recording row, whether the robust base fit kept it (not grossly off); all kept when absent.
    pub kept: Option<&'a [bool]>,
    /// The robust base fit's residual scale (per axis, or of |B|), µT; NaN to measure it here.
    pub scale_ut: f64,
}

/// Diagnoses a recording against its base fit `base` (the linear model of the robust fit, [`crate::robust`]).
pub fn diagnose(input: &DiagnosisInput<'_>, base: &Model) -> Result<Diagnosis, FitError> {
    // The field linearised at a coarse lag is the reference only with the lag modelled: if the diagnosis ends
    // without a timing effect, it is made again on the reference as recorded.
    let (d, lag0_s) = diagnose_at(input, base, true)?;
    let timed = d
        .effects
        .iter()
        .any(|e| e.effect.id().frame() == Frame::Timing);
    if lag0_s == 0.0 || timed {
        return Ok(d);
    }
    // Its per-sample vectors go before the next are made.
    drop(d);
    Ok(diagnose_at(input, base, false)?.0)
}

/// [`diagnose`], with the field linearised at the coarse lag if `linearise` (see [`timing`]); and that lag (0 if
/// none).
fn diagnose_at(
    input: &DiagnosisInput<'_>,
    base: &Model,
    linearise: bool,
) -> Result<(Diagnosis, f64), FitError> {
    let samples = Samples::gather(input, base, linearise);
    let lag0_s = samples.lag0_s;
    if samples.len() < MIN_SAMPLES {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: samples.len(),
        });
    }
    let setup = Setup::new(input, &samples, base);
    let base_residual = setup.residual(&base.a, base.b_ut, &[]);
    let settled = rounds::settle(&setup, &base_residual)?;
    let mut diagnosis = report::report(&setup, settled.round, base_residual, settled.rejected);
    // The per-sample vectors the report shares with the samples, moved rather than copied.
    diagnosis.residuals.direction = setup.unit;
    diagnosis.residuals.rows = samples.rows;
    diagnosis.residuals.stride = samples.stride;
    diagnosis.residuals.t_s = samples.t.into_owned();
    Ok((diagnosis, lag0_s))
}

#[cfg(test)]
mod testbench;

#[cfg(test)]
mod tests {
    use super::testbench::{Bench, FIELD_NED_UT};
    use super::*;
    use crate::effects::{Effect, EffectId};

    #[test]
    fn a_null_recording_is_consistent_and_keeps_the_base_fit() {
        let bench = Bench::new(1500, &[], 1);
        let (base, kept, scale) = bench.base();
        let d = diagnose(&bench.input(Some(&kept), scale), &base).unwrap();
        assert_eq!(d.verdict, Verdict::Consistent, "{:?}", d.effects);
        assert!(d.effects.is_empty() && d.spans.is_empty());
        // Without effects the final model is the base fit itself.
        for j in 0..3 {
            for k in 0..3 {
                assert!((d.model.a[j][k] - base.a[j][k]).abs() < 1e-9);
            }
        }
        assert_eq!(d.samples_used, 1500);
        // Every effect is offered or said untestable, with a reason.
        assert!(d.untestable.iter().all(|u| !u.why.is_empty()));
    }

    #[test]
    fn a_current_bias_is_found_with_its_coefficient() {
        let coef_ut_per_a = [0.3, 0.0, -0.2];
        let effect = Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a,
        };
        let bench = Bench::new(3000, &[effect], 2);
        let (base, kept, scale) = bench.base();
        let d = diagnose(&bench.input(Some(&kept), scale), &base).unwrap();
        assert_eq!(d.verdict, Verdict::Mismatch);
        let found = &d.effects[0];
        assert_eq!(found.effect.id(), EffectId::CurrentBias, "{:?}", d.effects);
        assert_eq!(found.channel.as_deref(), Some("i_motor"));
        let (
            Effect::CurrentBias {
                coef_ut_per_a: got, ..
            },
            Some(ParamValue::Vector(se)),
        ) = (found.effect, &found.params[1].se)
        else {
            panic!("{found:?}")
        };
        for k in 0..3 {
            assert!(
                (got[k] - coef_ut_per_a[k]).abs() < 4.0 * se[k],
                "{got:?} ± {se:?}"
            );
        }
        assert!(found.holdout_rms_after_ut < found.holdout_rms_before_ut);
        // It is a correction of the sensor: the model holds it.
        assert_eq!(d.model.corrections().count(), 1);
    }

    #[test]
    fn too_few_samples_are_refused() {
        let bench = Bench::new(MIN_SAMPLES - 1, &[], 3);
        let model = testbench::true_model();
        let err = diagnose(&bench.input(None, f64::NAN), &model).unwrap_err();
        assert!(matches!(err, FitError::TooFewSamples { .. }), "{err}");
        let _ = FIELD_NED_UT;
    }
}
