//! Why a fit can fail.

use crate::coverage::CoverageError;

/// A fit that could not be made, with what the user can do about it.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// Fewer usable samples than the fit needs.
    #[error("too few usable samples: {got}, need at least {needed}")]
    TooFewSamples {
        /// Samples the fit needs.
        needed: usize,
        /// Samples that were usable.
        got: usize,
    },
    /// The rotation did not span the three dimensions.
    #[error(transparent)]
    Coverage(#[from] CoverageError),
    /// The algebraic fit did not find an ellipsoid (the points lie on another quadric).
    #[error(
        "the readings do not lie on an ellipsoid (the algebraic fit found a {0}); \
         is the sensor saturated, or the field disturbed during the recording?"
    )]
    NotAnEllipsoid(&'static str),
    /// The recording does not determine the calibration along some direction (partial coverage).
    #[error(
        "the recording does not determine the offset along {}: its uncertainty there is ±{se_ut:.1} µT, {:.0} % of \
         the field ({field_ut:.1} µT). The sensor did not turn through enough directions: {advice}",
        crate::coverage::describe(*direction), 100.0 * se_ut / field_ut
    )]
    Undetermined {
        /// The least determined direction, sensor axes.
        direction: [f64; 3],
        /// The offset's standard error along it, µT.
        se_ut: f64,
        /// The field magnitude, µT.
        field_ut: f64,
        /// What to do.
        advice: String,
    },
    /// The fit's correction for the sensor's noise moved it more than a second-order correction may, or did not
    /// settle: on so few directions the noise biases the fit by about as much, and neither fit can be trusted.
    #[error(
        "the directions the sensor turned through do not pin the fit down against its own noise: correcting the \
         fit for the noise ({noise_ut:.2} µT per axis) {}; the fit is refused when that correction moves the \
         offset by more than {centre_limit_ut:.1} µT ({:.0} % of the {field_ut:.1} µT field) or the gains by more \
         than {:.0} %, or does not settle, since the uncorrected fit is then off by about as much and the correction \
         itself is not reliable. To do: {advice}, or lower the noise (average readings, a slower rate)",
        crate::error::noise_correction_said(*converged, *centre_moved_ut, *gain_moved),
        100.0 * centre_limit_ut / field_ut,
        100.0 * gain_limit
    )]
    NoiseDominates {
        /// The least determined direction, sensor axes.
        direction: [f64; 3],
        /// The raw noise the correction was for, RMS per axis, µT.
        noise_ut: f64,
        /// How far the correction moved the offset, µT.
        centre_moved_ut: f64,
        /// How far it may, µT.
        centre_limit_ut: f64,
        /// How far it moved `A`, relative to its mean gain (largest entry).
        gain_moved: f64,
        /// How far it may.
        gain_limit: f64,
        /// Whether it settled.
        converged: bool,
        /// The field magnitude, µT.
        field_ut: f64,
        /// What to do.
        advice: String,
    },
    /// The reference field hardly varies while the readings do: it cannot be the field in sensor axes.
    #[error(
        "the reference field hardly varies (spread {reference_ut:.2} µT) while the readings do ({readings_ut:.1} \
         µT): it must be the field in the sensor's axes at each sample (rx,ry,rz), which turns with the sensor — \
         give the attitude instead (qw,qx,qy,qz) with the world field (--field-ned), or fit the magnitude alone \
         (--method scalar)"
    )]
    ReferenceStill {
        /// The reference's largest spread, µT.
        reference_ut: f64,
        /// The readings' largest spread, µT.
        readings_ut: f64,
    },
    /// The normal equations were singular.
    #[error("the least-squares problem is singular: {0}")]
    Singular(&'static str),
}

/// What the noise correction of [`FitError::NoiseDominates`] did, as a clause.
pub(crate) fn noise_correction_said(
    converged: bool,
    centre_moved_ut: f64,
    gain_moved: f64,
) -> String {
    let moved = format!(
        "moves the offset by {centre_moved_ut:.1} µT and the gains by {:.1} %",
        100.0 * gain_moved
    );
    if converged {
        moved
    } else {
        format!("did not settle (its last step {moved})")
    }
}
