//! The diagnosis: when a recording and the fitted model differ, find where, say which physics the model left out,
//! model it, and show the fit improve on held-out data — and never make the calibration worse.
//!
//! A pipeline of stages, in order:
//! 1. **Robust base fit** ([`crate::robust`], run by the caller): the 12-parameter (or scalar) fit that gross
//!    disturbances cannot drag, and which samples it kept.
//! 2. **Gross spans** and 3. **their classification** ([`gross`]): the runs of samples the base fit could not keep,
//!    each a field fixed to the sensor (modelled: `bias_window`), fixed to the room (modelled: `disturbance`),
//!    changing as the sensor moves (a magnet nearby: left out), or unexplained (left out).
//! 4. **Candidates** ([`candidates`]): every effect of the catalogue ([`crate::effects`]) the recording can observe,
//!    its regressors computed by the effect's own definition (the one the simulator injects), plus the modelled
//!    spans' effects. A timing lag too large for `time_lag`'s first-order term is found coarsely first and the
//!    field linearised there ([`timing`], when the samples are gathered). Effects the recording cannot observe are
//!    untestable, with the reason; candidates the base model absorbs are reported as absorbed.
//! 5. **Selection** ([`select`](mod@select)): a Wald test with a BIC penalty, blocked cross-validation on the clean samples, a
//!    share of the residual it must explain, and for local effects a size above the reference's own error; greedy,
//!    with ambiguity. In the vector method the catalogue effects then come out of the residual and the spans are
//!    looked for again (a timing lag's residual is not a disturbance), at most [`ROUNDS`] times; the scalar method's
//!    spans stay the base fit's exclusions, whose window scan sees more than one residual's gross samples.
//! 6. **Plausibility and no harm** ([`guard`]): an effect stays only if the model stays physical (a non-linearity of
//!    a few per cent at most, `apply` invertible over the measured range, gains near the base fit's) and it is not an
//!    unnoticeable guess between two ambiguous effects, and the model must fit the clean held-out samples no worse
//!    than the base fit.
//! 7. **Report**: parameters with standard errors ([`fitted`]), findings in words ([`explain`]), where the mismatch is
//!    ([`locate`]), the reference's own error as a figure of its own.
//!
//! The vector method's problem has three rows per sample (`A·B̂ + b − Σ G·θ = B0`, the raw readings centred and the
//! errors-in-variables correction applied as in [`crate::vector`]); the scalar method's has one (the magnitude
//! residual linearised at the base fit, so body-fixed effects enter through `u·δ`, `u` the field direction).

mod candidates;
mod explain;
mod fitted;
mod gross;
mod guard;
mod locate;
mod samples;
pub(crate) mod scan;
mod select;
mod stats;
mod timing;

use std::borrow::Cow;

use nalgebra::DVector;

pub use candidates::Untestable;
pub use gross::SpanKind;
pub use guard::NOTICEABLE_GAIN;
pub use locate::{Components, Located, Orientation, Segment};

use crate::FitError;
use crate::chunks;
use crate::effects::{Effect, EffectId, Frame};
use crate::frames::{self, Mat3};
use crate::model::Model;
use crate::noise::NoiseFloor;
use crate::robust::{self, RobustProblem};
use candidates::{Candidate, Offer, ScanTimes};
use fitted::{SYM, coefficient, linear_of, linear_se, not_excited, params_of};
use gross::{Declined, Residual, Span};
use samples::Samples;
use select::{Selection, SetAside, select};
use stats::{Batches, BlockStats, Problem, Rows};

/// Fewest samples the diagnosis works on.
pub const MIN_SAMPLES: usize = 50;
/// Contiguous time blocks of the cross-validation.
const CV_BLOCKS: usize = 5;
/// Contiguous batches for the residual's autocorrelation (method of batch means).
const AUTOCORRELATION_BATCHES: usize = 100;
/// The step (µT) of the field along which the scalar method's regressors are differentiated for their noise.
const NOISE_STEP_UT: f64 = 0.01;
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

/// The overall finding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Nothing found: no effect, no gross span (a residual beyond the sensor's noise is the reference's own error).
    Consistent,
    /// The model misses something: effects found, or gross spans located.
    Mismatch,
}

/// A parameter's value in a report.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    /// A number.
    Number(f64),
    /// Three numbers.
    Vector([f64; 3]),
    /// Text (a channel name).
    Text(String),
}

/// A named parameter with its standard error.
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    /// The report name (`lag_s`, `coef_ut_per_c`, …).
    pub name: &'static str,
    /// Its value.
    pub value: ParamValue,
    /// Its standard error, if estimated.
    pub se: Option<ParamValue>,
}

/// An effect the diagnosis found and modelled.
#[derive(Clone, Debug, PartialEq)]
pub struct FoundEffect {
    /// The effect with its fitted parameters (from the final joint fit).
    pub effect: Effect,
    /// The current channel, for `current_bias`.
    pub channel: Option<String>,
    /// Its parameters as reported.
    pub params: Vec<Param>,
    /// Residual RMS before and after adding it, µT.
    pub rms_before_ut: f64,
    /// See `rms_before_ut`.
    pub rms_after_ut: f64,
    /// Held-out (blocked cross-validation) RMS before and after adding it, µT.
    pub holdout_rms_before_ut: f64,
    /// See `holdout_rms_before_ut`.
    pub holdout_rms_after_ut: f64,
    /// Evidence for it: the Wald statistic minus the complexity penalty, σ² units.
    pub evidence: f64,
    /// Its size: the RMS per axis of its perturbation over the samples where it acts, µT.
    pub size_ut: f64,
    /// What it is, with its main parameters in physical units (the start of `explanation`).
    pub what: String,
    /// The finding in words.
    pub explanation: String,
}

/// A span where the residual departed grossly from the rest, and what it was.
#[derive(Clone, Debug, PartialEq)]
pub struct GrossSpan {
    /// First and last sample's time, s (the sample indices without a time column).
    pub t0_s: f64,
    /// See `t0_s`.
    pub t1_s: f64,
    /// Samples in it.
    pub samples: usize,
    /// The largest residual in it under the base fit, µT.
    pub peak_ut: f64,
    /// The base fit's residual RMS in it (per axis, or of |B|), µT.
    pub rms_ut: f64,
    /// What explains it.
    pub kind: SpanKind,
    /// Whether it is modelled (the samples its constant explains kept, with an effect), or left out of the calibration.
    pub modelled: bool,
    /// In words, with the reason it was left out when it was.
    pub explanation: String,
    /// Of its samples, those the calibration kept all the same (see [`Diagnosis::kept_after_all`]).
    pub kept_samples: usize,
}

/// An effect the data suggested but the model may not hold, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Rejected {
    /// The effect.
    pub id: EffectId,
    /// Why it was rejected.
    pub why: String,
}

/// Two effects that explain the same residual.
#[derive(Clone, Debug, PartialEq)]
pub struct Ambiguity {
    /// The effect modelled and the alternative.
    pub ids: [EffectId; 2],
    /// Why they cannot be told apart here.
    pub why: String,
    /// The experiment that would separate them.
    pub experiment: String,
}

