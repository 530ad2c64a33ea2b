//! The JSON report (`--report report.json`). Its field names are a contract other tools read: `method`,
//! `calibration.A`, `calibration.b_ut`, `residual.rms_ut`, `residual.noise_floor_ut`, `base.{A,b_ut,rms_ut}`.
//! `calibration` and `residual` describe the final model (the one written to the parameters file, less a drift or a
//! step of the offset, which belong to this recording alone: `crate::params::sensor_model`), `base` the 12-parameter
//! fit. `units`, present when the readings are not µT, says what they are: `calibration.b_ut` and the residuals are
//! then µT when a field magnitude was known (`units.calibrated`), and `calibration.offset_ut` is in the readings' units. `heading` and `verdict` hold the heading error and the verdict the summary opens with.

use magcal_calib::diagnosis::{Components, Diagnosis, FoundEffect, ParamValue, SpanKind, Verdict};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::fit::{Calibration, Fit};
use crate::params::Correction;
use crate::verdict::{Assessment, GOOD_DEG, USABLE_DEG};

/// The whole report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// `vector` or `scalar`.
    pub method: String,
    /// The recording fitted.
    pub recording: String,
    /// The final model.
    pub calibration: CalibrationReport,
    /// The final model's residual against the noise floor.
    pub residual: ResidualReport,
    /// The 12-parameter fit.
    pub base: BaseReport,
    /// The raw noise, measured from the recording.
    pub noise: NoiseReport,
    /// Where the samples went.
    pub samples: SamplesReport,
    /// How well the rotation covered the sphere.
    pub coverage: CoverageReport,
    /// The world field used.
    pub field: FieldReport,
    /// What the method cannot see, and other things worth knowing.
    pub notes: Vec<String>,
    /// What may make the calibration wrong or unusable as it stands, and what to do (empty when all is well).
    #[serde(default)]
    pub warnings: Vec<String>,
    /// What the base model leaves out (absent with `--no-diagnose`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diagnosis: Option<DiagnosisReport>,
    /// Another convention the attitude reference fits far better in (absent when none does; the fit is then no
    /// calibration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attitude_convention: Option<ConventionReport>,
    /// A clock offset between the readings and the reference (absent when none is found; the fit is then no
    /// calibration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_offset: Option<OffsetReport>,
    /// The part of a mostly disturbed recording that agrees with the reference but does not determine a
    /// calibration (absent otherwise; the fit is then no calibration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub undetermined_part: Option<UndeterminedPartReport>,
    /// Where the attitude reference's north points, when found off true north and fitted (absent otherwise; the
    /// calibration does not depend on it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_heading: Option<ReferenceHeadingReport>,
    /// The heading error before and after, when the local field's direction is known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading: Option<HeadingReport>,
    /// Good, usable or redo, with the reason and what to do.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<VerdictReport>,
    /// What the readings are, when they are not µT (absent when they are).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<UnitsReport>,
}

/// Readings that are not µT (`magcal_app::units`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnitsReport {
    /// What one of their units is called: `counts` or `raw units`.
    pub readings: String,
    /// Their median radius about the fitted centre, in their units.
    pub radius: f64,
    /// How many make a gauss, when a chip or a unit says.
    pub per_gauss: Option<f64>,
    /// Where that comes from.
    pub source: Option<String>,
    /// The field's magnitude over what the readings read in that unit (1 at the datasheet's sensitivity).
    pub gain: Option<f64>,
    /// What the calibrated field, `b_ut` and the residuals are in: `uT`, or the readings' unit without a field.
    pub calibrated: String,
}

