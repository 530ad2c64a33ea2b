//! The reference's heading in a vector fit: an attitude reference whose north is not true north (a cube jig's edge
//! lined up with a compass or by eye, a capture volume's axes) found with the robust base fit, the field turned into
//! its axes for the fit, and said ([`magcal_calib::reference_heading`]).
//!
//! The heading is looked for on the rows the robust fit against the field as given kept (on a trimmed set of all
//! rows when that fit failed); when it is material, the robust fit is made again against the field turned by it, and
//! the heading found again on the rows that fit kept, until it settles. The calibration (`A`, `b`) is then the
//! sensor's, whatever the jig's heading; its standard errors include the heading's.

use std::borrow::Cow;

use magcal_calib::frames;
use magcal_calib::noise::NoiseFloor;
use magcal_calib::reference_heading::{self, HeadingEstimate, MIN_HEADING_DEG, SIGNIFICANT_SE};
use magcal_calib::robust::{self, Robust};
use magcal_calib::vector::{VectorFit, VectorProblem};
use magcal_recording::Recording;

use crate::field::ReferenceField;
use crate::fit::ReferenceHeading;
use crate::readings::expected_field;

/// Robust fits against the turned field, at most.
pub const MAX_ROUNDS: usize = 3;
/// The heading has settled when a round moves it by less than this share of its standard error.
const SETTLED_SE: f64 = 0.1;

/// What the search for the reference's heading found.
#[allow(
    clippy::large_enum_variant,
    reason = "one per calibration; boxing buys nothing"
)]
#[derive(Debug)]
pub enum Search {
    /// No attitude with a world field vector: there is nothing to turn.
    NoAttitude,
    /// A heading not worth fitting, or none determined (`None`: not even estimated): the fit against the field as
    /// given stands.
    Left(Option<HeadingEstimate>),
    /// A heading fitted.
    Turned(Turned),
}

/// The robust fit against the field turned by the reference's heading.
#[derive(Debug)]
pub struct Turned {
    /// The robust fit, its covariance widened by the heading's uncertainty.
    pub robust: Robust<VectorFit>,
    /// The expected field per row against which it was made, µT.
    pub expected_ut: Vec<[f64; 3]>,
    /// The heading.
    pub heading: ReferenceHeading,
}

/// The reference's heading of `rec` against `field`, from the rows the robust fit `first` against the field as
/// given kept (`None`: it failed), and the robust fit against the field turned by it when it is material (`noise`:
/// the raw readings' noise floor).
pub fn search(
    rec: &Recording,
    field: &ReferenceField,
    noise: &NoiseFloor,
    first: Option<&Robust<VectorFit>>,
) -> Search {
    let (Some(quat), Some(f)) = (&rec.quat, field.vector()) else {
        return Search::NoAttitude;
    };
    let found = match first {
        Some(r) => reference_heading::estimate(&rec.mag_ut, quat, f, Some(&r.kept)),
        None => reference_heading::estimate_trimmed(&rec.mag_ut, quat, f, None),
    };
    let noise_ut = |e: &HeadingEstimate| noise.calibrated_rms_ut(&e.a);
    let Some(mut est) = found.filter(|e| e.material(noise_ut(e))) else {
        return Search::Left(found);
    };
    let mut last = None;
    for _ in 0..MAX_ROUNDS {
        let turned = est.field_in_reference(f);
        let Ok(expected) = expected_field(rec, &vector(turned)) else {
            break;
        };
        let problem = VectorProblem {
            raw_ut: Cow::Borrowed(&rec.mag_ut),
            expected_ut: expected,
            raw_noise_var_ut2: noise.floor_ut.map(|f| f * f),
        };
        let Ok(r) = robust::fit(&problem, rec.t_s.as_deref()) else {
            break;
        };
        let Some(next) = reference_heading::estimate(&rec.mag_ut, quat, f, Some(&r.kept)) else {
            break;
        };
        let settled = angle_between(next.heading_deg, est.heading_deg) <= SETTLED_SE * next.se_deg;
        let again = !settled && next.material(noise_ut(&next));
        last = Some((r, problem.expected_ut.into_owned(), turned, next));
        if !again {
            break;
        }
        est = next;
    }
    match last {
        Some((mut robust, expected_ut, field_ned_ut, est)) if est.material(noise_ut(&est)) => {
            reference_heading::widen(&mut robust.fit, &est);
            Search::Turned(Turned {
                robust,
                expected_ut,
                heading: ReferenceHeading {
                    estimate: est,
                    field_ned_ut,
                    jig: rec.meta.routine.as_deref() == Some("cube24"),
                },
            })
        }
        Some((.., est)) => Search::Left(Some(est)),
        None => Search::Left(Some(est)),
    }
}

/// A field vector with no source (for the expected field).
fn vector(field_ned_ut: [f64; 3]) -> ReferenceField {
    ReferenceField::Vector {
        field_ned_ut,
        source: String::new(),
    }
}

