//! The short human summary `magcal-fit` prints: the heading error and the verdict first, then the parameters, the
//! fit, and the diagnosis.

use std::fmt::Write;

use magcal_calib::diagnosis::{
    Diagnosis, FoundEffect, Glitch, GrossSpan, NOTICEABLE_GAIN, Verdict as Finding,
};

use crate::apply::{Against, Check};
use crate::field::ReferenceField;
use crate::fit::{Calibration, Method};
use crate::heading::HeadingErrors;
use crate::params::ParamsFile;
use crate::verdict::{Assessment, GOOD_DEG, USABLE_DEG, Verdict, fmt_deg};

/// A channel the residual follows is named only when it explains at least this share of the residual's variance.
pub const CHANNEL_SHARE_SHOWN: f64 = 0.05;

/// `value ±se` with the standard error in two significant digits and the value to the same decimal place.
pub fn fmt_se(value: f64, se: f64) -> String {
    if !(se.is_finite() && se > 0.0) {
        return format!("{value:.5} (no standard error)");
    }
    // The decimal place of the standard error's second significant digit (one fewer if rounding carries over).
    let mut place = 1 - se.log10().floor() as i32;
    if (se * 10f64.powi(place)).round() >= 100.0 {
        place -= 1;
    }
    let decimals = place.max(0) as usize;
    format!("{value:.decimals$} ±{se:.decimals$}")
}

/// The heading figures in three lines (the last without a figure when the sensor's noise could not be measured);
/// `bound`: the figures left are an upper bound, what a check can resolve ([`crate::apply::Resolution`]).
fn heading_lines(h: &HeadingErrors, scalar: bool, noise_measured: bool, bound: bool) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "heading error, sensor level over 360 headings (horizontal field {:.1} µT, inclination {:.1}°, the worse side \
         up):",
        h.field.horizontal_ut,
        h.field.inclination_deg()
    );
    let _ = writeln!(
        out,
        "  removed by the calibration (the raw readings' error):  worst {}, RMS {}",
        fmt_deg(h.before.worst_deg),
        fmt_deg(h.before.rms_deg)
    );
    let left = format!(
        "  left after it ({}):",
        if bound {
            "at most: what the check resolves"
        } else {
            "one standard deviation"
        }
    );
    let _ = writeln!(
        out,
        "{left:<57}worst {}, RMS {}{}",
        fmt_deg(h.left.worst_deg),
        fmt_deg(h.left.rms_deg),
        if scalar {
            " (not included: a tilt of the sensor on its mount, a field not the same everywhere it went)"
        } else {
            ""
        },
    );
    if noise_measured {
        let _ = writeln!(
            out,
            "  a single reading's noise adds ±{} (averaging readings reduces it)",
            fmt_deg(h.noise_deg)
        );
    } else {
        out += "  a single reading's noise: not measured (the rows change orientation from one to the next)\n";
    }
    out
}

/// The verdict in one line, with the gate.
fn verdict_line(v: &Verdict) -> String {
    format!(
        "verdict: {} — {}. To do: {}. (good ≤ {}, usable ≤ {} left at worst)\n",
        v.grade.name().to_uppercase(),
        v.reason,
        v.todo,
        fmt_deg(GOOD_DEG),
        fmt_deg(USABLE_DEG)
    )
}