/// The heading figures (see `magcal_app::heading`): the sensor level over 360 headings, the worse side up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeadingReport {
    /// The horizontal field, µT (calibrated units).
    pub horizontal_ut: f64,
    /// The inclination, degrees, positive down.
    pub inclination_deg: f64,
    /// Raw readings used as if calibrated: worst heading, degrees.
    pub before_worst_deg: f64,
    /// Raw readings used as if calibrated: RMS over headings, degrees.
    pub before_rms_deg: f64,
    /// What the calibration leaves at the worst heading: one standard deviation of the largest error over the
    /// headings (drawn from the parameters' covariance, with the unexplained residual), degrees.
    pub left_worst_deg: f64,
    /// What the calibration leaves: RMS over headings of each heading's one standard deviation, degrees.
    pub left_rms_deg: f64,
    /// The part of `left_worst_deg` from the parameters' uncertainty alone, degrees.
    pub left_parameters_deg: f64,
    /// The residual the measured noise does not account for, µT.
    pub unexplained_ut: f64,
    /// One reading's noise across the field, degrees RMS.
    pub noise_deg: f64,
}

/// An attitude reference that fits far better in another convention than magcal's (`magcal_calib::convention`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConventionReport {
    /// The quaternions turn the world's axes into the sensor's.
    pub inverse: bool,
    /// The columns `qw,qx,qy,qz` hold `x, y, z, w`.
    pub scalar_last: bool,
    /// The world's axes: `ned` (magcal's), `enu`, `nwu`, or `field_up` (NED, the field's vertical reversed).
    pub world: String,
    /// In words.
    pub described: String,
    /// Others the reference fits about as well in (the recording cannot tell them apart), in words.
    pub also: Vec<String>,
    /// The median misfit (norm per sample, trimmed fit) in that convention, µT.
    pub median_misfit_ut: f64,
    /// The median misfit as the file gives the reference, µT.
    pub given_median_misfit_ut: f64,
    /// The share of the samples the reference explains in that convention (`magcal_calib::convention::Misfit`).
    pub explained: f64,
    /// The share as the file gives the reference.
    pub given_explained: f64,
}

/// Readings out of step with their reference (`magcal_calib::convention::OutOfStep`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OffsetReport {
    /// How late the readings are against the reference, s (negative: early).
    pub offset_s: f64,
    /// The share of the samples the reference explains shifted so.
    pub explained: f64,
    /// The share as the file gives the reference.
    pub given_explained: f64,
}

/// The part of a mostly disturbed recording one calibration explains, when it does not determine the calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UndeterminedPartReport {
    /// Its share of the samples with a reference.
    pub share: f64,
    /// Its residual's scale, µT per axis.
    pub sigma_ut: f64,
    /// The scale of the fit of the recording's majority, µT per axis.
    pub majority_sigma_ut: f64,
    /// Its longest stretches, `[t0_s, t1_s]` (1-based rows without time).
    pub stretches_s: Vec<(f64, f64)>,
    /// The share of the sphere of directions it covers.
    pub directions_covered: f64,
    /// Whether it sits in few stretches of the recording (else: fitted on half of its time, it misses the rest).
    pub brief: bool,
}

/// The attitude reference's north, found off true north and fitted (`magcal_app::reference_heading`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceHeadingReport {
    /// Where its north points, degrees east of true north (negative: west), in (−180, 180].
    pub heading_deg: f64,
    /// Its standard error, degrees.
    pub se_deg: f64,
    /// The declination of the field given, degrees east.
    pub declination_deg: f64,
    /// Whether the heading is the declination within its uncertainty: the reference was lined up with magnetic
    /// north (a compass).
    pub magnetic_north: bool,
    /// The field given turned into the reference's axes, against which the readings were fitted, NED, µT.
    pub field_in_reference_ned_ut: [f64; 3],
    /// The reference is the cube jig (`routine: cube24`): its north is the jig's edge.
    pub jig: bool,
}

impl ReferenceHeadingReport {
    /// The reference's heading of a calibration, when fitted.
    fn of(cal: &Calibration) -> Option<ReferenceHeadingReport> {
        let h = cal.reference_heading.as_ref()?;
        Some(ReferenceHeadingReport {
            heading_deg: h.estimate.heading_deg,
            se_deg: h.estimate.se_deg,
            declination_deg: cal
                .field
                .vector()
                .map_or(f64::NAN, |f| magcal_calib::frames::field_angles(f).0),
            magnetic_north: crate::reference_heading::on_magnetic_north(h, &cal.field),
            field_in_reference_ned_ut: h.field_ned_ut,
            jig: h.jig,
        })
    }
}

