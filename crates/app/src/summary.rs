//! The short human summary `magcal-fit` prints.

use std::fmt::Write;

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
    let _ = writeln!(
        out,
        "  residual RMS {:.3} µT {what}, noise floor {:.3} µT (×{:.2})",
        cal.residual_rms_ut,
        cal.noise_floor_ut,
        cal.residual_rms_ut / cal.noise_floor_ut
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
    out
}