/// What `magcal-apply` prints: a parameters file checked on `recording`.
pub fn check_summary(
    c: &Check,
    params: &ParamsFile,
    field: &ReferenceField,
    recording: &str,
) -> String {
    let mut out = String::new();
    let fitted_on = params
        .recording
        .as_ref()
        .map_or(String::new(), |r| format!(", fitted on {r}"));
    let against = match &c.against {
        Against::Vector => "against the expected field (attitude reference)".to_owned(),
        Against::Magnitude { field_ut, known } => format!(
            "against the field magnitude {field_ut:.2} µT ({})",
            if *known {
                field.source()
            } else {
                "this recording's mean: no field given"
            }
        ),
    };
    let left_out = match (c.disturbed.len(), c.glitches.len()) {
        (0, 0) => String::new(),
        (_, 0) => format!(
            " ({} in disturbed spans left out of the check)",
            c.samples_left_out
        ),
        (0, g) => format!(
            " ({} in {g} glitch{} left out of the check)",
            c.samples_left_out,
            if g == 1 { "" } else { "es" }
        ),
        (_, g) => format!(
            " ({} in disturbed spans and {g} glitch{} left out of the check)",
            c.samples_left_out,
            if g == 1 { "" } else { "es" }
        ),
    };
    let _ = writeln!(
        out,
        "{recording}: {} parameters{fitted_on}; {} samples {against}{left_out}",
        params.method, c.samples_used
    );
    let what = match c.against {
        Against::Vector => "per axis",
        Against::Magnitude { .. } => "of |B|",
    };
    let noise = if c.noise_floor_ut > 0.0 {
        format!(
            "the sensor's noise {:.3} µT (×{:.2})",
            c.noise_floor_ut,
            c.residual_rms_ut / c.noise_floor_ut
        )
    } else {
        "the sensor's noise not measured (the rows change orientation from one to the next)"
            .to_owned()
    };
    let _ = writeln!(
        out,
        "  residual RMS {:.3} µT {what} (the raw readings as they are: {:.3} µT), {noise}",
        c.residual_rms_ut, c.raw_residual_rms_ut,
    );
    if let Some(m) = &c.measured {
        let _ = writeln!(
            out,
            "  heading error measured with the attitude reference: raw readings RMS {}, calibrated RMS {} (95 % of \
             readings within {})",
            fmt_deg(m.raw_rms_deg),
            fmt_deg(m.rms_deg),
            fmt_deg(m.p95_deg)
        );
    }
    match &c.heading {
        Some(h) => {
            out += &heading_lines(
                h,
                c.against != Against::Vector,
                c.noise_floor_ut > 0.0,
                c.resolution.bound,
            );
            let _ = writeln!(
                out,
                "  this check's own standard error: ±{} on what is left (the residual's mean square over {} blocks of \
                 time{})",
                fmt_deg(c.resolution.se_deg),
                crate::apply::CHECK_BLOCKS,
                if c.resolution.bound {
                    ": within two of the sensor's noise, so the figures left are what the check resolves, not an \
                     estimate"
                } else {
                    ""
                }
            );
        }
        None => {
            let _ = writeln!(
                out,
                "heading error: not known without the direction of the local field"
            );
        }
    }
    out += &verdict_line(&c.verdict);
    for w in &c.warnings {
        let _ = writeln!(out, "  WARNING: {w}");
    }
    const SPANS_SHOWN: usize = 6;
    for sp in c.disturbed.iter().take(SPANS_SHOWN) {
        let _ = writeln!(out, "  disturbance {}", sp.explanation);
    }
    if c.disturbed.len() > SPANS_SHOWN {
        let _ = writeln!(
            out,
            "  and {} more disturbances",
            c.disturbed.len() - SPANS_SHOWN
        );
    }
    out += &glitches_line(&c.glitches);
    out
}

/// The summary of a calibration of `recording`, with its heading figures and verdict, for a run that writes no
/// JSON report: where the details are only in the report, it says how to get one (`--report FILE`).
pub fn summary(cal: &Calibration, assessment: &Assessment, recording: &str) -> String {
    summary_with_report(cal, assessment, recording, None)
}

/// [`summary`] for a run that writes its JSON report to `report` (if any): the details the summary leaves to the
/// report are pointed to there.
pub fn summary_with_report(
    cal: &Calibration,
    assessment: &Assessment,
    recording: &str,
    report: Option<&std::path::Path>,
) -> String {
    let mut out = samples_line(cal, recording);
    out += &heading_block(cal, assessment);
    for w in &cal.warnings {
        let _ = writeln!(out, "  WARNING: {w}");
    }
    out += &field_line(&cal.field);
    if let Some(h) = &cal.reference_heading {
        out += &crate::reference_heading::line(h, &cal.field);
    }
    out += &model_lines(cal);
    out += &residual_lines(cal);
    for note in &cal.notes {
        let _ = writeln!(out, "  note: {note}");
    }
    if let Some(d) = &cal.diagnosis {
        let reference_off = cal.fit.reference_off(&cal.field).is_some();
        let details = match report {
            Some(path) => format!("in {}", path.display()),
            None => "add --report FILE".to_owned(),
        };
        out += &diagnosis(d, !cal.fit.is_vector(), reference_off, &details);
    }
    out
}

