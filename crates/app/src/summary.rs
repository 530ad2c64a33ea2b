//! The short human summary `magcal-fit` prints.

use std::fmt::Write;

use magcal_calib::diagnosis::{Diagnosis, Verdict};

use crate::calibrate::{Calibration, Method};

/// The summary of a calibration of `recording`.
pub fn summary(cal: &Calibration, recording: &str) -> String {
    let mut out = String::new();
    let model = cal.model();
    let (a_se, b_se) = cal.standard_errors();
    let method = match cal.method() {
        Method::Vector => {
            "vector calibration (seed paper eqs. 2–4, against the known field components)"
        }
        _ => "scalar calibration (ellipsoid fit, constant |B|)",
    };
    let s = &cal.samples;
    let _ = writeln!(out, "{recording}: {method}");
    for w in &cal.warnings {
        let _ = writeln!(out, "  WARNING: {w}");
    }
    let _ = write!(out, "  samples: {} used of {}", s.used, s.total);
    if s.missing_reference > 0 {
        let _ = write!(
            out,
            " ({} without an attitude reference left out)",
            s.missing_reference
        );
    }
    out.push('\n');
    match (cal.field.vector(), cal.field.magnitude()) {
        (Some(f), Some(m)) => {
            let _ = writeln!(
                out,
                "  field: [{:.2}, {:.2}, {:.2}] µT NED, |B| {m:.2} µT ({})",
                f[0],
                f[1],
                f[2],
                cal.field.source()
            );
        }
        (None, Some(m)) => {
            let _ = writeln!(out, "  field: |B| {m:.2} µT ({})", cal.field.source());
        }
        _ => {
            let _ = writeln!(out, "  field: unknown");
        }
    }
    for j in 0..3 {
        let prefix = if j == 0 { "  A = " } else { "      " };
        let row: Vec<String> = (0..3)
            .map(|k| format!("{:>9.5} ±{:.5}", model.a[j][k], a_se[j][k]))
            .collect();
        let _ = writeln!(out, "{prefix}[{}]", row.join("  "));
    }
    let b: Vec<String> = (0..3)
        .map(|k| format!("{:.3} ±{:.3}", model.b_ut[k], b_se[k]))
        .collect();
    let centre = magcal_calib::scalar::centre(&model.a, model.b_ut);
    let _ = writeln!(
        out,
        "  b = [{}] µT   (offset −A⁻¹b = [{:.2}, {:.2}, {:.2}] µT)",
        b.join(", "),
        centre[0],
        centre[1],
        centre[2]
    );
    let what = match cal.method() {
        Method::Vector => "per axis",
        _ => "of |B|",
    };
    let (rms, floor) = match &cal.diagnosis {
        Some(d) => (d.extended.rms_ut, d.noise_floor_ut),
        None => (cal.residual_rms_ut, cal.noise_floor_ut),
    };
    let _ = writeln!(
        out,
        "  residual RMS {rms:.3} µT {what}, noise floor {floor:.3} µT (×{:.2})",
        rms / floor
    );
    let cov = match &cal.fit {
        crate::calibrate::Fit::Vector(v) => v.coverage,
        crate::calibrate::Fit::Scalar(s) => s.coverage,
    };
    let _ = writeln!(
        out,
        "  coverage: {:.0}% of the sphere of directions; spread {:.1} / {:.1} / {:.1} µT",
        100.0 * cal.sphere_coverage,
        cov.spread_ut[0],
        cov.spread_ut[1],
        cov.spread_ut[2]
    );
    for note in &cal.notes {
        let _ = writeln!(out, "  note: {note}");
    }
    if let Some(d) = &cal.diagnosis {
        out += &diagnosis(d);
    }
    out
}

/// The diagnosis in a few lines.
fn diagnosis(d: &Diagnosis) -> String {
    let mut out = String::new();
    let verdict = match d.verdict {
        Verdict::Consistent => {
            "consistent: the residual is noise; nothing this recording can show is left out"
        }
        Verdict::Mismatch if d.effects.is_empty() => {
            "mismatch: the residual is above the noise, and no effect of the \
             catalogue explains it"
        }
        Verdict::Mismatch => "mismatch",
    };
    let _ = writeln!(out, "diagnosis: {verdict}");
    let l = &d.located;
    if !l.axes.is_empty()
        || !l.segments.is_empty()
        || l.channel.is_some()
        || l.orientation.is_some()
    {
        let mut parts = Vec::new();
        if !l.axes.is_empty() {
            parts.push(format!("axes {}", l.axes.join(", ")));
        }
        if !l.segments.is_empty() {
            let spans: Vec<String> = l
                .segments
                .iter()
                .map(|s| format!("{:.1}–{:.1} s", s.t0_s, s.t1_s))
                .collect();
            parts.push(format!("spans {}", spans.join(", ")));
        }
        if let Some(o) = l.orientation {
            parts.push(format!(
                "worst with the field along {} ({:.3} against {:.3} µT)",
                o.direction, o.rms_ut, o.elsewhere_rms_ut
            ));
        }
        if let Some(c) = &l.channel {
            parts.push(format!(
                "follows {c} ({:.0} % of the residual's variance)",
                100.0 * l.channel_share
            ));
        }
        let _ = writeln!(out, "  located: {}", parts.join("; "));
    }
    for e in &d.effects {
        let _ = writeln!(out, "  found {}: {}", e.effect.id(), e.explanation);
    }
    for a in &d.ambiguous {
        let _ = writeln!(
            out,
            "  ambiguous: {}; to separate them: {}",
            a.why, a.experiment
        );
    }
    if !d.effects.is_empty() {
        let _ = writeln!(
            out,
            "  model: residual {:.3} → {:.3} µT, held-out {:.3} → {:.3} µT, noise floor {:.3} µT",
            d.base.rms_ut,
            d.extended.rms_ut,
            d.base.holdout_rms_ut,
            d.extended.holdout_rms_ut,
            d.noise_floor_ut
        );
    }
    let untestable: Vec<String> = d
        .untestable
        .iter()
        .map(|u| format!("{} ({})", u.id, u.why))
        .collect();
    if !untestable.is_empty() {
        let _ = writeln!(out, "  not tested: {}", untestable.join("; "));
    }
    out
}
