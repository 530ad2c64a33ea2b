//! A fitted calibration and what was measured around it: the method, the fit itself (vector or scalar, seen through
//! their common face [`CalibrationFit`]), the noise, the samples, what the robust base fit left out, the diagnosis,
//! and what the reference may be instead of what it was taken for.

use magcal_calib::Model;
use magcal_calib::convention;
use magcal_calib::diagnosis::Diagnosis;
use magcal_calib::fit::CalibrationFit;
use magcal_calib::noise::NoiseFloor;
use magcal_calib::reference_heading::HeadingEstimate;
use magcal_calib::robust;
use magcal_calib::scalar::ScalarFit;
use magcal_calib::vector::VectorFit;
use magcal_recording::Recording;

use crate::field::ReferenceField;
use crate::units::Units;

/// Which calibration method to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Method {
    /// Vector when the recording has an attitude reference, scalar otherwise.
    #[default]
    Auto,
    /// The seed paper's vector method (needs the expected field per sample).
    Vector,
    /// The ellipsoid (constant magnitude) method.
    Scalar,
}

impl Method {
    /// The name used in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Auto => "auto",
            Method::Vector => "vector",
            Method::Scalar => "scalar",
        }
    }
}

/// The fit itself, by method.
#[allow(
    clippy::large_enum_variant,
    reason = "one per calibration; boxing buys nothing"
)]
#[derive(Clone, Debug, PartialEq)]
pub enum Fit {
    /// A vector fit.
    Vector(VectorFit),
    /// A scalar fit.
    Scalar(ScalarFit),
}

/// How many samples went where.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SampleCounts {
    /// Rows in the recording.
    pub total: usize,
    /// Rows the fit used.
    pub used: usize,
    /// Rows left out because their attitude reference (vector method) or reading was missing.
    pub missing_reference: usize,
    /// Rows the robust base fit excluded as grossly off.
    pub excluded: usize,
}

/// A fitted calibration and what was measured around it.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    /// The fit.
    pub fit: Fit,
    /// The field it was fitted against.
    pub field: ReferenceField,
    /// The raw readings' noise floor.
    pub noise: NoiseFloor,
    /// Residual RMS per axis (vector) or of the magnitude (scalar), µT.
    pub residual_rms_ut: f64,
    /// The noise floor to compare it with, in calibrated units, µT.
    pub noise_floor_ut: f64,
    /// Whether the sample-to-sample noise was measured. When not (rows that change orientation from one to the next:
    /// their differences measure the rotation), the residual bounds it for the figures, and the verdict counts the
    /// whole residual as error.
    pub noise_measured: bool,
    /// Fraction of the sphere of field directions the recording visited (100 cells).
    pub sphere_coverage: f64,
    /// Sample counts.
    pub samples: SampleCounts,
    /// Things the user should know (coverage warnings, what the method cannot see).
    pub notes: Vec<String>,
    /// Things the user must not miss: the calibration may be wrong or unusable as it stands, and what to do.
    pub warnings: Vec<String>,
    /// The raw readings are not µT (a note or a warning says so): the offset is in their units; `units` says what
    /// they may be, and the exports convert with it.
    pub raw_not_ut: bool,
    /// The readings' unit: µT, or raw units with what makes them gauss ([`Units`]).
    pub units: Units,
    /// What the robust base fit left out.
    pub robust: RobustSummary,
    /// What the base model leaves out, when diagnosed.
    pub diagnosis: Option<Diagnosis>,
    /// Why the diagnosis, asked for, could not be made (the calibration is then the base fit).
    pub diagnosis_failed: Option<String>,
    /// What the reference was found to be instead of what it was taken for (a warning says so; the fit is then no
    /// calibration).
    pub reference: ReferenceDoubt,
    /// The reference's north, found off true north and fitted: the readings were fitted against the field turned
    /// into its axes ([`Calibration::fitted_field`]).
    pub reference_heading: Option<ReferenceHeading>,
}

/// An attitude reference whose north is not true north (a cube jig's edge, a capture volume's axes), fitted
/// ([`magcal_calib::reference_heading`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceHeading {
    /// Where its north points, with the standard error, from the rows the fit kept.
    pub estimate: HeadingEstimate,
    /// The world field in its axes (the field given turned by the heading), NED, µT.
    pub field_ned_ut: [f64; 3],
    /// The reference is the cube jig (the recording's routine is `cube24`): its north is the jig's edge.
    pub jig: bool,
}