/// A fit's linear part and residuals (on the clean samples).
#[derive(Clone, Debug, PartialEq)]
pub struct FitSummary {
    /// `A`.
    pub a: Mat3,
    /// `b`, µT.
    pub b_ut: [f64; 3],
    /// Standard errors of `A`, `b` and the offset, from the diagnosis' problem.
    pub se: Option<LinearSe>,
    /// Residual RMS (per axis, or of |B|), µT.
    pub rms_ut: f64,
    /// Held-out residual RMS, µT.
    pub holdout_rms_ut: f64,
}

/// Standard errors of a fit's linear part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearSe {
    /// Of `A`'s entries.
    pub a: Mat3,
    /// Of `b`, µT.
    pub b_ut: [f64; 3],
    /// Of the offset `−A⁻¹·b`, µT.
    pub offset_ut: [f64; 3],
}

/// Per-sample residuals before and after, for plots: one component per calibrated axis (vector) or one (|B|).
#[derive(Clone, Debug, PartialEq)]
pub struct Residuals {
    /// The recording rows used.
    pub rows: Vec<usize>,
    /// Time, s (zero without a time column).
    pub t_s: Vec<f64>,
    /// The field direction in sensor axes.
    pub direction: Vec<[f64; 3]>,
    /// Residual of the base fit, µT.
    pub base: Components,
    /// Residual of the extended fit, µT.
    pub extended: Components,
    /// The channels the residual was compared with (`temp`, `i_<name>`, `t`, `rotation_rate`), per sample.
    pub channels: Vec<(String, Vec<f64>)>,
    /// Per sample, whether it was left out of the calibration (a gross span not modelled).
    pub excluded: Vec<bool>,
}

/// What the diagnosis found.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnosis {
    /// The overall finding.
    pub verdict: Verdict,
    /// Effects found and modelled, in the order they were chosen.
    pub effects: Vec<FoundEffect>,
    /// Effects that could not be told apart.
    pub ambiguous: Vec<Ambiguity>,
    /// Effects this recording cannot test (including the absorbed ones).
    pub untestable: Vec<Untestable>,
    /// Where the base model's residual departs from the noise; its segments are the gross spans.
    pub located: Located,
    /// The 12-parameter (or scalar) base fit on the clean samples (outside every gross span).
    pub base: FitSummary,
    /// The fit with the effects found.
    pub extended: FitSummary,
    /// The extended model: `A`, `b` and the body-fixed effects as corrections.
    pub model: Model,
    /// The noise floor in calibrated units, µT (per axis RMS, or of |B|).
    pub noise_floor_ut: f64,
    /// The reference's own error: what the final model's residual on the clean samples holds beyond the sensor's
    /// noise (attitude alignment, synchronisation, field gradients; for the scalar method, model errors), µT.
    pub reference_floor_ut: f64,
    /// The gross spans, in time order.
    pub spans: Vec<GrossSpan>,
    /// Effects suggested by the data but rejected, with why.
    pub rejected: Vec<Rejected>,
    /// Samples used; rows left out for a missing channel.
    pub samples_used: usize,
    /// Samples left out of the calibration in gross spans.
    pub samples_excluded: usize,
    /// See `samples_used`.
    pub samples_left_out: usize,
    /// Per-sample residuals before and after.
    pub residuals: Residuals,
}

impl GrossSpan {
    /// Whether the calibration kept every one of its samples after all ([`Diagnosis::kept_after_all`]).
    pub fn wholly_kept(&self) -> bool {
        self.kept_samples > 0 && self.kept_samples >= self.samples
    }
}

impl Diagnosis {
    /// Records that the calibration kept the recording rows `kept` (per row) after all, though the diagnosis left
    /// some of them out — its spans' fading edges and lulls, which fit as well as the clean part, or whose leaving
    /// out fitted held-out data no better — so that the spans, the counts and the per-sample flags say what the
    /// calibration did.
    pub fn kept_after_all(&mut self, kept: &[bool]) {
        let r = &mut self.residuals;
        let has_time = r.t_s.iter().any(|t| *t != 0.0);
        for (i, &row) in r.rows.iter().enumerate() {
            if !r.excluded[i] || !kept.get(row).copied().unwrap_or(false) {
                continue;
            }
            r.excluded[i] = false;
            self.samples_left_out = self.samples_left_out.saturating_sub(1);
            let at = if has_time { r.t_s[i] } else { i as f64 };
            if let Some(sp) = self
                .spans
                .iter_mut()
                .find(|sp| !sp.modelled && (sp.t0_s..=sp.t1_s).contains(&at))
            {
                sp.kept_samples += 1;
            }
        }
        const LEFT_OUT: &str = "left out of the calibration";
        for sp in self.spans.iter_mut().filter(|sp| sp.kept_samples > 0) {
            sp.explanation = if sp.wholly_kept() {
                sp.explanation.replacen(
                    LEFT_OUT,
                    "kept in the calibration (leaving its samples out fitted the rest no better)",
                    1,
                )
            } else {
                format!(
                    "{} (but for {} of its {} samples, kept: leaving them out fitted the rest no better)",
                    sp.explanation, sp.kept_samples, sp.samples
                )
            };
        }
    }
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
    let mut kept = samples.kept.clone();
    let mut scale = if input.scale_ut > 0.0 {
        input.scale_ut
    } else {
        setup.scale(&base_residual)
    };
    let mut span_residual = Cow::Borrowed(base_residual.as_slice());
    let mut left_out: Vec<(usize, usize, Declined)> = Vec::new();
    let mut rejected = Vec::new();
    let mut round = setup.round_or_declined(&span_residual, &kept, scale, &mut left_out)?;
    for _ in 1..ROUNDS {
        // Guard first: effects that make the model unphysical go, and if modelling the spans harms the clean
        // held-out fit, they are left out instead.
        let harmful_spans = setup.guard(&mut round, &mut rejected);
        if harmful_spans {
            left_out.extend(
                round
                    .spans
                    .iter()
                    .filter(|s| s.modelled())
                    .map(|s| (s.start, s.end, Declined::NoGain)),
            );
            round = setup.round_or_declined(&span_residual, &kept, scale, &mut left_out)?;
            continue;
        }
        // The scalar method's exclusions are the base fit's (its scan for shifted windows sees more than the gross
        // spans of one residual).
        if !setup.vector {
            break;
        }
        // The spans again, with the catalogue's effects out of the residual.
        let (a, b) = linear_of(&round.sel.last, setup.vector, base, setup.raw_mean);
        let effects = round.catalogue_effects();
        let residual = setup.residual(&a, b, &effects);
        let scale2 = setup.scale(&residual);
        let sizes: Vec<f64> = residual.iter().map(|e| setup.size(e)).collect();
        let times = samples.has_time.then_some(&samples.t[..]);
        let tail = crate::vector::VectorProblem::RAMP_TAIL;
        let kept2 = robust::outside(
            &robust::gross_spans(&sizes, scale2, times, tail),
            sizes.len(),
        );
        if kept2 == kept {
            break;
        }
        (kept, scale, span_residual) = (kept2, scale2, Cow::Owned(residual));
        round = setup.round_or_declined(&span_residual, &kept, scale, &mut left_out)?;
    }
    if setup.guard(&mut round, &mut rejected) {
        left_out.extend(
            round
                .spans
                .iter()
                .filter(|s| s.modelled())
                .map(|s| (s.start, s.end, Declined::NoGain)),
        );
        round = setup.round_or_declined(&span_residual, &kept, scale, &mut left_out)?;
        setup.guard(&mut round, &mut rejected);
    }
    let mut diagnosis = setup.report(round, base_residual, rejected, base);
    // The per-sample vectors the report shares with the samples, moved rather than copied.
    diagnosis.residuals.direction = setup.unit;
    diagnosis.residuals.rows = samples.rows;
    diagnosis.residuals.t_s = samples.t.into_owned();
    Ok((diagnosis, lag0_s))
}

