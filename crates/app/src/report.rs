//! The JSON report (`--report report.json`). Its field names are a contract other tools read: `method`,
//! `calibration.A`, `calibration.b_ut`, `residual.rms_ut`, `residual.noise_floor_ut`, `base.{A,b_ut,rms_ut}`.
//! `calibration` and `residual` describe the final model (the one written to the parameters file), `base` the
//! 12-parameter fit.

use magcal_calib::noise::NoiseSource;
use serde::{Deserialize, Serialize};

use crate::calibrate::{Calibration, Fit};
use crate::params::Correction;

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
    /// Warnings and what the method cannot see.
    pub notes: Vec<String>,
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
    /// Body-fixed corrections.
    pub corrections: Vec<Correction>,
    /// Scalar method: the raw ellipsoid's semi-axes, largest first, µT.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ellipsoid_radii_ut: Option<[f64; 3]>,
}

/// Residual RMS against the noise floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResidualReport {
    /// RMS per axis (vector) or of |B| − F (scalar), µT.
    pub rms_ut: f64,
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

impl Report {
    /// The report of a calibration of `recording`.
    pub fn new(cal: &Calibration, recording: &str, channels: &[String]) -> Report {
        let model = cal.model();
        let (a_se, b_se_ut) = cal.standard_errors();
        let coverage = match &cal.fit {
            Fit::Vector(v) => v.coverage,
            Fit::Scalar(s) => s.coverage,
        };
        let magnitude_ut = cal.field.magnitude().or(match &cal.fit {
            Fit::Scalar(s) => Some(s.field_ut),
            Fit::Vector(_) => None,
        });
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
                corrections: model
                    .corrections()
                    .filter_map(|e| Correction::from_effect(e, channels))
                    .collect(),
                ellipsoid_radii_ut: match &cal.fit {
                    Fit::Scalar(s) => Some(s.radii_ut()),
                    Fit::Vector(_) => None,
                },
            },
            residual: ResidualReport {
                rms_ut: cal.residual_rms_ut,
                noise_floor_ut: cal.noise_floor_ut,
                rms_axis_ut,
            },
            base: BaseReport {
                a: model.a,
                b_ut: model.b_ut,
                rms_ut: cal.residual_rms_ut,
            },
            noise: NoiseReport {
                sigma_ut: cal.noise.sigma_ut,
                lsb_ut: cal.noise.lsb_ut,
                floor_ut: cal.noise.floor_ut,
                source: match cal.noise.source {
                    NoiseSource::Still { start, end } => {
                        format!("still segment, samples {start}–{end}")
                    }
                    NoiseSource::Differences { order } => format!("differences of order {order}"),
                },
            },
            samples: SamplesReport {
                total: cal.samples.total,
                used: cal.samples.used,
                missing_reference: cal.samples.missing_reference,
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
        }
    }

    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report is plain data")
    }
}