/// The verdict.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VerdictReport {
    /// `good`, `usable` or `redo`.
    pub grade: String,
    /// Why.
    pub reason: String,
    /// The one thing to do.
    pub todo: String,
    /// The gate: most heading error left for good, degrees.
    pub good_deg: f64,
    /// The gate: most heading error left for usable, degrees.
    pub usable_deg: f64,
}

/// The diagnosis, as other tools read it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisReport {
    /// `consistent` or `mismatch`.
    pub verdict: String,
    /// Effects found and modelled, in the order chosen.
    pub effects: Vec<EffectReport>,
    /// Effects that explain the same residual.
    pub ambiguous: Vec<AmbiguityReport>,
    /// Effects this recording cannot test, with the reason (absorbed ones included).
    pub untestable: Vec<UntestableReport>,
    /// Where the base model's residual departs from the noise.
    pub located: LocatedReport,
    /// The noise floor the residuals are compared with, µT.
    pub noise_floor_ut: f64,
    /// The reference's own error: the final model's residual on the clean samples beyond the sensor's noise, µT.
    #[serde(default)]
    pub reference_floor_ut: f64,
    /// The spans where the residual departed grossly, what each was, and whether it was modelled or left out.
    #[serde(default)]
    pub spans: Vec<SpanReport>,
    /// Gross spans that are no finding — at most a few samples, or within what the recording's own noise makes by
    /// chance — left out of the calibration and counted.
    #[serde(default)]
    pub glitches: Vec<GlitchReport>,
    /// Effects the data suggested but the model does not hold, and why.
    #[serde(default)]
    pub rejected: Vec<RejectedReport>,
    /// Samples left out of the calibration in gross spans.
    #[serde(default)]
    pub samples_excluded: usize,
    /// Samples the diagnosis used.
    pub samples_used: usize,
    /// Rows left out for a missing channel.
    pub samples_left_out: usize,
}

/// One effect found.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectReport {
    /// The effect id (`time_lag`, …).
    pub id: String,
    /// Parameters by name, each with `<name>_se` beside it where estimated.
    pub params: Map<String, Value>,
    /// Residual RMS before adding it, µT.
    pub rms_before_ut: f64,
    /// Residual RMS after, µT.
    pub rms_after_ut: f64,
    /// Held-out RMS before, µT.
    pub holdout_rms_before_ut: f64,
    /// Held-out RMS after, µT.
    pub holdout_rms_after_ut: f64,
    /// Evidence (Wald statistic minus the complexity penalty).
    pub evidence: f64,
    /// Its size: RMS per axis of its perturbation where it acts, µT.
    #[serde(default)]
    pub size_ut: f64,
    /// The finding in words.
    pub explanation: String,
}

/// A glitch: a gross span that is no finding.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GlitchReport {
    /// First sample's time, s.
    pub t0_s: f64,
    /// Last sample's time, s.
    pub t1_s: f64,
    /// Samples in it.
    pub samples: usize,
    /// Largest residual in it, µT.
    pub peak_ut: f64,
}

/// A gross span.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpanReport {
    /// First sample's time, s.
    pub t0_s: f64,
    /// Last sample's time, s.
    pub t1_s: f64,
    /// Samples in it.
    pub samples: usize,
    /// Largest residual in it under the base fit, µT.
    pub peak_ut: f64,
    /// The base fit's residual RMS in it, µT.
    pub rms_ut: f64,
    /// `sensor_fixed`, `room_fixed`, `magnitude_shift` (scalar method), `moving` or `unexplained`.
    pub kind: String,
    /// The constant field that explains it: in sensor axes (`sensor_fixed`) or NED (`room_fixed`), µT.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field_ut: Option<[f64; 3]>,
    /// The constant shift of |B| that explains it (`magnitude_shift`), µT.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shift_ut: Option<f64>,
    /// Modelled (the samples its constant explains kept, with an effect) or left out of the calibration.
    pub modelled: bool,
    /// Of a span left out, the samples the calibration kept all the same: its fading edges and lulls, which fit as
    /// well as the clean part.
    #[serde(default)]
    pub kept_samples: usize,
    /// In words.
    pub explanation: String,
}