/// Why no step is offered when the recording is too short to scan for one.
const NO_STEP_SCAN: &str = "the recording is too short to look for a step";
/// Why the scalar method offers no step when one side of it hardly turned.
const STILL_SIDE_OF_STEP: &str = "the sensor turned too little on one side of the likeliest step for the magnitude to \
                                  show the offset there";
/// The scalar method offers a step only when the clean samples on each side of it cover at least this share of the
/// directions all of them cover: on the physical BROAD 02 and Nexus 5 recordings with disturbances added, steps
/// with a side at 0.20 and 0.32 of it took up what was left of a field on the board or a magnet's pass, 3–7 µT off
/// in the offset; every step of the simulated power study (200 recordings) is still offered (at 0.5, 6 % were not).
const STEP_SIDE_COVERAGE: f64 = 0.35;
/// Cells of the sphere of directions for [`STEP_SIDE_COVERAGE`].
const STEP_SIDE_CELLS: usize = 100;

/// What every stage shares: the samples and what the reference offers.
struct Setup<'a> {
    input: &'a DiagnosisInput<'a>,
    samples: &'a Samples<'a>,
    vector: bool,
    /// The field magnitude (scalar: the fitted one; vector: the reference's mean), µT.
    field_ut: f64,
    raw_mean: [f64; 3],
    /// The field direction per sample, sensor axes.
    unit: Vec<[f64; 3]>,
    current_names: Vec<&'a str>,
    /// The noise floor in calibrated units (per axis RMS, or of |B|), µT.
    noise_floor_ut: f64,
    n_base: usize,
    /// The base fit the samples' fields were computed with (the scalar method's linearisation point).
    base: Model,
}

/// One batch's normal equations: its clean rows and its other included ones apart (the batch lies within one
/// cross-validation block), its batch sums, and per candidate the rows where it acts.
struct BatchPart {
    clean: BlockStats,
    other: BlockStats,
    batch: Batches,
    active: Vec<usize>,
}

/// One pass of stages 2–5.
struct Round {
    spans: Vec<Span>,
    /// Per sample: in the fits (clean, or in a modelled span's window).
    included: Vec<bool>,
    /// Per sample: outside every gross span.
    clean: Vec<bool>,
    cands: Vec<Candidate>,
    untestable: Vec<Untestable>,
    problem: Problem,
    sel: Selection,
}

