//! What the diagnosis hands back: the effects found and modelled, the gross spans and what each was, the effects it
//! could not test or tell apart, the base and extended fits, and the per-sample residuals for plots.

use crate::effects::{Effect, EffectId};
use crate::frames::Mat3;
use crate::model::Model;

use super::candidates::Untestable;
use super::gross::SpanKind;
use super::locate::{Components, Located};

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

/// A gross span that is no finding: at most a few samples long, or within what the recording's own noise makes by
/// chance anywhere in it. Left out of the calibration and counted; it says nothing of the physics.
#[derive(Clone, Debug, PartialEq)]
pub struct Glitch {
    /// First and last sample's time, s (the sample indices without a time column).
    pub t0_s: f64,
    /// See `t0_s`.
    pub t1_s: f64,
    /// Samples in it.
    pub samples: usize,
    /// The largest residual in it, µT.
    pub peak_ut: f64,
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
    /// Each sample is every `stride`-th usable row of the recording (1: every one; a recording of more than
    /// [`MOST_SAMPLES`](super::samples::MOST_SAMPLES) samples is diagnosed on some).
    pub stride: usize,
}

impl Residuals {
    /// The recording rows left out of the calibration: those of the samples `excluded`, and, on a thinned
    /// recording, the rows between two such samples in a row.
    pub fn excluded_rows(&self) -> Vec<usize> {
        rows_of(&self.rows, |k| self.excluded[k], self.stride)
    }
}

/// The recording rows of the samples (at recording rows `rows`, every `stride`-th usable row) that are `flagged` (by
/// their index): each one's own, and the rows between two flagged samples in a row.
pub(crate) fn rows_of(
    rows: &[usize],
    flagged: impl Fn(usize) -> bool,
    stride: usize,
) -> Vec<usize> {
    let mut out = Vec::new();
    for (k, &row) in rows.iter().enumerate().filter(|(k, _)| flagged(*k)) {
        out.push(row);
        if stride > 1 && k + 1 < rows.len() && flagged(k + 1) {
            out.extend(row + 1..rows[k + 1]);
        }
    }
    out
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
    /// The gross spans that are findings, in time order.
    pub spans: Vec<GrossSpan>,
    /// The gross spans that are glitches, in time order: left out of the calibration, no finding.
    pub glitches: Vec<Glitch>,
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
            self.samples_excluded = self.samples_excluded.saturating_sub(1);
            self.samples_used += 1;
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

#[cfg(test)]
mod tests {
    use super::rows_of;

    #[test]
    fn the_rows_between_two_samples_left_out_are_left_out_on_a_thinned_recording() {
        // Samples at rows 0, 3, 6, 9, 12 (every third); those at 3, 6 and 12 flagged.
        let rows = [0, 3, 6, 9, 12];
        let flagged = [false, true, true, false, true];
        assert_eq!(rows_of(&rows, |k| flagged[k], 3), [3, 4, 5, 6, 12]);
        // Sample by sample, each its own row.
        assert_eq!(
            rows_of(&[0, 1, 2, 4], |k| [true, true, false, true][k], 1),
            [0, 1, 4]
        );
    }
}