/// An effect rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RejectedReport {
    /// The effect id.
    pub id: String,
    /// Why.
    pub why: String,
}

/// Two effects that explain the same residual.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AmbiguityReport {
    /// The effect modelled and the alternative.
    pub ids: Vec<String>,
    /// Why they cannot be told apart here.
    pub why: String,
    /// The experiment that would separate them.
    pub experiment: String,
}

/// An effect that could not be tested.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UntestableReport {
    /// The effect id.
    pub id: String,
    /// Why.
    pub why: String,
}

/// Where the mismatch is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocatedReport {
    /// Axes above the noise (`x`, `y`, `z`, or `|B|`).
    pub axes: Vec<String>,
    /// Residual RMS per axis, µT.
    pub axis_rms_ut: Vec<f64>,
    /// Time spans above the noise.
    pub segments: Vec<SegmentReport>,
    /// The channel the residual follows.
    pub channel: Option<String>,
    /// The share of the residual's variance it explains.
    pub channel_share: f64,
    /// The orientation where the residual is largest, if it stands out.
    pub orientation: Option<OrientationReport>,
}

/// A time span.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SegmentReport {
    /// Start, s.
    pub t0_s: f64,
    /// End, s.
    pub t1_s: f64,
    /// RMS inside, µT.
    pub rms_ut: f64,
}

/// An orientation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrientationReport {
    /// The sensor axis the field points along.
    pub direction: String,
    /// Residual RMS there, µT.
    pub rms_ut: f64,
    /// Elsewhere, µT.
    pub elsewhere_rms_ut: f64,
}

/// A found effect's parameters by name, each with `<name>_se` beside it where estimated.
pub(crate) fn params_json(e: &FoundEffect) -> Map<String, Value> {
    let mut params = Map::new();
    for p in &e.params {
        params.insert(p.name.to_owned(), json_value(&p.value));
        if let Some(se) = &p.se {
            params.insert(format!("{}_se", p.name), json_value(se));
        }
    }
    params
}

fn json_value(v: &ParamValue) -> Value {
    match v {
        ParamValue::Number(x) => serde_json::json!(x),
        ParamValue::Vector(x) => serde_json::json!(x),
        ParamValue::Text(t) => Value::String(t.clone()),
    }
}