impl<'a> Setup<'a> {
    fn new(input: &'a DiagnosisInput<'a>, samples: &'a Samples, base: &Model) -> Setup<'a> {
        let n = samples.len();
        let vector = !matches!(input.reference, Reference::Magnitude { .. });
        let field_ut = match input.reference {
            Reference::Magnitude { field_ut } => field_ut,
            _ => samples.field.iter().map(|f| frames::norm(*f)).sum::<f64>() / n as f64,
        };
        let raw_mean = frames::scale(
            samples.raw.iter().fold([0.0; 3], |s, m| frames::add(s, *m)),
            1.0 / n as f64,
        );
        let unit: Vec<[f64; 3]> = samples
            .field
            .iter()
            .map(|f| frames::scale(*f, 1.0 / frames::norm(*f)))
            .collect();
        let noise_floor_ut = if vector {
            input.noise.calibrated_rms_ut(&base.a)
        } else {
            // |B| noise: the calibrated noise along the field direction, averaged.
            let f = input.noise.floor_ut;
            let along: f64 = unit
                .iter()
                .map(|u| {
                    let au = frames::mat_t_vec(&base.a, *u);
                    (0..3).map(|k| (au[k] * f[k]).powi(2)).sum::<f64>()
                })
                .sum::<f64>()
                / n as f64;
            along.sqrt()
        };
        Setup {
            input,
            samples,
            vector,
            field_ut,
            raw_mean,
            unit,
            current_names: input.currents.iter().map(|(name, _)| *name).collect(),
            noise_floor_ut,
            n_base: if vector { 12 } else { 9 },
            base: *base,
        }
    }

    /// The residual per sample of `A·B̂ + b − Σδ` against the reference: three components (vector), or the
    /// magnitude's in the first (scalar).
    fn residual(&self, a: &Mat3, b: [f64; 3], effects: &[Effect]) -> Vec<[f64; 3]> {
        let s = self.samples;
        (0..s.len())
            .map(|i| {
                let ctx = s.context(i);
                let delta = effects
                    .iter()
                    .fold([0.0; 3], |acc, e| frames::add(acc, e.perturbation_ut(&ctx)));
                let cal = frames::sub(frames::add(frames::mat_vec(a, s.raw[i]), b), delta);
                if self.vector {
                    frames::sub(cal, s.field[i])
                } else {
                    [frames::norm(cal) - self.field_ut, 0.0, 0.0]
                }
            })
            .collect()
    }

    /// A residual's size, as the robust fit judges it.
    fn size(&self, e: &[f64; 3]) -> f64 {
        if self.vector {
            frames::norm(*e)
        } else {
            e[0].abs()
        }
    }

    /// The residual's scale: its median size as a standard deviation (per axis, or of |B|).
    fn scale(&self, residual: &[[f64; 3]]) -> f64 {
        let mut v: Vec<f64> = residual.iter().map(|e| self.size(e)).collect();
        let mid = v.len() / 2;
        let median = *v.select_nth_unstable_by(mid, f64::total_cmp).1;
        median
            / if self.vector {
                <crate::vector::VectorProblem<'_> as RobustProblem>::MEDIAN_OF_UNIT
            } else {
                <crate::scalar::ScalarProblem<'_> as RobustProblem>::MEDIAN_OF_UNIT
            }
    }

    /// [`Setup::round`]; if the spans' effects leave its base problem without a solution (a field in the room
    /// while the sensor hardly turned is nearly the offset), every span is left out instead (added to `left_out`).
    fn round_or_declined(
        &self,
        residual: &[[f64; 3]],
        kept: &[bool],
        scale: f64,
        left_out: &mut Vec<(usize, usize, Declined)>,
    ) -> Result<Round, FitError> {
        match self.round(residual, kept, scale, left_out) {
            Err(FitError::Singular(_)) => {
                left_out.extend(
                    robust::excluded_runs(kept)
                        .into_iter()
                        .map(|(a, b)| (a, b, Declined::Undetermined)),
                );
                self.round(residual, kept, scale, left_out)
            }
            other => other,
        }
    }

    /// Stages 2–5 on the spans of `residual`'s gross samples (those not `kept`), with the spans overlapping
    /// `left_out` not modelled.
    fn round(
        &self,
        residual: &[[f64; 3]],
        kept: &[bool],
        scale: f64,
        left_out: &[(usize, usize, Declined)],
    ) -> Result<Round, FitError> {
        let s = self.samples;
        let n = s.len();
        let rho: Vec<f64> = if self.vector {
            Vec::new()
        } else {
            residual.iter().map(|e| e[0]).collect()
        };
        let view = if self.vector {
            Residual::Vector {
                e: residual,
                rot: s.rot(),
            }
        } else {
            Residual::Magnitude {
                rho: &rho,
                unit: &self.unit,
                field_ut: self.field_ut,
            }
        };
        let mut spans = gross::spans(&view, kept, scale, &self.unit);
        let mut included = vec![true; n];
        let mut clean = vec![true; n];
        let mut span_effects = Vec::new();
        for span in &mut spans {
            clean[span.start..span.end].fill(false);
            included[span.start..span.end].fill(false);
            if let Some(&(_, _, why)) = left_out
                .iter()
                .find(|&&(a, b, _)| a < span.end && span.start < b)
            {
                span.declined = Some(why);
            }
            if !span.modelled() || !s.has_time {
                continue;
            }
            let (a, b) = if self.vector {
                gross::refine_edges(span, residual, s.rot(), scale)
            } else {
                (span.start, span.end)
            };
            for (i, inc) in included.iter_mut().enumerate().take(b).skip(a) {
                *inc = gross::explained_at(&view, &span.kind, i, scale);
            }
            let (t0_s, t1_s) = (candidates::between(s, a), candidates::between(s, b));
            let effect = match span.kind {
                SpanKind::RoomFixed { .. } => Effect::Disturbance {
                    t0_s,
                    t1_s,
                    field_ned_ut: [0.0; 3],
                },
                _ => Effect::BiasWindow {
                    t0_s,
                    t1_s,
                    offset_ut: [0.0; 3],
                },
            };
            let times = ScanTimes {
                start_s: (t0_s, t0_s),
                end_s: Some((t1_s, t1_s)),
                sample_interval_s: candidates::sample_interval_s(s),
            };
            span_effects.push((effect, times));
        }
        // Scans for small steps and windows run on the clean samples.
        let clean_idx: Vec<usize> = (0..n).filter(|&i| clean[i]).collect();
        let back = |k: usize| clean_idx.get(k).copied().unwrap_or(n);
        let remap = |sc: scan::Scan| scan::Scan {
            start: back(sc.start),
            end: back(sc.end),
            stat: sc.stat,
            start_interval: (back(sc.start_interval.0), back(sc.start_interval.1)),
            end_interval: (back(sc.end_interval.0), back(sc.end_interval.1)),
        };
        let sigma2 = clean_idx
            .iter()
            .map(|&i| frames::dot(residual[i], residual[i]))
            .sum::<f64>()
            / (clean_idx.len().max(1) * if self.vector { 3 } else { 1 }) as f64;
        let step = if !s.has_time {
            None
        } else if self.vector {
            let e_clean: Vec<[f64; 3]> = clean_idx.iter().map(|&i| residual[i]).collect();
            scan::step_vector(&e_clean, sigma2)
        } else {
            let rho_clean: Vec<f64> = clean_idx.iter().map(|&i| residual[i][0]).collect();
            let u_clean: Vec<[f64; 3]> = clean_idx.iter().map(|&i| self.unit[i]).collect();
            scan::step_scalar(&rho_clean, &u_clean, sigma2)
        };
        // The magnitude shows a step of the offset only where the sensor turned on both sides of it: from a still
        // stretch any offset fits, and a step there soaks up what is left of a disturbance beside it.
        let step = step.map(remap).ok_or(NO_STEP_SCAN).and_then(|st| {
            let covered = |r: std::ops::Range<usize>| {
                crate::coverage::sphere_fraction(
                    r.filter(|&i| clean[i]).map(|i| self.unit[i]),
                    STEP_SIDE_CELLS,
                )
            };
            let all = covered(0..n);
            let side = covered(0..st.start).min(covered(st.start..n));
            if self.vector || side >= STEP_SIDE_COVERAGE * all {
                Ok(st)
            } else {
                Err(STILL_SIDE_OF_STEP)
            }
        });
        let window = match (s.rot(), self.vector && s.has_time) {
            (Some(rot), true) => {
                let world: Vec<[f64; 3]> = clean_idx
                    .iter()
                    .map(|&i| frames::mat_vec(&rot.at(i), residual[i]))
                    .collect();
                scan::window(&world, sigma2)
            }
            _ => None,
        };
        let offer = Offer {
            samples: s,
            vector: self.vector,
            current_names: &self.current_names,
            step,
            window: window.map(remap),
            spans: span_effects,
        };
        let (mut cands, untestable) = candidates::candidates(&offer, self.n_base);
        let problem = self.accumulate(&mut cands, &included, &clean);
        let mut base_columns: Vec<usize> = (0..self.n_base).collect();
        for c in cands.iter().filter(|c| c.forced) {
            base_columns.extend(c.columns());
        }
        let sel = select(
            &problem,
            &base_columns,
            &cands,
            &self.a_columns(),
            self.noise_floor_ut.powi(2),
            if self.vector {
                select::MIN_EXCESS_SHARE
            } else {
                select::MIN_EXCESS_SHARE_MAGNITUDE
            },
        )
        .ok_or(FitError::Singular(
            "the diagnosis' base problem has no solution",
        ))?;
        Ok(Round {
            spans,
            included,
            clean,
            cands,
            untestable,
            problem,
            sel,
        })
    }

    /// The columns of `A` in the design.
    fn a_columns(&self) -> Vec<usize> {
        if self.vector {
            (0..3)
                .flat_map(|j| (0..3).map(move |k| 4 * j + k))
                .collect()
        } else {
            (0..6).collect()
        }
    }

    /// The normal equations of the included samples per block (and of the clean ones apart), counting where each
    /// candidate acts. Each batch of the autocorrelation lies within one block and is summed on its own, on all
    /// threads; the batches are merged in order.
    fn accumulate(&self, cands: &mut [Candidate], included: &[bool], clean: &[bool]) -> Problem {
        let columns = cands.last().map_or(self.n_base, |c| c.first + c.n);
        let dims = if self.vector { 3 } else { 1 };
        let parts = chunks::parts(AUTOCORRELATION_BATCHES, |batch| {
            self.accumulate_batch(batch, cands, included, clean, columns)
        });
        let mut blocks: Vec<BlockStats> =
            (0..CV_BLOCKS).map(|_| BlockStats::new(columns)).collect();
        let mut clean_blocks = blocks.clone();
        let mut batches = Batches::new(AUTOCORRELATION_BATCHES, dims, columns);
        let mut batch_stats = Vec::with_capacity(parts.len());
        let mut active = vec![0usize; cands.len()];
        for (batch, part) in parts.iter().enumerate() {
            let b = batch / (AUTOCORRELATION_BATCHES / CV_BLOCKS);
            blocks[b].add(&part.clean);
            blocks[b].add(&part.other);
            clean_blocks[b].add(&part.clean);
            batches.put(batch, &part.batch);
            let mut all = part.clean.clone();
            all.add(&part.other);
            batch_stats.push(all);
            for (a, p) in active.iter_mut().zip(&part.active) {
                *a += p;
            }
        }
        for (c, cand) in cands.iter_mut().enumerate() {
            cand.active_rows = active[c];
        }
        let mut noise_var = DVector::zeros(columns);
        if self.vector {
            for j in 0..3 {
                for k in 0..3 {
                    noise_var[4 * j + k] = self.input.noise.floor_ut[k].powi(2);
                }
            }
        }
        Problem::new(blocks, clean_blocks, batches, batch_stats, noise_var)
    }

    /// [`Setup::accumulate`] over the samples of one batch (`i·BATCHES/n` = `batch`); a candidate's zero regressors
    /// are left out of the rows.
    fn accumulate_batch(
        &self,
        batch: usize,
        cands: &[Candidate],
        included: &[bool],
        clean: &[bool],
        columns: usize,
    ) -> BatchPart {
        let s = self.samples;
        let n = s.len();
        let dims = if self.vector { 3 } else { 1 };
        let mut part = BatchPart {
            clean: BlockStats::new(columns),
            other: BlockStats::new(columns),
            batch: Batches::new(1, dims, columns),
            active: vec![0; cands.len()],
        };
        let first = (batch * n).div_ceil(AUTOCORRELATION_BATCHES);
        let end = ((batch + 1) * n).div_ceil(AUTOCORRELATION_BATCHES);
        let mut entries: Vec<(usize, f64)> = Vec::with_capacity(columns);
        let mut cross: Vec<(usize, f64)> = Vec::new();
        let mut regs: Vec<[[f64; 3]; 3]> = vec![[[0.0; 3]; 3]; cands.len()];
        let probes: Vec<candidates::Probes> = cands.iter().map(Candidate::probes).collect();
        for i in (first..end).filter(|&i| included[i]) {
            let ctx = s.context(i);
            for (reg, probe) in regs.iter_mut().zip(&probes) {
                *reg = probe.regressors(&ctx);
            }
            let mc = frames::sub(s.raw[i], self.raw_mean);
            let stats = if clean[i] {
                &mut part.clean
            } else {
                &mut part.other
            };
            stats.samples += 1;
            if self.vector {
                for j in 0..3 {
                    entries.clear();
                    entries.extend((0..3).map(|k| (4 * j + k, mc[k])));
                    entries.push((4 * j + 3, 1.0));
                    push_candidates(&mut entries, cands, &mut part.active, |c, k| -regs[c][k][j]);
                    stats.add_row(&entries, s.field[i][j]);
                    part.batch.add_row(0, j, &entries, s.field[i][j]);
                }
            } else {
                // ρ + J·Δ − u·G·θ ≈ 0 around the base fit (ρ: its residual), with the readings centred.
                let u = self.unit[i];
                entries.clear();
                for (k, (r, q)) in SYM.iter().enumerate() {
                    let d = if r == q {
                        u[*r] * mc[*q]
                    } else {
                        u[*r] * mc[*q] + u[*q] * mc[*r]
                    };
                    entries.push((k, d));
                }
                entries.extend((0..3).map(|k| (6 + k, u[k])));
                push_candidates(&mut entries, cands, &mut part.active, |c, k| {
                    -frames::dot(u, regs[c][k])
                });
                let rho = self.base_rho(i);
                stats.add_row(&entries, -rho);
                part.batch.add_row(0, 0, &entries, -rho);
                // The observation −ρ and every regressor carry the same reading noise n: −ρ's is −(Aᵀu)·n, a
                // regressor x's is ∇x·n, so cov(x, −ρ) = −∇x·d with d = Σₙ·Aᵀu. Left in, it is a correlation the
                // fit would credit to whatever regressor the noise bends most (a cubic in the field): its
                // derivative along d, per column, corrects Xᵀy.
                let f = self.input.noise.floor_ut;
                let au = frames::mat_t_vec(&self.base.a, u);
                let d: [f64; 3] = std::array::from_fn(|k| f[k] * f[k] * au[k]);
                let ad = frames::mat_vec(&self.base.a, d);
                let size = frames::norm(ad);
                if size > 0.0 {
                    let field = s.field[i];
                    let du = frames::scale(
                        frames::sub(ad, frames::scale(u, frames::dot(u, ad))),
                        1.0 / frames::norm(field),
                    );
                    cross.clear();
                    for (k, (r, q)) in SYM.iter().enumerate() {
                        let mut g = du[*r] * mc[*q] + u[*r] * d[*q];
                        if r != q {
                            g += du[*q] * mc[*r] + u[*q] * d[*r];
                        }
                        cross.push((k, g));
                    }
                    cross.extend((0..3).map(|k| (6 + k, du[k])));
                    let mut shifted = ctx;
                    shifted.field_ut = frames::add(field, frames::scale(ad, NOISE_STEP_UT / size));
                    for (c, (cand, probe)) in cands.iter().zip(&probes).enumerate() {
                        let moved = probe.regressors(&shifted);
                        for k in 0..cand.n {
                            let dreg = frames::scale(
                                frames::sub(moved[k], regs[c][k]),
                                size / NOISE_STEP_UT,
                            );
                            let g = -(frames::dot(du, regs[c][k]) + frames::dot(u, dreg));
                            if g != 0.0 {
                                cross.push((cand.first + k, g));
                            }
                        }
                    }
                    stats.add_noise_cross(&cross);
                }
            }
        }
        part
    }

    /// The scalar method's base residual of sample `i` (zero for the vector method, whose rows need none).
    fn base_rho(&self, i: usize) -> f64 {
        if self.vector {
            0.0
        } else {
            frames::norm(self.samples.field[i]) - self.field_ut
        }
    }

    /// Stage 6: drops the chosen effects that make the model unphysical, then, while the clean held-out samples fit
    /// worse than with the base fit alone, the catalogue's effects last first. Returns whether the modelled spans
    /// themselves are not worth their rows (then they are to be left out): see [`Round::spans_worth_their_rows`].
    fn guard(&self, round: &mut Round, rejected: &mut Vec<Rejected>) -> bool {
        let linear: Vec<usize> = (0..self.n_base).collect();
        let Some(base12) = round.problem.solve_on(Rows::Clean, &linear, None, true) else {
            return false;
        };
        let (a_base, _) = linear_of(&base12, self.vector, &self.base, self.raw_mean);
        loop {
            let chosen = round.chosen_steps();
            let mut drop = chosen.iter().find_map(|&c| {
                let effect = round.fitted_effect(c, &round.sel.last);
                guard::implausible(&effect, self.samples, self.field_ut).map(|why| (c, why))
            });
            if drop.is_none() {
                drop = chosen.iter().find_map(|&c| {
                    let &(_, other) = round.sel.ambiguous.iter().find(|(a, _)| *a == c)?;
                    let step = round.sel.steps.iter().find(|s| s.cand == c)?;
                    let rows = round.problem.clean_total.rows.max(1) as f64;
                    let (before, after) = ((step.cv.0 / rows).sqrt(), (step.cv.1 / rows).sqrt());
                    (before - after < NOTICEABLE_GAIN * before).then(|| {
                        let ids = (round.cands[c].id(), round.cands[other].id());
                        (c, guard::guess_why(ids.0, ids.1, before, after))
                    })
                });
            }
            if drop.is_none()
                && let Some(&last) = chosen.last()
            {
                let (a, _) = linear_of(&round.sel.last, self.vector, &self.base, self.raw_mean);
                // A timing effect corrects the reference, not the sensor: the gains are judged against the base
                // fit with it (a lag of 64 ms bends the base fit's gains by more than the rule allows).
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
                        Some(fit) => linear_of(&fit, self.vector, &self.base, self.raw_mean).0,
                        None => a_base,
                    }
                };
                let change = guard::gain_change(&a, &a_base);
                if change > guard::MAX_GAIN_CHANGE {
                    drop = Some((last, guard::gains_why(change)));
                }
            }
            // The catalogue's effects last first while the clean held-out samples fit worse than with the base fit
            // alone; without one, the modelled spans answer for it (below: a span worse than the base is not worth
            // its rows either).
            if drop.is_none()
                && let Some(&last) = chosen.last()
            {
                let problem = &round.problem;
                let cv_base = problem.cv_rss_on(Rows::Clean, &linear);
                let cv_final = problem.cv_rss(&round.sel.last.columns);
                if let (Some(cv_base), Some(cv_final)) = (cv_base, cv_final)
                    && cv_final > cv_base
                {
                    let rows = problem.clean_total.rows.max(1) as f64;
                    let rms = |x: f64| (x / rows).sqrt();
                    let id = round.cands[last].id();
                    drop = Some((last, guard::harm_why(id, rms(cv_final), rms(cv_base))));
                }
            }
            let Some((c, why)) = drop else {
                return !round.spans_worth_their_rows();
            };
            rejected.push(Rejected {
                id: round.cands[c].id(),
                why,
            });
            round.remove(c);
        }
    }
}