/// The summary's first line: the recording, the method and the samples it used.
fn samples_line(cal: &Calibration, recording: &str) -> String {
    let mut out = String::new();
    let method = match cal.method() {
        Method::Vector => "vector calibration, against the attitude reference",
        _ => "scalar calibration (ellipsoid fit: the field's magnitude only)",
    };
    let s = &cal.samples;
    // The vector method's final model is the diagnosis' own fit when it models an effect: on the rows it used,
    // which may hold many the base fit left out (those a timing lag or a field on the board explains).
    let final_rows = cal
        .diagnosis
        .as_ref()
        .filter(|d| cal.method() == Method::Vector && !d.effects.is_empty())
        .map(|d| d.samples_used)
        .filter(|&n| n != s.used);
    let _ = write!(
        out,
        "{recording}: {method}, {} of {} samples",
        final_rows.unwrap_or(s.used),
        s.total
    );
    // The rows left out as grossly off are said of the rows the fit could use, as the verdict says them.
    let usable = s.used + s.excluded;
    let mut clauses = Vec::new();
    if s.missing_reference > 0 {
        clauses.push(format!(
            "{} without an attitude reference left out",
            s.missing_reference
        ));
    }
    let of_usable = if s.missing_reference > 0 {
        format!("of the other {usable}")
    } else {
        format!("of the {usable}")
    };
    let share = 100.0 * s.excluded as f64 / usable.max(1) as f64;
    match final_rows {
        Some(_) => clauses.push(format!(
            "{of_usable}, the base fit, without the effects the diagnosis found, used {} and left out {} ({share:.0} \
             %) as grossly off",
            s.used, s.excluded
        )),
        None if s.excluded > 0 => clauses.push(format!(
            "{of_usable}, {} ({share:.0} %) left out as grossly off",
            s.excluded
        )),
        None => {}
    }
    if !clauses.is_empty() {
        let _ = write!(out, " ({})", clauses.join("; "));
    }
    out.push('\n');
    out
}

/// The heading figures (and those of `A` and `b` alone, when the model has corrections) and the verdict.
fn heading_block(cal: &Calibration, assessment: &Assessment) -> String {
    let mut out = String::new();
    match &assessment.heading {
        Some(h) => {
            out += &heading_lines(h, cal.method() == Method::Scalar, cal.noise_measured, false)
        }
        None => {
            let _ = writeln!(
                out,
                "heading error: not known without the direction of the local field"
            );
        }
    }
    match &assessment.without_corrections {
        Some((n, _)) if assessment.linear_only => {
            let _ = writeln!(
                out,
                "  (A and b alone: the model's {n} correction(s) cannot go to this target)"
            );
        }
        Some((n, Some(h))) => {
            let _ = writeln!(
                out,
                "  with A and b alone (what --export and --write-to carry, without the {n} correction(s)): worst {} \
                 left",
                fmt_deg(h.left.worst_deg)
            );
        }
        _ => {}
    }
    out += &verdict_line(&assessment.verdict);
    out
}

/// The field the fit was made against, and where it came from.
fn field_line(field: &ReferenceField) -> String {
    match (field.vector(), field.magnitude()) {
        (Some(f), Some(m)) => format!(
            "  field: [{:.2}, {:.2}, {:.2}] µT NED, |B| {m:.2} µT ({})\n",
            f[0],
            f[1],
            f[2],
            field.source()
        ),
        (None, Some(m)) => format!("  field: |B| {m:.2} µT ({})\n", field.source()),
        _ => "  field: unknown\n".to_owned(),
    }
}