impl DiagnosisReport {
    /// The report of a diagnosis.
    pub fn new(d: &Diagnosis) -> DiagnosisReport {
        DiagnosisReport {
            verdict: match d.verdict {
                Verdict::Consistent => "consistent",
                Verdict::Mismatch => "mismatch",
            }
            .to_owned(),
            effects: d
                .effects
                .iter()
                .map(|e| EffectReport {
                    id: e.effect.id().as_str().to_owned(),
                    params: params_json(e),
                    rms_before_ut: e.rms_before_ut,
                    rms_after_ut: e.rms_after_ut,
                    holdout_rms_before_ut: e.holdout_rms_before_ut,
                    holdout_rms_after_ut: e.holdout_rms_after_ut,
                    evidence: e.evidence,
                    size_ut: e.size_ut,
                    explanation: e.explanation.clone(),
                })
                .collect(),
            ambiguous: d
                .ambiguous
                .iter()
                .map(|a| AmbiguityReport {
                    ids: a.ids.iter().map(|i| i.as_str().to_owned()).collect(),
                    why: a.why.clone(),
                    experiment: a.experiment.clone(),
                })
                .collect(),
            untestable: d
                .untestable
                .iter()
                .map(|u| UntestableReport {
                    id: u.id.as_str().to_owned(),
                    why: u.why.clone(),
                })
                .collect(),
            located: LocatedReport {
                axes: d.located.axes.iter().map(|a| (*a).to_owned()).collect(),
                axis_rms_ut: d.located.axis_rms_ut.clone(),
                segments: d
                    .located
                    .segments
                    .iter()
                    .map(|s| SegmentReport {
                        t0_s: s.t0_s,
                        t1_s: s.t1_s,
                        rms_ut: s.rms_ut,
                    })
                    .collect(),
                channel: d.located.channel.clone(),
                channel_share: d.located.channel_share,
                orientation: d.located.orientation.map(|o| OrientationReport {
                    direction: o.direction.to_owned(),
                    rms_ut: o.rms_ut,
                    elsewhere_rms_ut: o.elsewhere_rms_ut,
                }),
            },
            noise_floor_ut: d.noise_floor_ut,
            reference_floor_ut: d.reference_floor_ut,
            spans: d
                .spans
                .iter()
                .map(|sp| {
                    let shift_ut = match sp.kind {
                        SpanKind::MagnitudeShift { shift_ut } => Some(shift_ut),
                        _ => None,
                    };
                    let (kind, field_ut) = match sp.kind {
                        SpanKind::SensorFixed { offset_ut, .. } => {
                            ("sensor_fixed", Some(offset_ut))
                        }
                        SpanKind::RoomFixed { field_ned_ut } => ("room_fixed", Some(field_ned_ut)),
                        SpanKind::MagnitudeShift { .. } => ("magnitude_shift", None),
                        SpanKind::Moving => ("moving", None),
                        SpanKind::Unexplained => ("unexplained", None),
                    };
                    SpanReport {
                        t0_s: sp.t0_s,
                        t1_s: sp.t1_s,
                        samples: sp.samples,
                        peak_ut: sp.peak_ut,
                        rms_ut: sp.rms_ut,
                        kind: kind.to_owned(),
                        field_ut,
                        shift_ut,
                        modelled: sp.modelled,
                        kept_samples: sp.kept_samples,
                        explanation: sp.explanation.clone(),
                    }
                })
                .collect(),
            glitches: d
                .glitches
                .iter()
                .map(|g| GlitchReport {
                    t0_s: g.t0_s,
                    t1_s: g.t1_s,
                    samples: g.samples,
                    peak_ut: g.peak_ut,
                })
                .collect(),
            rejected: d
                .rejected
                .iter()
                .map(|r| RejectedReport {
                    id: r.id.as_str().to_owned(),
                    why: r.why.clone(),
                })
                .collect(),
            samples_excluded: d.samples_excluded,
            samples_used: d.samples_used,
            samples_left_out: d.samples_left_out,
        }
    }
}

/// `B = A·B̂ + b − Σ corrections`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CalibrationReport {
    /// `A`, row-major.
    #[serde(rename = "A")]
    pub a: [[f64; 3]; 3],
    /// `b`, µT.
    pub b_ut: [f64; 3],
    /// Standard errors of `A`.
    #[serde(rename = "A_se")]
    pub a_se: [[f64; 3]; 3],
    /// Standard errors of `b`, µT.
    pub b_se_ut: [f64; 3],
    /// The hard-iron offset in raw units, `−A⁻¹·b`, µT.
    pub offset_ut: [f64; 3],
    /// Standard errors of the offset, µT.
    #[serde(default)]
    pub offset_se_ut: [f64; 3],
    /// Body-fixed corrections.
    pub corrections: Vec<Correction>,
    /// Scalar method: the raw ellipsoid's semi-axes, largest first, µT.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ellipsoid_radii_ut: Option<[f64; 3]>,
    /// How much more the base fits of the recording's two halves in time disagree than their covariances say, per
    /// parameter (`κ`, about 1 when they agree); the base fit's standard errors are widened by `√κ` when above 1.
    #[serde(default = "one")]
    pub halves_dispersion: f64,
}

/// The halves' dispersion of a report written before it was measured.
fn one() -> f64 {
    1.0
}

/// Residual RMS against the noise floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResidualReport {
    /// RMS per axis (vector) or of |B| − F (scalar), µT.
    pub rms_ut: f64,
    /// Held-out RMS (blocked cross-validation), µT, when diagnosed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_rms_ut: Option<f64>,
    /// The noise floor in calibrated units, µT.
    pub noise_floor_ut: f64,
    /// RMS per calibrated axis (vector method), µT.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rms_axis_ut: Option<[f64; 3]>,
}

/// The 12-parameter fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaseReport {
    /// `A`.
    #[serde(rename = "A")]
    pub a: [[f64; 3]; 3],
    /// `b`, µT.
    pub b_ut: [f64; 3],
    /// Its residual RMS, µT.
    pub rms_ut: f64,
    /// Its held-out RMS, µT, when diagnosed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_rms_ut: Option<f64>,
}