impl Round {
    /// Whether the modelled spans' rows are worth keeping: with them, the clean rows' held-out residual is
    /// noticeably ([`NOTICEABLE_GAIN`]) lower than with the same model fitted on the clean rows alone. A gain nobody
    /// would notice does not pay for a constant fitted to a disturbance whose edges and shape are only estimated
    /// (true when no span is modelled).
    fn spans_worth_their_rows(&self) -> bool {
        if !self.spans.iter().any(|s| s.modelled()) {
            return true;
        }
        let forced: Vec<usize> = self
            .cands
            .iter()
            .filter(|c| c.forced)
            .flat_map(|c| c.columns())
            .collect();
        let without: Vec<usize> = self
            .sel
            .last
            .columns
            .iter()
            .copied()
            .filter(|c| !forced.contains(c))
            .collect();
        match (
            self.problem.cv_rss(&self.sel.last.columns),
            self.problem.cv_rss_on(Rows::Clean, &without),
        ) {
            (Some(with), Some(alone)) => with.sqrt() <= (1.0 - NOTICEABLE_GAIN) * alone.sqrt(),
            // Without the spans' rows the model cannot be fitted: they are needed.
            (Some(_), None) => true,
            _ => false,
        }
    }

    /// The selected catalogue candidates still in the model, in the order they were chosen.
    fn chosen_steps(&self) -> Vec<usize> {
        self.sel
            .steps
            .iter()
            .filter(|step| !self.sel.steps.iter().any(|s| s.replaced == Some(step.cand)))
            .map(|step| step.cand)
            .collect()
    }