/// `A` and `b` of the final model with their standard errors, and the offset.
fn model_lines(cal: &Calibration) -> String {
    let mut out = String::new();
    let model = cal.model();
    let (a_se, b_se) = cal.standard_errors();
    let cells: Vec<Vec<String>> = (0..3)
        .map(|j| (0..3).map(|k| fmt_se(model.a[j][k], a_se[j][k])).collect())
        .collect();
    let width = cells
        .iter()
        .flatten()
        .map(|c| c.chars().count())
        .max()
        .unwrap_or(0);
    for (j, row) in cells.iter().enumerate() {
        let prefix = if j == 0 { "  A = " } else { "      " };
        let row: Vec<String> = row.iter().map(|c| format!("{c:>width$}")).collect();
        let _ = writeln!(out, "{prefix}[{}]", row.join("   "));
    }
    let b: Vec<String> = (0..3).map(|k| fmt_se(model.b_ut[k], b_se[k])).collect();
    let centre = magcal_calib::scalar::centre(&model.a, model.b_ut);
    let _ = writeln!(
        out,
        "  b = [{}] {}   (offset −A⁻¹b = [{:.2}, {:.2}, {:.2}] {})",
        b.join(", "),
        cal.units.calibrated_label(),
        centre[0],
        centre[1],
        centre[2],
        cal.units.raw_label()
    );
    out
}

/// The residual against the noise floor, and the coverage of the sphere of directions.
fn residual_lines(cal: &Calibration) -> String {
    let mut out = String::new();
    let what = match cal.method() {
        Method::Vector => "per axis",
        _ => "of |B|",
    };
    let (rms, floor) = match &cal.diagnosis {
        Some(d) => (d.extended.rms_ut, d.noise_floor_ut),
        None => (cal.residual_rms_ut, cal.noise_floor_ut),
    };
    let unit = cal.units.calibrated_label();
    if cal.noise_measured {
        let _ = writeln!(
            out,
            "  residual RMS {rms:.3} {unit} {what}, the sensor's noise {floor:.3} {unit} (×{:.2})",
            rms / floor
        );
    } else {
        let _ = writeln!(
            out,
            "  residual RMS {rms:.3} {unit} {what}, the sensor's noise not measured (the note below says why)"
        );
    }
    let cov = cal.fit.face().coverage();
    let _ = writeln!(
        out,
        "  coverage: {:.0}% of the sphere of directions; spread {:.1} / {:.1} / {:.1} {}",
        100.0 * cal.sphere_coverage,
        cov.spread_ut[0],
        cov.spread_ut[1],
        cov.spread_ut[2],
        cal.units.raw_label()
    );
    out
}

/// Whether an effect lowers the residual on data the fit did not see enough to notice.
/// A modelled effect is announced as a finding only when it lowers the residual on data the fit did not see by at
/// least [`NOTICEABLE_GAIN`]; smaller ones are listed on one line as too small to notice.
fn noticeable(e: &FoundEffect) -> bool {
    e.holdout_rms_before_ut - e.holdout_rms_after_ut >= NOTICEABLE_GAIN * e.holdout_rms_before_ut
}

/// What became of the spans located: left out of the calibration, or kept (some or all) because leaving them out
/// fitted the rest no better ([`magcal_calib::diagnosis::Diagnosis::kept_after_all`]).
fn spans_fate(spans: &[GrossSpan]) -> String {
    let kept = spans.iter().filter(|sp| sp.wholly_kept()).count();
    const NO_BETTER: &str = "leaving them out fitted the rest no better";
    match kept {
        0 => "left out of the calibration".to_owned(),
        k if k == spans.len() => format!("kept in the calibration ({NO_BETTER})"),
        k => format!(
            "{} of {} left out of the calibration ({k} kept: {NO_BETTER})",
            spans.len() - k,
            spans.len()
        ),
    }
}