/// The raw noise floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseReport {
    /// Random noise per raw axis, µT.
    pub sigma_ut: [f64; 3],
    /// The readings' grid step, µT, if on one.
    pub lsb_ut: Option<[f64; 3]>,
    /// Floor per raw axis (noise and quantisation), µT.
    pub floor_ut: [f64; 3],
    /// `still segment t=…` or `differences of order k`.
    pub source: String,
}

/// Sample counts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplesReport {
    /// Rows in the recording.
    pub total: usize,
    /// Rows used.
    pub used: usize,
    /// Rows left out for a missing attitude reference.
    pub missing_reference: usize,
    /// Rows the robust base fit excluded as grossly off.
    #[serde(default)]
    pub excluded: usize,
}

/// Coverage of the rotation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CoverageReport {
    /// Fraction of the sphere of field directions visited (100 cells).
    pub sphere_fraction: f64,
    /// Spread of the raw readings along their principal directions, µT.
    pub spread_ut: [f64; 3],
    /// The least observed direction, sensor axes.
    pub weakest_direction: [f64; 3],
    /// Largest over smallest spread.
    pub condition_number: f64,
}

/// The field used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldReport {
    /// NED vector, µT, when known.
    pub ned_ut: Option<[f64; 3]>,
    /// Magnitude, µT, when known (for the scalar method without one: the fitted radius).
    pub magnitude_ut: Option<f64>,
    /// Where it came from.
    pub source: String,
}

/// RMS per component of per-sample residuals.
fn per_axis_rms(res: &Components) -> [f64; 3] {
    let n = res.len().max(1) as f64;
    std::array::from_fn(|j| {
        (res.iter()
            .map(|r| r.get(j).map_or(0.0, |v| v * v))
            .sum::<f64>()
            / n)
            .sqrt()
    })
}