    /// Candidate `c` with its parameters from a solution.
    fn fitted_effect(&self, c: usize, sol: &stats::Solution) -> Effect {
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
    fn catalogue_effects(&self) -> Vec<Effect> {
        self.chosen_steps()
            .into_iter()
            .map(|c| self.fitted_effect(c, &self.sel.last))
            .collect()
    }

    /// Takes candidate `c` out of the model: its step goes, and the last solution is solved again without it.
    fn remove(&mut self, c: usize) {
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

impl Setup<'_> {
    /// Stage 7: the report of a round.
    fn report(
        &self,
        mut round: Round,
        base_residual: Vec<[f64; 3]>,
        rejected: Vec<Rejected>,
        base: &Model,
    ) -> Diagnosis {
        let s = self.samples;
        let n = s.len();
        let problem = &round.problem;
        let vector = self.vector;
        let linear: Vec<usize> = (0..self.n_base).collect();
        let clean_rows = problem.clean_total.rows.max(1) as f64;
        let rms = |rss: f64| (rss / clean_rows).sqrt();
        let last = round.sel.last.clone();
        let rows = problem.total.rows as f64;
        let dof = (rows - last.columns.len() as f64).max(1.0);
        // Standard errors allow for residuals that are alike from sample to sample (see `select`): the variance per
        // row is scaled by the autocorrelation factor.
        let tau_last = problem.autocorrelation(&last);
        let sigma2_last = last.rss / dof * tau_last;
        // The base fit on the clean samples alone, and its held-out residual there.
        let base12 = problem
            .solve_on(Rows::Clean, &linear, None, true)
            .unwrap_or_else(|| round.sel.base.clone());
        let base_cv = problem
            .cv_rss_on(Rows::Clean, &linear)
            .unwrap_or(round.sel.base_cv);
        // The final linear part is the base fit's moved by what the effects change in this problem's least squares:
        // without effects it is the base fit itself (whose scalar solver has a shape prior and direction weights the
        // linearised problem does not). In the vector method with effects, this problem's fit is the base fit's
        // least squares with the effects modelled, on the rows it includes, and is the final one: moved from the
        // base fit by the difference to the clean rows' fit, it took back in the pull of rows the robust fit kept and
        // this problem explains (a field on the board that the reference's own error hid in places) or leaves out
        // (it once did so for want of one row: a gross sample the diagnosis left out put A 0.058 off on BROAD 02
        // with 5.6 µT on its board).
        let (ext_a, ext_b) = if vector && last.columns.len() > linear.len() {
            linear_of(&last, vector, base, self.raw_mean)
        } else {
            let (a1, b1) = linear_of(&last, vector, base, self.raw_mean);
            let (a0, b0) = linear_of(&base12, vector, base, self.raw_mean);
            let a: Mat3 = std::array::from_fn(|j| {
                std::array::from_fn(|k| base.a[j][k] + a1[j][k] - a0[j][k])
            });
            let b: [f64; 3] = std::array::from_fn(|j| base.b_ut[j] + b1[j] - b0[j]);
            (a, b)
        };
        let (base_a, base_b) = (base.a, base.b_ut);

        // The effects with their fitted parameters: the modelled spans', then the catalogue's in the order chosen.
        let forced: Vec<usize> = (0..round.cands.len())
            .filter(|&c| round.cands[c].forced)
            .collect();
        let steps: Vec<select::Step> = round
            .sel
            .steps
            .iter()
            .filter(|st| !round.sel.steps.iter().any(|o| o.replaced == Some(st.cand)))
            .cloned()
            .collect();
        let mut chosen: Vec<(usize, Effect, [f64; 3])> = forced
            .iter()
            .copied()
            .chain(steps.iter().map(|st| st.cand))
            .map(|c| {
                let cand = &round.cands[c];
                let mut se = [0.0; 3];
                for (k, x) in se.iter_mut().enumerate().take(cand.n) {
                    *x = coefficient(&last, cand.first + k, sigma2_last)
                        .map_or(f64::NAN, |(_, s)| s);
                }
                (c, round.fitted_effect(c, &last), se)
            })
            .collect();
        self.relocate(
            &mut round.cands,
            &round.clean,
            &mut chosen,
            &ext_a,
            ext_b,
            last.rss / rows,
        );

        let mut model = Model::linear(ext_a, ext_b);
        let mut effects = Vec::new();
        let all: Vec<Effect> = chosen.iter().map(|c| c.1).collect();
        let final_residual = self.residual(&ext_a, ext_b, &all);
        let sizes = self.sizes(&chosen, &final_residual);
        let dims = if vector { 3 } else { 1 };
        let extended = Components::from_residuals(final_residual, dims);
        for (k, (c, effect, se)) in chosen.iter().enumerate() {
            let cand = &round.cands[*c];
            if effect.id().frame() == Frame::Body && !effect.id().is_transient() {
                model.add_correction(*effect).expect(
                    "candidates are limited so that every body-fixed effect fits in a model",
                );
            }
            let (rss, cv, evidence) = match steps.iter().find(|st| st.cand == *c) {
                Some(st) => (st.rss, st.cv, st.evidence),
                // A span's effect: its samples are not in the clean held-out set, so its figures are the residual
                // inside the span under the base fit and under the final model.
                None => {
                    let inside = sizes[k].1;
                    let before = round
                        .spans
                        .iter()
                        .find(|sp| {
                            sp.modelled() && {
                                let (t0, t1) = span_time(s, sp);
                                t0 <= effect_t1(effect) && effect_t0(effect) <= t1
                            }
                        })
                        .map_or(inside, |sp| sp.rms_ut);
                    let sq = |x: f64| x * x * clean_rows;
                    // Its evidence as a selected effect's would be: the Wald statistic less the BIC penalty.
                    let evidence = select::wald(&last, cand, false, rows) / tau_last
                        - cand.n as f64 * (rows / tau_last).ln();
                    ((sq(before), sq(inside)), (sq(before), sq(inside)), evidence)
                }
            };
            let holdout = (rms(cv.0), rms(cv.1));
            let what = explain::what(effect, cand.channel.as_deref(), self.field_ut);
            effects.push(FoundEffect {
                explanation: explain::explain(&what, holdout, self.noise_floor_ut),
                what,
                params: params_of(effect, *se, cand, last.rss / rows * tau_last),
                effect: *effect,
                channel: cand.channel.clone(),
                rms_before_ut: rms(rss.0),
                rms_after_ut: rms(rss.1),
                holdout_rms_before_ut: holdout.0,
                holdout_rms_after_ut: holdout.1,
                evidence,
                size_ut: sizes[k].0,
            });
        }
        let ambiguous = round
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
            .collect();
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
                        format!("not excited{name}: {}", not_excited(cand.id()))
                    }
                    SetAside::Absorbed {
                        unabsorbed,
                        takes_up,
                    } => format!(
                        "absorbed — not testable with this data{name}: the base fit takes up {:.1} % of it, so it \
                         would bias {takes_up}",
                        100.0 * (1.0 - unabsorbed)
                    ),
                },
            });
        }

        let channels = self.channels();
        let floor_axes: Vec<f64> = if vector {
            self.input.noise.calibrated_ut(&base.a).to_vec()
        } else {
            vec![self.noise_floor_ut]
        };
        // Where the mismatch is, on the samples the calibration used (the samples themselves when all are); its
        // segments are the gross spans.
        let used: Vec<usize> = (0..n).filter(|&i| round.included[i]).collect();
        let all_used = used.len() == n;
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
            Cow::Borrowed(&self.unit)
        } else {
            Cow::Owned(used.iter().map(|&i| self.unit[i]).collect())
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
        let mut located = locate::locate(
            &used_rows,
            &floor_axes,
            used_t.as_deref(),
            &used_dirs,
            &channel_values,
        );
        let spans: Vec<GrossSpan> = round.spans.iter().map(|sp| self.gross_span(sp)).collect();
        located.segments = spans
            .iter()
            .map(|sp| Segment {
                t0_s: sp.t0_s,
                t1_s: sp.t1_s,
                rms_ut: sp.rms_ut,
            })
            .collect();
        let reference_floor_ut = (rms(problem.clean_rss(&last)).powi(2)
            - self.noise_floor_ut.powi(2))
        .max(0.0)
        .sqrt();
        let verdict = if effects.is_empty() && spans.is_empty() {
            Verdict::Consistent
        } else {
            Verdict::Mismatch
        };
        let excluded: Vec<bool> = round.included.iter().map(|i| !i).collect();
        Diagnosis {
            verdict,
            effects,
            ambiguous,
            untestable,
            located,
            base: FitSummary {
                a: base_a,
                b_ut: base_b,
                se: Some(linear_se(
                    problem,
                    &base12,
                    rows,
                    vector,
                    (&base_a, base_b),
                    self.raw_mean,
                )),
                rms_ut: rms(problem.clean_rss(&base12)),
                holdout_rms_ut: rms(base_cv),
            },
            extended: FitSummary {
                a: ext_a,
                b_ut: ext_b,
                se: Some(linear_se(
                    problem,
                    &last,
                    rows,
                    vector,
                    (&ext_a, ext_b),
                    self.raw_mean,
                )),
                rms_ut: rms(problem.clean_rss(&last)),
                holdout_rms_ut: rms(round.sel.last_cv),
            },
            model,
            noise_floor_ut: self.noise_floor_ut,
            reference_floor_ut,
            spans,
            rejected,
            samples_used: used.len(),
            samples_excluded: n - used.len(),
            samples_left_out: s.left_out,
            // Filled by `diagnose`.
            residuals: Residuals {
                rows: Vec::new(),
                t_s: Vec::new(),
                direction: Vec::new(),
                base: base_rows,
                extended,
                channels,
                excluded,
            },
        }
    }

    /// A scanned time was located on the base residual, which the base fit had partly bent to the effect; locate it
    /// again on the extended fit's residual with every other effect removed.
    fn relocate(
        &self,
        cands: &mut [Candidate],
        clean: &[bool],
        chosen: &mut [(usize, Effect, [f64; 3])],
        ext_a: &Mat3,
        ext_b: [f64; 3],
        sigma2: f64,
    ) {
        let s = self.samples;
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
            let partial = self.residual(ext_a, ext_b, &others);
            let clean_idx: Vec<usize> = (0..s.len()).filter(|&i| clean[i]).collect();
            let e: Vec<[f64; 3]> = clean_idx.iter().map(|&i| partial[i]).collect();
            let rescan = match (effect, self.vector) {
                (Effect::BiasStep { .. }, true) => scan::step_vector(&e, sigma2),
                (Effect::BiasStep { .. }, false) => {
                    let rho: Vec<f64> = e.iter().map(|x| x[0]).collect();
                    let u: Vec<[f64; 3]> = clean_idx.iter().map(|&i| self.unit[i]).collect();
                    scan::step_scalar(&rho, &u, sigma2)
                }
                _ => s.rot().and_then(|rot| {
                    let world: Vec<[f64; 3]> = clean_idx
                        .iter()
                        .map(|&i| frames::mat_vec(&rot.at(i), partial[i]))
                        .collect();
                    scan::window(&world, sigma2)
                }),
            };
            let Some(w) = rescan else { continue };
            let back = |x: usize| clean_idx.get(x).copied().unwrap_or(s.len());
            let w = scan::Scan {
                start: back(w.start),
                end: back(w.end),
                stat: w.stat,
                start_interval: (back(w.start_interval.0), back(w.start_interval.1)),
                end_interval: (back(w.end_interval.0), back(w.end_interval.1)),
            };
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

    /// Each effect's size (RMS per axis of its perturbation where it acts), and the final model's residual RMS per
    /// axis where it acts (`residual`: the final model's, per sample).
    fn sizes(
        &self,
        chosen: &[(usize, Effect, [f64; 3])],
        residual: &[[f64; 3]],
    ) -> Vec<(f64, f64)> {
        let s = self.samples;
        let dims = if self.vector { 3.0 } else { 1.0 };
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

    /// The channels the residual is compared with, per sample.
    fn channels(&self) -> Vec<(String, Vec<f64>)> {
        let s = self.samples;
        let n = s.len();
        let mut channels: Vec<(String, Vec<f64>)> = Vec::new();
        if s.has_temp {
            channels.push(("temp".to_owned(), s.temp.to_vec()));
        }
        for (k, name) in self.current_names.iter().enumerate() {
            channels.push((
                (*name).to_owned(),
                (0..n).map(|i| s.currents[i * s.n_currents + k]).collect(),
            ));
        }
        if s.has_time {
            channels.push(("t".to_owned(), s.t.to_vec()));
        }
        if self.vector && s.has_time {
            channels.push((
                "rotation_rate".to_owned(),
                s.rate.iter().map(|r| frames::norm(*r)).collect(),
            ));
        }
        channels
    }

    /// A span as the report gives it.
    fn gross_span(&self, sp: &Span) -> GrossSpan {
        let (t0_s, t1_s) = span_time(self.samples, sp);
        let when = if self.samples.has_time {
            format!("{t0_s:.2}–{t1_s:.2} s")
        } else {
            format!("samples {}–{}", sp.start, sp.end)
        };
        let explanation = match sp.kind {
            SpanKind::SensorFixed { offset_ut, .. }
            | SpanKind::RoomFixed {
                field_ned_ut: offset_ut,
            } if !sp.turned => {
                format!(
                    "{when}: a constant field of {:.1} µT while the sensor hardly turned (fixed to the sensor or to \
                     the room: they cannot be told apart, nor from something that moved) — left out of the calibration",
                    frames::norm(offset_ut)
                )
            }
            SpanKind::SensorFixed {
                offset_ut,
                told_apart: true,
            }
            | SpanKind::RoomFixed {
                field_ned_ut: offset_ut,
            } if sp.declined.is_some() => format!(
                "{when}: a field of {:.1} µT fixed to the {} — left out of the calibration: {}",
                frames::norm(offset_ut),
                if matches!(sp.kind, SpanKind::RoomFixed { .. }) {
                    "room"
                } else {
                    "sensor"
                },
                match sp.declined {
                    Some(Declined::Undetermined) => {
                        "modelled, it left the fit without a solution"
                    }
                    _ =>
                        "with its samples kept and modelled, the clean part fitted no better on held-out data",
                }
            ),
            SpanKind::SensorFixed {
                offset_ut,
                told_apart: true,
            } => format!(
                "{when}: a field of {:.1} µT fixed to the sensor — modelled (bias_window), the samples it explains kept",
                frames::norm(offset_ut)
            ),
            SpanKind::SensorFixed { offset_ut, .. } => format!(
                "{when}: a constant field of {:.1} µT, fixed to the sensor or to the room: the two cannot be told apart \
                 here{} — left out of the calibration",
                frames::norm(offset_ut),
                if self.vector {
                    ""
                } else {
                    " (the magnitude alone does not show the frame)"
                }
            ),
            SpanKind::RoomFixed { field_ned_ut } => format!(
                "{when}: a field of {:.1} µT fixed in the room — modelled (disturbance), the samples it explains kept",
                frames::norm(field_ned_ut)
            ),
            SpanKind::MagnitudeShift { shift_ut } => format!(
                "{when}: the field's magnitude {} by {:.1} µT throughout while the sensor turned — a field fixed in \
                 the room (a magnet or steel placed nearby, then taken away); left out of the calibration",
                if shift_ut > 0.0 { "raised" } else { "lowered" },
                shift_ut.abs()
            ),
            SpanKind::Moving => format!(
                "{when}: up to {:.1} µT, changing as the sensor moved — a magnet or steel nearby; left out of the \
                 calibration",
                sp.peak_ut
            ),
            SpanKind::Unexplained => format!(
                "{when}: up to {:.1} µT, {} — left out of the calibration",
                sp.peak_ut,
                if sp.end - sp.start <= 3 {
                    "a glitch of a few samples"
                } else {
                    "neither fixed to the sensor nor to the room while the sensor was still (something moved near \
                     it)"
                }
            ),
        };
        GrossSpan {
            t0_s,
            t1_s,
            samples: sp.end - sp.start,
            peak_ut: sp.peak_ut,
            rms_ut: sp.rms_ut,
            kind: sp.kind,
            modelled: sp.modelled(),
            explanation,
            kept_samples: 0,
        }
    }
}

/// Appends the candidates' values in a row (`value(c, k)`: candidate `c`'s parameter `k`), the zeros left out, and
/// counts the candidates that act in it.
fn push_candidates(
    entries: &mut Vec<(usize, f64)>,
    cands: &[Candidate],
    active: &mut [usize],
    value: impl Fn(usize, usize) -> f64,
) {
    for (c, cand) in cands.iter().enumerate() {
        let before = entries.len();
        entries.extend(
            (0..cand.n)
                .map(|k| (cand.first + k, value(c, k)))
                .filter(|(_, v)| *v != 0.0),
        );
        if entries.len() > before {
            active[c] += 1;
        }
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