/// The diagnosis in a few lines (`scalar`: the scalar method, which has no attitude reference whose error the residual
/// could be; `reference_off`: the reference disagrees with the readings by a good part of the field, which the
/// WARNING above says).
fn diagnosis(d: &Diagnosis, scalar: bool, reference_off: bool, details: &str) -> String {
    let mut out = String::new();
    let reference = reference_clause(d, scalar, reference_off);
    let verdict = match d.verdict {
        Finding::Consistent if reference_off => {
            format!(
                "not judged: the reference is off, so the residual cannot show what is left out{reference}"
            )
        }
        Finding::Consistent => {
            format!("consistent: nothing this recording can show is left out{reference}")
        }
        Finding::Mismatch if d.effects.is_empty() => {
            format!("mismatch: disturbances located, {}", spans_fate(&d.spans))
        }
        Finding::Mismatch => "mismatch".to_owned(),
    };
    let _ = writeln!(out, "diagnosis: {verdict}");
    const SPANS_SHOWN: usize = 6;
    for sp in d.spans.iter().take(SPANS_SHOWN) {
        let _ = writeln!(out, "  disturbance {}", sp.explanation);
    }
    if d.spans.len() > SPANS_SHOWN {
        let _ = writeln!(
            out,
            "  and {} more disturbances (every one: {details})",
            d.spans.len() - SPANS_SHOWN
        );
    }
    out += &glitches_line(&d.glitches);
    out += &located_line(d);
    out += &effect_lines(d);
    if !d.effects.is_empty() {
        let _ = writeln!(
            out,
            "  model: residual {:.3} → {:.3} µT, on data the fit did not see {:.3} → {:.3} µT, noise {:.3} µT{}",
            d.base.rms_ut,
            d.extended.rms_ut,
            d.base.holdout_rms_ut,
            d.extended.holdout_rms_ut,
            d.noise_floor_ut,
            match (reference.is_empty(), scalar) {
                (true, _) => String::new(),
                (false, true) => format!(
                    ", unexplained beyond the noise {:.3} µT",
                    d.reference_floor_ut
                ),
                (false, false) =>
                    format!(", the reference's own error {:.3} µT", d.reference_floor_ut),
            }
        );
    }
    if !d.untestable.is_empty() {
        let _ = writeln!(
            out,
            "  not tested: {} effects this recording cannot show (which and why: {details})",
            d.untestable.len()
        );
    }
    out
}

/// The glitches in one line, when there are any: how many, where the first few were, and that they are no finding.
fn glitches_line(glitches: &[Glitch]) -> String {
    if glitches.is_empty() {
        return String::new();
    }
    const SHOWN: usize = 4;
    let mut at: Vec<String> = glitches
        .iter()
        .take(SHOWN)
        .map(|g| {
            if g.t1_s > g.t0_s {
                format!("{:.2}–{:.2} s", g.t0_s, g.t1_s)
            } else {
                format!("{:.2} s", g.t0_s)
            }
        })
        .collect();
    if glitches.len() > SHOWN {
        at.push("…".to_owned());
    }
    let samples: usize = glitches.iter().map(|g| g.samples).sum();
    format!(
        "  {} glitch{} left out ({samples} samples: {}): too short to be a field, or no larger than this recording's \
         own noise makes somewhere by chance — not a finding\n",
        glitches.len(),
        if glitches.len() == 1 { "" } else { "es" },
        at.join(", ")
    )
}

/// What the residual beyond the sensor's noise is, as a clause to append (empty when it is within half the noise).
fn reference_clause(d: &Diagnosis, scalar: bool, reference_off: bool) -> String {
    if d.reference_floor_ut <= 0.5 * d.noise_floor_ut {
        String::new()
    } else if reference_off {
        format!(
            " (the residual beyond the sensor's noise, {:.2} µT, is no error a reference has in magcal's convention: \
             see the WARNING above)",
            d.reference_floor_ut
        )
    } else if scalar {
        format!(
            " (the residual beyond the sensor's noise, {:.2} µT, is left unexplained: the field's own variation where \
             the sensor moved, or something none of the effects tested accounts for)",
            d.reference_floor_ut
        )
    } else {
        format!(
            " (the residual beyond the sensor's noise, {:.2} µT, is the reference's own error)",
            d.reference_floor_ut
        )
    }
}