/// The angle between two headings, degrees, in [0, 180].
fn angle_between(a_deg: f64, b_deg: f64) -> f64 {
    ((a_deg - b_deg + 180.0).rem_euclid(360.0) - 180.0).abs()
}

/// Whether the heading is where the field given says magnetic north is: within the larger of
/// [`SIGNIFICANT_SE`] standard errors and [`MIN_HEADING_DEG`] of its declination (the reference was lined up with
/// a compass).
pub fn on_magnetic_north(h: &ReferenceHeading, field: &ReferenceField) -> bool {
    field.vector().is_some_and(|f| {
        let declination_deg = frames::field_angles(f).0;
        angle_between(h.estimate.heading_deg, declination_deg)
            <= (SIGNIFICANT_SE * h.estimate.se_deg).max(MIN_HEADING_DEG)
    })
}

/// The declination (true minus given) a heading computed with the field given would be off by, when the reference's
/// north is not explained by magnetic north ([`on_magnetic_north`]): the heading with its sign reversed, which is
/// also what a field given off in declination by as much leaves.
pub fn declination_off_deg(h: &ReferenceHeading, field: &ReferenceField) -> Option<f64> {
    (!on_magnetic_north(h, field)).then_some(-h.estimate.heading_deg)
}

/// `x` degrees east (or west) in words, to two decimals.
fn east_or_west(x_deg: f64) -> String {
    if x_deg >= 0.0 {
        format!("{x_deg:.2}° east")
    } else {
        format!("{:.2}° west", -x_deg)
    }
}

/// The summary's line on the reference's heading (`field`: the field given).
pub fn line(h: &ReferenceHeading, field: &ReferenceField) -> String {
    let e = &h.estimate;
    let subject = if h.jig {
        "the jig's edge"
    } else {
        "the attitude reference's north"
    };
    let declination_deg = field.vector().map_or(0.0, |f| frames::field_angles(f).0);
    let why = if on_magnetic_north(h, field) {
        format!(
            " — where the declination is {declination_deg:.2}° ({}): it was lined up with magnetic north (a compass)",
            field.source()
        )
    } else {
        format!(
            " (or the declination given is {} too far {}: the two look the same)",
            format_args!("{:.2}°", e.heading_deg.abs()),
            if e.heading_deg >= 0.0 { "east" } else { "west" }
        )
    };
    format!(
        "  reference: {subject} points {} of true north ±{:.2}°{why}; the field was turned into its axes for the \
         fit, and the calibration does not depend on it\n",
        east_or_west(e.heading_deg),
        e.se_deg
    )
}

/// A note when the recording does not determine the reference's heading (the sensor turned about the vertical
/// only, so `A` takes up a turn of the reference about it).
pub fn undetermined_note(e: &HeadingEstimate) -> String {
    format!(
        "the attitude reference's heading (where its north points) is not determined by this recording (±{}): the \
         sensor turned (almost) about the vertical only, so A takes up a turn of the reference about it; tilt the \
         sensor through other faces to tell the two apart",
        if e.se_deg.is_finite() {
            format!("{:.1}°", e.se_deg)
        } else {
            "any angle".to_owned()
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn heading(heading_deg: f64, se_deg: f64) -> ReferenceHeading {
        let e = HeadingEstimate {
            heading_deg,
            se_deg,
            n: 1000,
            rms_ut: 0.3,
            rms_unturned_ut: 3.0,
            a: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            b_ut: [0.0; 3],
            sensitivity: [[0.0; 4]; 3],
        };
        ReferenceHeading {
            estimate: e,
            field_ned_ut: [0.0; 3],
            jig: true,
        }
    }

    #[test]
    fn a_heading_on_magnetic_north_is_said_to_be_a_compass() {
        let field = ReferenceField::Vector {
            field_ned_ut: frames::field_from_angles(10.2, 66.0, 49.0),
            source: "World Magnetic Model".into(),
        };
        let h = heading(10.25, 0.02);
        assert!(on_magnetic_north(&h, &field));
        assert_eq!(declination_off_deg(&h, &field), None);
        let text = line(&h, &field);
        assert!(
            text.contains("the jig's edge points 10.25° east of true north")
                && text.contains("where the declination is 10.20°")
                && text.contains("a compass")
                && text.contains("the calibration does not depend on it"),
            "{text}"
        );
        let h = heading(-30.0, 0.02);
        assert!(!on_magnetic_north(&h, &field));
        assert_eq!(declination_off_deg(&h, &field), Some(30.0));
        let text = line(&h, &field);
        assert!(
            text.contains("30.00° west of true north") && !text.contains("compass"),
            "{text}"
        );
        assert!((angle_between(179.0, -179.0) - 2.0).abs() < 1e-9);
    }
}
