//! The last check on every fit, before anything is written: a calibration that cannot be right is refused, one that
//! looks wrong for a reason the user can fix (units, a field outside the Earth's range) is written with a loud
//! warning that says what it looks like and what would fix it.

use magcal_calib::convention::{Better, OutOfStep};
use magcal_calib::scalar::centre;
use magcal_calib::{FitError, Model, frames};
use nalgebra::Matrix3;

use crate::field::ReferenceField;
use crate::fit::{Fit, ReferenceDoubt, UndeterminedPart};

pub use crate::units::EARTH_FIELD_UT;
/// `A`'s singular values may differ by this factor before the gains are called implausible.
const GAIN_SPREAD_WARN: f64 = 1.5;
/// Below this ratio of the smallest to the largest singular value, `A` is as good as singular: refused.
const GAIN_SPREAD_REFUSE: f64 = 1e-3;
/// Readings in µT whose mean gain against a given field is off by more than this factor (either way): a sensor's
/// sensitivity is within 10–20 % of its datasheet's, so the field given is more likely wrong.
const MEAN_GAIN_WARN: f64 = 1.3;

/// What [`check`] found of a calibration it did not refuse.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Checked {
    /// What the user must not miss.
    pub warnings: Vec<String>,
    /// The raw readings are not µT (their radius is far from any Earth's field): the offset is in their units
    /// ([`crate::units`] says what they may be).
    pub raw_not_ut: bool,
    /// The median radius of the raw readings the fit kept about the fitted centre, in their units.
    pub raw_radius: f64,
}

/// Checks a fitted model (of the readings `raw_ut` it `kept`); refuses what cannot be a calibration and returns the
/// warnings for the rest. `reference` is what the reference was found to be instead ([`magcal_calib::convention`]).
pub fn check(
    model: &Model,
    fit: &Fit,
    field: &ReferenceField,
    raw_ut: &[[f64; 3]],
    kept: &[bool],
    reference: &ReferenceDoubt,
) -> Result<Checked, FitError> {
    let a = Matrix3::from_fn(|j, k| model.a[j][k]);
    let sv = a.singular_values();
    let (lo, hi) = (sv.min(), sv.max());
    if !(a.determinant().abs() > 0.0 && lo > GAIN_SPREAD_REFUSE * hi && hi.is_finite())
        || model.b_ut.iter().any(|b| !b.is_finite())
    {
        return Err(FitError::Singular(
            "the fitted matrix A is (nearly) singular: the recording does not determine a calibration",
        ));
    }
    let mut warnings = Vec::new();
    // A reference off by a good part of the field bends A every way: that, not the gains, is what to say.
    let reference_off = fit.reference_off(field);
    if let Some(b) = &reference.convention {
        warnings.push(convention_warning(b));
    } else if let Some(o) = &reference.offset {
        warnings.push(offset_warning(o));
    } else if let Some(part) = &reference.part {
        warnings.push(part_warning(part));
    } else if let Some((rms, f)) = reference_off {
        warnings.push(format!(
            "the readings and the attitude reference disagree by {rms:.1} µT RMS per axis, {:.0} % of the field: \
             more than any sensor's calibration leaves. The reference is likely in another convention than \
             magcal's — quaternions qw,qx,qy,qz turning the sensor's axes into the world's NED axes, the field in \
             NED — or off in time: try the conjugate (inverse) quaternion, the x,y,z,w order, an ENU world, or \
             check the clocks. A and b here are not a calibration",
            100.0 * rms / f
        ));
    }
    let reference_doubtful = reference_off.is_some() || reference.is_some();
    if hi / lo > GAIN_SPREAD_WARN && !reference_doubtful {
        warnings.push(format!(
            "the fitted gains differ by a factor {:.2} between directions (singular values of A {:.4}–{:.4}): more \
             than a sensor's axes plausibly differ. Check for a saturated axis, a mis-set range, or a magnet moving \
             with the sensor",
            hi / lo,
            lo,
            hi
        ));
    }
    // The radius about their centre of the raw readings the fit kept (a field on the board for half of a recording
    // is no unit): what the sensor's units make of the Earth's field.
    let c = centre(&model.a, model.b_ut);
    let mut radii: Vec<f64> = raw_ut
        .iter()
        .zip(kept)
        .step_by((raw_ut.len() / 10_000).max(1))
        .filter(|(_, k)| **k)
        .map(|(m, _)| frames::norm(frames::sub(*m, c)))
        .filter(|r| r.is_finite())
        .collect();
    let raw_radius = median(&mut radii);
    let calibrated = fit.face().magnitude_ut().unwrap_or_else(|| {
        field
            .magnitude()
            .unwrap_or(raw_radius * (sv.iter().product::<f64>()).cbrt())
    });
    let (low, high) = EARTH_FIELD_UT;
    let raw_in_range = (0.5 * low..=1.5 * high).contains(&raw_radius);
    let known = match fit {
        Fit::Scalar(s) => s.field_given.then_some(s.field_ut),
        Fit::Vector(_) => Some(calibrated),
    };
    // Against a doubtful reference the centre is no hard iron, and the radius about it no unit.
    let raw_not_ut = !reference_doubtful && !raw_in_range && raw_radius > 0.0;
    if !raw_not_ut && !(low..=high).contains(&calibrated) {
        warnings.push(format!(
            "the calibrated field is {calibrated:.1} µT, outside the Earth's {low:.0}–{high:.0} µT: if the readings \
             are µT, the field given (or fitted) is wrong or the sensor sits in a strongly disturbed place; if the \
             sensor's gain is off, A corrects it only for this field"
        ));
    }
    let mean_gain = sv.iter().product::<f64>().cbrt();
    if raw_in_range
        && known.is_some()
        && !reference_doubtful
        && mean_gain.ln().abs() > MEAN_GAIN_WARN.ln()
    {
        warnings.push(format!(
            "A scales the readings by {mean_gain:.3} on average: they lie {raw_radius:.1} µT from their centre, and \
             the field they were fitted to is {calibrated:.1} µT ({}). A sensor that reports µT is rarely off by \
             more than 10–20 %: check that field (or the readings' units): calibrated readings take its magnitude",
            field.source()
        ));
    }
    if fit.is_vector() && !reference_doubtful && a.determinant() < 0.0 {
        warnings.push(
            "A mirrors the axes (its determinant is negative): the readings' axes are left-handed against the \
             attitude reference's — two axes swapped or one reversed (a wiring or a driver's axis map). A as fitted \
             undoes it, but exports with a symmetric matrix (ArduPilot, PX4) cannot: fix the axis map and record \
             again"
                .to_owned(),
        );
    }
    let offset = frames::norm(c);
    if raw_in_range && offset > 10.0 * calibrated {
        warnings.push(format!(
            "the hard-iron offset is {offset:.0} µT, {:.0} times the field: a magnet or steel very close to the \
             sensor. The calibration holds only while it stays exactly where it is",
            offset / calibrated
        ));
    }
    Ok(Checked {
        warnings,
        raw_not_ut,
        raw_radius,
    })
}