/// What a vector fit's reference may be instead of what it was taken for ([`convention`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReferenceDoubt {
    /// The attitude in another convention.
    pub convention: Option<convention::Better>,
    /// The reference out of step with the readings (looked for when no other convention is found).
    pub offset: Option<convention::OutOfStep>,
    /// A part of a mostly disturbed recording that agrees with the reference but does not determine a calibration
    /// (looked for when neither of the others is found).
    pub part: Option<UndeterminedPart>,
}

impl ReferenceDoubt {
    /// Whether any was found.
    pub fn is_some(&self) -> bool {
        self.convention.is_some() || self.offset.is_some() || self.part.is_some()
    }
}

/// The part of a mostly disturbed recording one calibration explains, when it does not determine the
/// calibration: it sits in few stretches, or fitted on half of its time it misses the other half
/// ([`magcal_calib::robust::holds_out`]).
#[derive(Clone, Debug, PartialEq)]
pub struct UndeterminedPart {
    /// Its share of the samples with a reference.
    pub share: f64,
    /// Its residual's scale, µT per axis.
    pub sigma_ut: f64,
    /// The scale of the fit of the whole recording's majority, µT per axis.
    pub majority_sigma_ut: f64,
    /// Its longest stretches, in time order: `(t0_s, t1_s)` (rows, 1-based, without time).
    pub stretches: Vec<(f64, f64)>,
    /// The share of the sphere of directions its expected fields cover.
    pub covered: f64,
    /// Whether it sits in few stretches of the recording (rather than missing itself across them).
    pub brief: bool,
}

/// A vector fit whose residual exceeds this share of the field's magnitude does not fit its attitude reference: the
/// reference is not in magcal's convention, or off in time.
pub const REFERENCE_OFF_SHARE: f64 = 0.1;

impl Fit {
    /// The fit's common face, whatever its method.
    pub fn face(&self) -> &dyn CalibrationFit {
        match self {
            Fit::Vector(v) => v,
            Fit::Scalar(s) => s,
        }
    }

    /// The method that made it.
    pub fn method(&self) -> Method {
        match self {
            Fit::Vector(_) => Method::Vector,
            Fit::Scalar(_) => Method::Scalar,
        }
    }

    /// Whether it is a vector fit (every component against an attitude reference).
    pub fn is_vector(&self) -> bool {
        matches!(self, Fit::Vector(_))
    }

    /// A vector fit's residual (RMS per axis, µT) and the field's magnitude when the residual exceeds
    /// [`REFERENCE_OFF_SHARE`] of it: the attitude reference is not in magcal's convention, or off in time.
    pub fn reference_off(&self, field: &ReferenceField) -> Option<(f64, f64)> {
        match (self, field.magnitude()) {
            (Fit::Vector(v), Some(f)) => {
                let rms = v.residual_rms_ut();
                (rms > REFERENCE_OFF_SHARE * f).then_some((rms, f))
            }
            _ => None,
        }
    }
}

impl Calibration {
    /// Whether the attitude reference is in another convention ([`convention`]) or off by a good part of the field
    /// ([`Fit::reference_off`]): `A` and `b` are then no calibration (a warning says so), and go to no target.
    pub fn reference_doubtful(&self) -> bool {
        self.reference.is_some() || self.fit.reference_off(&self.field).is_some()
    }

    /// The method that was used.
    pub fn method(&self) -> Method {
        self.fit.method()
    }

    /// The final model: the diagnosis' extended model when there is one, the base fit otherwise.
    pub fn model(&self) -> Model {
        match &self.diagnosis {
            Some(d) => d.model,
            None => self.base_model(),
        }
    }

    /// The field the readings were fitted against: the field given, turned into the reference's axes when its north
    /// was found off true north ([`Calibration::reference_heading`]).
    pub fn fitted_field(&self) -> ReferenceField {
        match (&self.reference_heading, &self.field) {
            (Some(h), ReferenceField::Vector { source, .. }) => ReferenceField::Vector {
                field_ned_ut: h.field_ned_ut,
                source: format!(
                    "{source}, turned {:.2}° about the vertical into the reference's axes",
                    -h.estimate.heading_deg
                ),
            },
            _ => self.field.clone(),
        }
    }

    /// The base (12-parameter or scalar) fit.
    pub fn base_model(&self) -> Model {
        self.fit.face().model()
    }

    /// Residual RMS of the final model (µT): the diagnosis' extended fit, or the base fit.
    pub fn final_rms_ut(&self) -> f64 {
        self.diagnosis
            .as_ref()
            .map_or(self.residual_rms_ut, |d| d.extended.rms_ut)
    }