/// Where the residual departs from the noise (axes, orientation, channel), when the diagnosis says it does.
fn located_line(d: &Diagnosis) -> String {
    let l = &d.located;
    let channel = l
        .channel
        .as_ref()
        .filter(|_| l.channel_share >= CHANNEL_SHARE_SHOWN);
    if d.verdict != Finding::Mismatch
        || (l.axes.is_empty() && channel.is_none() && l.orientation.is_none())
    {
        return String::new();
    }
    let mut parts = Vec::new();
    if !l.axes.is_empty() {
        parts.push(format!("axes {}", l.axes.join(", ")));
    }
    if let Some(o) = l.orientation {
        parts.push(format!(
            "worst with the field along {} ({:.3} against {:.3} µT)",
            o.direction, o.rms_ut, o.elsewhere_rms_ut
        ));
    }
    if let Some(c) = channel {
        parts.push(format!(
            "follows {} ({:.0} % of the residual's variance)",
            crate::plots::channel_label(c),
            100.0 * l.channel_share
        ));
    }
    format!("  located: {}\n", parts.join("; "))
}

/// The effects found (the noticeable ones one a line, the others on one), the ambiguities and the effects rejected.
fn effect_lines(d: &Diagnosis) -> String {
    let mut out = String::new();
    let (shown, small): (Vec<&FoundEffect>, Vec<&FoundEffect>) =
        d.effects.iter().partition(|e| noticeable(e));
    for e in &shown {
        let _ = writeln!(out, "  found {}: {}", e.effect.id(), e.explanation);
    }
    if !small.is_empty() {
        let list: Vec<String> = small
            .iter()
            .map(|e| {
                format!(
                    "{} ({:.3} → {:.3} µT)",
                    e.effect.id(),
                    e.holdout_rms_before_ut,
                    e.holdout_rms_after_ut
                )
            })
            .collect();
        let _ = writeln!(
            out,
            "  also modelled, too small to notice (under {:.0} % on data the fit did not see): {}",
            100.0 * NOTICEABLE_GAIN,
            list.join(", ")
        );
    }
    for a in &d.ambiguous {
        let _ = writeln!(
            out,
            "  ambiguous: {}; to separate them: {}",
            a.why, a.experiment
        );
    }
    for r in &d.rejected {
        let _ = writeln!(out, "  not modelled, {}: {}", r.id, r.why);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_errors_have_two_significant_digits() {
        assert_eq!(fmt_se(0.975_72, 0.002_11), "0.9757 ±0.0021");
        assert_eq!(fmt_se(-139.961, 0.166), "-139.96 ±0.17");
        assert_eq!(fmt_se(12.34, 1.5), "12.3 ±1.5");
        assert_eq!(fmt_se(1234.5, 25.0), "1234 ±25");
        assert_eq!(fmt_se(0.5, 0.000_012_3), "0.500000 ±0.000012");
        assert_eq!(fmt_se(0.002_016, 0.000_099_97), "0.00202 ±0.00010");
        assert_eq!(fmt_se(1.0, 0.0), "1.00000 (no standard error)");
        assert!(!fmt_se(0.97, 1e-9).contains("±0.0000 "));
    }

    #[test]
    fn the_verdict_says_which_spans_were_kept() {
        let span = |samples, kept_samples| GrossSpan {
            t0_s: 1.0,
            t1_s: 2.0,
            samples,
            peak_ut: 40.0,
            rms_ut: 10.0,
            kind: magcal_calib::diagnosis::SpanKind::Moving,
            modelled: false,
            explanation: String::new(),
            kept_samples,
        };
        assert_eq!(
            spans_fate(&[span(100, 0), span(50, 10)]),
            "left out of the calibration"
        );
        assert_eq!(
            spans_fate(&[span(100, 0), span(50, 50)]),
            "1 of 2 left out of the calibration (1 kept: leaving them out fitted the rest no better)"
        );
        assert_eq!(
            spans_fate(&[span(50, 50)]),
            "kept in the calibration (leaving them out fitted the rest no better)"
        );
    }
}