/// The warning for an attitude reference that fits far better in another convention.
pub fn convention_warning(b: &Better) -> String {
    format!(
        "the attitude reference fits the readings far better read as {}: then it explains {:.0} % of them (median \
         misfit {:.2} µT), as the file gives it {:.0} % ({:.2} µT). magcal reads qw,qx,qy,qz as the turn of the \
         sensor's axes into the world's north-east-down axes, with the field in NED: rewrite the quaternions (or \
         the field) in that convention and fit again. A and b here are not a calibration, and spans left out as \
         disturbed are where the wrong reference happened not to fit",
        b.describe(),
        100.0 * b.better.explained,
        b.better.median_ut,
        100.0 * b.given.explained,
        b.given.median_ut
    )
}

/// The warning for a mostly disturbed recording whose consistent part does not determine a calibration.
pub fn part_warning(p: &UndeterminedPart) -> String {
    let stretches: Vec<String> = p
        .stretches
        .iter()
        .map(|(t0, t1)| format!("{t0:.1}–{t1:.1} s"))
        .collect();
    format!(
        "most of this recording is disturbed: only {:.0} % of the readings with a reference agree with it under one \
         calibration, to {:.2} µT per axis (the majority's fit misses by {:.2} µT) — mostly at {} — but they do \
         not determine the calibration: {} (they cover {:.0} % of the directions). The reference itself is not \
         at fault there. Record again away from magnets and metal, turning through more directions. A and b here \
         are not a calibration",
        100.0 * p.share,
        p.sigma_ut,
        p.majority_sigma_ut,
        stretches.join(", "),
        if p.brief {
            "they sit in few stretches of the recording"
        } else {
            "fitted on every other tenth of the recording they miss the rest"
        },
        100.0 * p.covered
    )
}

/// The warning for readings out of step with their reference.
pub fn offset_warning(o: &OutOfStep) -> String {
    format!(
        "the readings and the attitude reference are out of step: with the reference shifted so that the readings \
         are {} by {:.0} ms, it explains {:.0} % of them (median misfit {:.2} µT), as the file gives it {:.0} % \
         ({:.2} µT). The two were likely logged on different clocks: shift the reference's times by {:+.0} ms (or \
         record both on one clock) and fit again. A and b here are not a calibration, and spans left out as \
         disturbed are where the reference happened to fit",
        if o.offset_s > 0.0 { "late" } else { "early" },
        1000.0 * o.offset_s.abs(),
        100.0 * o.shifted.explained,
        o.shifted.median_ut,
        100.0 * o.given.explained,
        o.given.median_ut,
        1000.0 * o.offset_s
    )
}

/// The median of `v` (reordered), NaN when empty.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}