    /// Standard errors of the offset `−A⁻¹·b` of the final model, µT: the base fit's
    /// ([`CalibrationFit::offset_se_ut`]); for a model extended by the diagnosis, the larger of that and the
    /// diagnosis' own (its problem's covariance, see [`magcal_calib::diagnosis::LinearSe`]).
    pub fn offset_se_ut(&self) -> [f64; 3] {
        let base = self.fit.face().offset_se_ut();
        match self.diagnosis.as_ref().and_then(|d| d.extended.se) {
            Some(se) => std::array::from_fn(|k| base[k].max(se.offset_ut[k])),
            None => base,
        }
    }

    /// Standard errors of the final model's `A` and `b`: the base fit's, or for a model extended by the diagnosis
    /// the larger of those and the diagnosis' own.
    pub fn standard_errors(&self) -> ([[f64; 3]; 3], [f64; 3]) {
        let (a, b) = self.fit.face().standard_errors();
        match self.diagnosis.as_ref().and_then(|d| d.extended.se) {
            Some(se) => (
                std::array::from_fn(|j| std::array::from_fn(|k| a[j][k].max(se.a[j][k]))),
                std::array::from_fn(|j| b[j].max(se.b_ut[j])),
            ),
            None => (a, b),
        }
    }
}

/// What the robust base fit left out: samples whose residual departs grossly from the rest (see
/// [`magcal_calib::robust`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RobustSummary {
    /// Per recording row: kept by the base fit (rows it cannot use count as kept).
    pub kept: Vec<bool>,
    /// The residual's scale (a standard deviation per axis, or of |B|, from the median residual), µT.
    pub scale_ut: f64,
    /// The excluded spans: recording rows `[start, end)`, and their times when the recording has them, s.
    pub spans: Vec<ExcludedSpan>,
    /// Whether windows where the magnitude moved too little to be gross were looked for too (the scalar method on
    /// a recording with time, [`robust::shifted_windows`]).
    pub magnitude_windows: bool,
}

/// A span of rows the base fit excluded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExcludedSpan {
    /// First row.
    pub start: usize,
    /// One past the last row.
    pub end: usize,
    /// Time of the first and last row, s (NaN without a time column).
    pub t0_s: f64,
    /// See `t0_s`.
    pub t1_s: f64,
    /// Rows excluded in it (a span may hold kept rows between excluded ones).
    pub excluded: usize,
}

impl RobustSummary {
    /// What the robust fit that `kept` these rows (its residual scale `scale_ut`) left out of `rec`; `scalar`: the
    /// scalar method's, which also looks for windows where |B| moved.
    pub fn of(kept: Vec<bool>, scale_ut: f64, rec: &Recording, scalar: bool) -> RobustSummary {
        let t = rec.t_s.as_deref();
        let spans = robust::excluded_runs(&kept)
            .into_iter()
            .map(|(start, end)| ExcludedSpan {
                start,
                end,
                t0_s: t.map_or(f64::NAN, |t| t[start]),
                t1_s: t.map_or(f64::NAN, |t| t[end - 1]),
                excluded: kept[start..end].iter().filter(|k| !**k).count(),
            })
            .collect();
        RobustSummary {
            kept,
            scale_ut,
            spans,
            magnitude_windows: scalar && t.is_some(),
        }
    }

    /// Rows excluded.
    pub fn excluded(&self) -> usize {
        self.spans.iter().map(|s| s.excluded).sum()
    }

    /// A note saying what was excluded, when anything was.
    pub fn note(&self) -> Option<String> {
        if self.spans.is_empty() {
            return None;
        }
        const SHOWN: usize = 6;
        let mut spans: Vec<String> = self
            .spans
            .iter()
            .take(SHOWN)
            .map(|s| {
                if s.t0_s.is_finite() {
                    format!("{:.1}–{:.1} s", s.t0_s, s.t1_s)
                } else {
                    format!("rows {}–{}", s.start + 1, s.end)
                }
            })
            .collect();
        if self.spans.len() > SHOWN {
            spans.push(format!("and {} more", self.spans.len() - SHOWN));
        }
        let windows = if self.magnitude_windows {
            format!(
                " or in a window where |B| moved by more than {:.0} times the sensor's noise",
                robust::SHIFT_MIN_NOISE
            )
        } else {
            String::new()
        };
        Some(format!(
            "{} samples left out of the base fit, their residual more than {:.0} times the typical {:.2} µT{windows}: {}",
            self.excluded(),
            robust::GROSS_SIGMA,
            self.scale_ut,
            spans.join(", ")
        ))
    }
}