impl Report {
    /// The report of a calibration of `recording`.
    pub fn new(cal: &Calibration, recording: &str, channels: &[String]) -> Report {
        let model = cal.model();
        let (a_se, b_se_ut) = cal.standard_errors();
        let coverage = cal.fit.face().coverage();
        let magnitude_ut = cal.field.magnitude().or(cal.fit.face().magnitude_ut());
        let rms_axis_ut = match &cal.fit {
            Fit::Vector(v) => Some(v.residual_rms_ut),
            Fit::Scalar(_) => None,
        };
        Report {
            method: cal.method().as_str().to_owned(),
            recording: recording.to_owned(),
            calibration: CalibrationReport {
                a: model.a,
                b_ut: model.b_ut,
                a_se,
                b_se_ut,
                offset_ut: magcal_calib::scalar::centre(&model.a, model.b_ut),
                offset_se_ut: cal.offset_se_ut(),
                corrections: model
                    .corrections()
                    .filter_map(|e| Correction::from_effect(e, channels))
                    .collect(),
                ellipsoid_radii_ut: match &cal.fit {
                    Fit::Scalar(s) => Some(s.radii_ut()),
                    Fit::Vector(_) => None,
                },
                halves_dispersion: cal.fit.face().halves().kappa,
            },
            residual: match &cal.diagnosis {
                Some(d) => ResidualReport {
                    rms_ut: d.extended.rms_ut,
                    holdout_rms_ut: Some(d.extended.holdout_rms_ut),
                    noise_floor_ut: d.noise_floor_ut,
                    rms_axis_ut: rms_axis_ut.map(|_| per_axis_rms(&d.residuals.extended)),
                },
                None => ResidualReport {
                    rms_ut: cal.residual_rms_ut,
                    holdout_rms_ut: None,
                    noise_floor_ut: cal.noise_floor_ut,
                    rms_axis_ut,
                },
            },
            base: match &cal.diagnosis {
                Some(d) => BaseReport {
                    a: d.base.a,
                    b_ut: d.base.b_ut,
                    rms_ut: d.base.rms_ut,
                    holdout_rms_ut: Some(d.base.holdout_rms_ut),
                },
                None => BaseReport {
                    a: model.a,
                    b_ut: model.b_ut,
                    rms_ut: cal.residual_rms_ut,
                    holdout_rms_ut: None,
                },
            },
            noise: NoiseReport {
                sigma_ut: cal.noise.sigma_ut,
                lsb_ut: cal.noise.lsb_ut,
                floor_ut: cal.noise.floor_ut,
                source: crate::readings::noise_source(&cal.noise),
            },
            samples: SamplesReport {
                total: cal.samples.total,
                used: cal.samples.used,
                missing_reference: cal.samples.missing_reference,
                excluded: cal.samples.excluded,
            },
            coverage: CoverageReport {
                sphere_fraction: cal.sphere_coverage,
                spread_ut: coverage.spread_ut,
                weakest_direction: coverage.directions[2],
                condition_number: coverage.spread_ut[0] / coverage.spread_ut[2],
            },
            field: FieldReport {
                ned_ut: cal.field.vector(),
                magnitude_ut,
                source: cal.field.source().to_owned(),
            },
            notes: cal.notes.clone(),
            warnings: cal.warnings.clone(),
            diagnosis: cal.diagnosis.as_ref().map(DiagnosisReport::new),
            attitude_convention: cal.reference.convention.as_ref().map(|b| ConventionReport {
                inverse: b.convention.inverse,
                scalar_last: b.convention.scalar_last,
                world: b.convention.world.as_str().to_owned(),
                described: b.convention.describe(),
                also: b.also.iter().map(|c| c.describe()).collect(),
                median_misfit_ut: b.better.median_ut,
                given_median_misfit_ut: b.given.median_ut,
                explained: b.better.explained,
                given_explained: b.given.explained,
            }),
            reference_offset: cal.reference.offset.map(|o| OffsetReport {
                offset_s: o.offset_s,
                explained: o.shifted.explained,
                given_explained: o.given.explained,
            }),
            undetermined_part: cal.reference.part.as_ref().map(|p| UndeterminedPartReport {
                share: p.share,
                sigma_ut: p.sigma_ut,
                majority_sigma_ut: p.majority_sigma_ut,
                stretches_s: p.stretches.clone(),
                directions_covered: p.covered,
                brief: p.brief,
            }),
            reference_heading: ReferenceHeadingReport::of(cal),
            heading: None,
            verdict: None,
            units: cal.units.raw().map(|r| UnitsReport {
                readings: cal.units.raw_label(),
                radius: r.radius,
                per_gauss: r.scale.as_ref().map(|s| s.per_gauss),
                source: r.scale.as_ref().map(|s| s.source.clone()),
                gain: r.gain,
                calibrated: if cal.units.calibrated_ut() {
                    "uT".to_owned()
                } else {
                    cal.units.raw_label()
                },
            }),
        }
    }

    /// The report with the heading figures and the verdict.
    pub fn with_assessment(mut self, a: &Assessment) -> Report {
        self.heading = a.heading.as_ref().map(|h| HeadingReport {
            horizontal_ut: h.field.horizontal_ut,
            inclination_deg: h.field.inclination_deg(),
            before_worst_deg: h.before.worst_deg,
            before_rms_deg: h.before.rms_deg,
            left_worst_deg: h.left.worst_deg,
            left_rms_deg: h.left.rms_deg,
            left_parameters_deg: h.parameters_deg,
            unexplained_ut: h.unexplained_ut,
            noise_deg: h.noise_deg,
        });
        let v = &a.verdict;
        self.verdict = Some(VerdictReport {
            grade: v.grade.name().to_owned(),
            reason: v.reason.clone(),
            todo: v.todo.clone(),
            good_deg: GOOD_DEG,
            usable_deg: USABLE_DEG,
        });
        self
    }

    /// Writes the report as pretty JSON, atomically.
    pub fn write(&self, path: &std::path::Path) -> anyhow::Result<()> {
        use anyhow::Context;
        crate::files::write_atomic(path, self.to_json().as_bytes())
            .with_context(|| format!("writing the report {}", path.display()))
    }

    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report is plain data")
    }
}
