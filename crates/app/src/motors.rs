//! The bench motor test's fit: `magcal-fit` of a recording whose metadata says `routine: motors` (written by
//! `magcal-record --routine motors`).
//!
//! The vehicle was held still, so the recording has one orientation: `A` and `b` cannot be fitted from it, and the
//! coverage check would rightly refuse it as a calibration. What it gives is the current term alone
//! ([`magcal_calib::diagnosis::fit_motors`]): per axis `B(t) = B0 + k·I(t − lag)`, `k` the catalogue's
//! `current_bias` coefficients in µT/A with their standard errors, kept only when the diagnosis' selection takes it.
//!
//! Which field `k` is in: the recording's field is the chip's own (a flight controller's, with the autopilot's
//! calibration undone by the recorder). With `--params PARAMS.toml` (the fit of a rotation recording of the same
//! sensor) its `A` and `b` are applied first, so `k` is in calibrated µT/A, the unit the autopilots' motor
//! compensation takes; without it, `k` is in the readings' own axes and scale (a calibration's `A` is the identity
//! to within its gains' few per cent: said in the summary).
//!
//! The heading error the term makes is worked out at the held attitude (the mean of the recording's quaternions) in
//! the world field (`--field-ned`, `--location`/`--date`, or the recording's metadata): at hover current, the median
//! of the currents above idle (the lowest current plus [`IDLE_SHARE`] of the range), and at full current, the
//! highest recorded ([`magcal_calib::diagnosis::heading_error_deg`]).
//!
//! The term goes to an autopilot as its motor compensation: exported ([`MotorsFitted::export`]) or written to the
//! flight controller ([`MotorsFitted::write_back`]).

use std::path::Path;

use anyhow::{Context as _, bail};
use magcal_calib::diagnosis::{
    Lag, MAX_LAG_HALF_WIDTH_S, MotorFit, MotorInput, fit_motors, heading_error_deg,
};
use magcal_calib::frames::{self, Mat3};
use magcal_recording::Recording;

use crate::device::DeviceSpec;
use crate::export::{ExportFormat, current_export};
use crate::field::{FieldArgs, resolve};
use crate::params::ParamsFile;
use crate::record::Routine;
use crate::writeback::write_back_current;

/// Currents up to this share of the range above the lowest are idle: the hover current is the median of the rest.
pub const IDLE_SHARE: f64 = 0.1;
/// The largest lag between the current and the field scanned either way, s.
pub const MAX_LAG_S: f64 = 1.0;

/// Whether the file at `path` is a motors recording (its metadata's `routine` is `motors`).
pub fn is_motors_recording(path: &Path) -> bool {
    Recording::read_metadata(path)
        .is_ok_and(|m| m.routine.as_deref() == Some(Routine::Motors.name()))
}

/// What a motors fit is asked for.
#[derive(Clone, Copy, Debug)]
pub struct MotorsRequest<'a> {
    /// The world field as given on the command line (else the recording's metadata says it).
    pub field: &'a FieldArgs,
    /// The sensor's calibration, fitted elsewhere (`--params`).
    pub params: Option<&'a Path>,
}

/// The heading error the current term makes at the held attitude.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingFigures {
    /// The hover current (the median above idle), A, and the heading error there, degrees.
    pub hover: (f64, f64),
    /// The full current (the highest), A, and the heading error there, degrees.
    pub full: (f64, f64),
    /// The world field's horizontal part, µT.
    pub horizontal_ut: f64,
}

/// A motors recording fitted.
#[derive(Debug)]
pub struct MotorsFitted {
    /// The recording as read.
    pub rec: Recording,
    /// The current channel fitted (`i_battery` for a flight controller).
    pub channel: String,
    /// The calibration applied first: the parameters file and its `A`; `None` for the readings as recorded.
    pub calibration: Option<(String, Mat3)>,
    /// The fit.
    pub fit: MotorFit,
    /// The noise floor per calibrated axis, µT.
    pub noise_floor_ut: [f64; 3],
    /// The lowest and highest current, A.
    pub current_range_a: (f64, f64),
    /// The heading error the term makes, or why it cannot be said.
    pub headings: Result<HeadingFigures, String>,
}

/// Reads and fits the motors recording at `path`; see the [module docs](self).
pub fn fit_motors_file(path: &Path, request: &MotorsRequest<'_>) -> anyhow::Result<MotorsFitted> {
    let name = path.display();
    let rec = Recording::read(path)?;
    let Some(t_s) = rec.t_s.as_deref() else {
        bail!("{name}: a motors recording needs its t column (the current's lag is in time)");
    };
    let Some(current) = rec.currents.first() else {
        bail!(
            "{name}: no current channel (an i_<name> column): a motors recording holds the current the motors draw \
             (magcal-record --routine motors records a flight controller's battery current as i_battery)"
        );
    };
    let (calibration, a, b_ut) = match request.params {
        Some(p) => {
            let file = ParamsFile::read(p)?;
            if let Some(units) = &file.units {
                bail!(
                    "{}: its readings were {}, not µT; a motors recording holds µT (fit the sensor's µT readings \
                     and give that parameters file)",
                    p.display(),
                    units.readings
                );
            }
            let (a, b) = (file.calibration.a, file.calibration.b_ut);
            (Some((p.display().to_string(), a)), a, b)
        }
        None => (None, IDENTITY, [0.0; 3]),
    };
    let field_ut: Vec<[f64; 3]> = rec
        .mag_ut
        .iter()
        .map(|&m| frames::add(frames::mat_vec(&a, m), b_ut))
        .collect();
    let noise_floor_ut = magcal_calib::noise::estimate(&rec.mag_ut, None).calibrated_ut(&a);
    let fit = fit_motors(&MotorInput {
        t_s,
        field_ut: &field_ut,
        current_a: &current.values,
        noise_floor_ut,
        max_lag_s: MAX_LAG_S,
    })
    .with_context(|| format!("{name}: cannot fit the current term"))?;
    let finite: Vec<f64> = current
        .values
        .iter()
        .copied()
        .filter(|i| i.is_finite())
        .collect();
    let lowest = finite.iter().copied().fold(f64::INFINITY, f64::min);
    let highest = finite.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let headings = headings(&rec, &fit, &finite, (lowest, highest), request.field);
    Ok(MotorsFitted {
        channel: current.name.clone(),
        rec,
        calibration,
        fit,
        noise_floor_ut,
        current_range_a: (lowest, highest),
        headings,
    })
}

const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The hover current: the median of the currents above idle (the lowest plus [`IDLE_SHARE`] of the range).
pub fn hover_current_a(currents_a: &[f64], (lowest, highest): (f64, f64)) -> f64 {
    let idle = lowest + IDLE_SHARE * (highest - lowest);
    let mut above: Vec<f64> = currents_a.iter().copied().filter(|&i| i > idle).collect();
    if above.is_empty() {
        return highest;
    }
    above.sort_by(f64::total_cmp);
    let n = above.len();
    if n % 2 == 1 {
        above[n / 2]
    } else {
        (above[n / 2 - 1] + above[n / 2]) / 2.0
    }
}

/// The mean of the recording's attitudes (sensor → NED), as a matrix; `None` without one.
fn held_attitude(rec: &Recording) -> Option<Mat3> {
    let quats = rec.quat.as_deref()?;
    let mut sum = [0.0; 4];
    let mut first: Option<[f64; 4]> = None;
    for q in quats.iter().filter(|q| q[0].is_finite()) {
        let f = *first.get_or_insert(*q);
        // q and −q are one attitude: each is added on the first's side.
        let sign = if (0..4).map(|k| q[k] * f[k]).sum::<f64>() < 0.0 {
            -1.0
        } else {
            1.0
        };
        (0..4).for_each(|k| sum[k] += sign * q[k]);
    }
    let norm = sum.iter().map(|v| v * v).sum::<f64>().sqrt();
    (norm > 0.0).then(|| frames::quat_to_matrix(sum.map(|v| v / norm)))
}

/// The heading figures of a fit, or why there are none.
fn headings(
    rec: &Recording,
    fit: &MotorFit,
    currents_a: &[f64],
    range_a: (f64, f64),
    field: &FieldArgs,
) -> Result<HeadingFigures, String> {
    let term = fit
        .current
        .as_ref()
        .ok_or("no current term, so no heading error from it")?;
    let r = held_attitude(rec)
        .ok_or("the recording has no attitude (qw,qx,qy,qz), so the held heading is not known")?;
    let field_ned_ut = resolve(field, &rec.meta)
        .map_err(|e| e.to_string())?
        .vector()
        .ok_or(
            "no world field vector (give --field-ned or --location/--date, or record with them): the heading error \
             needs the field's horizontal part",
        )?;
    let hover_a = hover_current_a(currents_a, range_a);
    let at = |i: f64| (i, heading_error_deg(&term.effect, i, &r, field_ned_ut));
    Ok(HeadingFigures {
        hover: at(hover_a),
        full: at(range_a.1),
        horizontal_ut: field_ned_ut[0].hypot(field_ned_ut[1]),
    })
}

/// What to do about a lag whose interval is wide.
const LAG_ADVICE: &str = "the current changed too slowly for the field's delay to show (its information is \
                          Σ (k·dI/dt)²/σ²): blip the throttle, snapping it from idle to high and back, ten times \
                          (magcal-record --routine motors asks for it), and record again";

/// Why the report gives no `lag_s`, when it does not.
fn lag_not_determined(lag: Option<Lag>) -> Option<String> {
    match lag {
        Some(l) if l.determined() => None,
        Some(l) if !l.current_keeps_up() => Some(format!(
            "the current changed every {:.0} ms (the median), the field was sampled every {:.0} ms: a current \
             measured less often than the field is held between measurements, late by up to that, so the lag found \
             is not the field's (ArduCopter reads its battery monitor at 10 Hz whatever rate BATTERY_STATUS is \
             streamed at); the coefficients are still fitted (with a 10 Hz current, simulated, within 7 % at \
             0.05 µT/A and 2 % at 1 µT/A)",
            1e3 * l.current_update_s,
            1e3 * l.sample_interval_s
        )),
        Some(l) => Some(format!(
            "its profile interval is ± {:.1} ms (one standard deviation), wider than ± {:.1} ms: {LAG_ADVICE}",
            1e3 * l.half_width_s(),
            1e3 * MAX_LAG_HALF_WIDTH_S
        )),
        None => Some(format!(
            "no profile interval within ± {MAX_LAG_S} s (taken as 0 s): {LAG_ADVICE}"
        )),
    }
}

/// A number with its standard error, to the error's two significant digits.
fn with_se(v: f64, se: f64) -> String {
    let digits = if se > 0.0 && se.is_finite() {
        (1.0 - se.log10().floor()).clamp(0.0, 6.0) as usize
    } else {
        4
    };
    format!("{v:+.digits$} ± {se:.digits$}")
}

impl MotorsFitted {
    /// The summary for the terminal, `name` standing for the recording.
    pub fn summary(&self, name: &str) -> String {
        let f = &self.fit;
        let (lo, hi) = self.current_range_a;
        let mut s = format!(
            "motor test {name}: {} samples, current {} from {lo:.1} to {hi:.1} A\n",
            f.samples, self.channel
        );
        s += &match &self.calibration {
            Some((path, _)) => format!("calibration applied first: {path} (A and b): k is in calibrated µT/A\n"),
            None => "no --params: k is in the readings' own axes and scale (a flight controller's recording: the chip's \
                     field with the autopilot's calibration undone), which a calibration's A changes by its gains' few \
                     per cent; give --params PARAMS.toml, the fit of a rotation recording, for calibrated µT/A\n"
                .to_owned(),
        };
        let floor = magcal_calib::noise::rms3(self.noise_floor_ut);
        match &f.current {
            Some(term) => {
                let (k, se) = (term.coef_ut_per_a(), term.coef_se_ut_per_a);
                let axes: Vec<String> = (0..3).map(|j| with_se(k[j], se[j])).collect();
                s += &format!(
                    "current term (current_bias on {}): k = [{}] µT/A, i.e. [{:+.2}, {:+.2}, {:+.2}] µT per 10 A\n",
                    self.channel,
                    axes.join(", "),
                    10.0 * k[0],
                    10.0 * k[1],
                    10.0 * k[2]
                );
                let why = lag_not_determined(term.lag);
                s += &match (term.lag, why) {
                    (Some(l), None) => format!(
                        "  lag of the field behind the recorded current: {:.1} ms ({:.1} to {:.1} ms, one standard \
                         deviation)\n",
                        1e3 * l.lag_s,
                        1e3 * l.interval_s.0,
                        1e3 * l.interval_s.1
                    ),
                    (Some(l), Some(why)) => format!(
                        "  lag of the field behind the recorded current: not determined ({:.1} ms at best, where k is \
                         fitted): {why}\n",
                        1e3 * l.lag_s
                    ),
                    (None, why) => format!(
                        "  lag of the field behind the recorded current: not identified: {}\n",
                        why.unwrap_or_default()
                    ),
                };
            }
            None => {
                s += &format!(
                    "no current term: {}\n",
                    f.untestable.unwrap_or(
                        "the field does not follow the current beyond its noise (the diagnosis' selection: Wald test \
                         with its penalty, held-out blocks)"
                    )
                );
            }
        }
        s += &format!(
            "  residual {:.3} µT RMS per axis against a noise floor of {floor:.3} µT (the constant field alone: {:.3} \
             µT){}\n",
            f.residual_rms_ut,
            f.constant_rms_ut,
            if f.autocorrelation > 1.5 {
                format!(
                    "; neighbouring residuals alike (autocorrelation factor {:.1})",
                    f.autocorrelation
                )
            } else {
                String::new()
            }
        );
        s += &match &self.headings {
            Ok(h) => format!(
                "heading error this removes: {:.1}° at hover current ({:.1} A, the median current above idle) and \
                 {:.1}° at full current ({:.1} A, the maximum), at the held attitude in a horizontal field of {:.1} µT\n",
                h.hover.1, h.hover.0, h.full.1, h.full.0, h.horizontal_ut
            ),
            Err(why) if f.current.is_some() => format!("heading error: not worked out: {why}\n"),
            Err(_) => String::new(),
        };
        s
    }

    /// The JSON report: the current term under the diagnosis' effect id and parameter names.
    pub fn report(&self, name: &str) -> serde_json::Value {
        let f = &self.fit;
        let term = f.current.as_ref().map(|t| {
            serde_json::json!({
                "id": "current_bias",
                "params": {
                    "channel": self.channel,
                    "coef_ut_per_a": t.coef_ut_per_a(),
                    "coef_ut_per_a_se": t.coef_se_ut_per_a,
                },
                "evidence": t.evidence,
                "lag_s": t.lag.filter(|l| l.determined()).map(|l| l.lag_s),
                "lag_interval_s": t.lag.map(|l| [l.interval_s.0, l.interval_s.1]),
                "lag_not_determined": lag_not_determined(t.lag),
            })
        });
        let headings = self.headings.as_ref().ok().map(|h| {
            serde_json::json!({
                "hover_current_a": h.hover.0,
                "hover_deg": h.hover.1,
                "full_current_a": h.full.0,
                "full_deg": h.full.1,
                "horizontal_field_ut": h.horizontal_ut,
            })
        });
        serde_json::json!({
            "routine": Routine::Motors.name(),
            "recording": name,
            "samples": f.samples,
            "channel": self.channel,
            "current_range_a": [self.current_range_a.0, self.current_range_a.1],
            "calibration": self.calibration.as_ref().map(|(p, _)| p),
            "offset_ut": f.offset_ut,
            "current_bias": term,
            "untestable": f.untestable,
            "residual_rms_ut": f.residual_rms_ut,
            "constant_rms_ut": f.constant_rms_ut,
            "noise_floor_ut": self.noise_floor_ut,
            "autocorrelation": f.autocorrelation,
            "heading_error": headings,
            "heading_error_not": self.headings.as_ref().err(),
        })
    }

    /// The current term in an autopilot's motor-compensation parameters ([`current_export`]); an error when there is
    /// no term to export or the format has no place for one.
    pub fn export(&self, format: ExportFormat) -> Result<String, String> {
        let term = self.fit.current.as_ref().ok_or(
            "no current term was found: nothing to export (the compensation would be zero)",
        )?;
        let a = self.calibration.as_ref().map_or(IDENTITY, |(_, a)| *a);
        current_export(format, term.coef_ut_per_a(), &a)
    }

    /// Writes the current term to the flight controller `spec` names ([`write_back_current`]), its previous values
    /// saved first to `undo`; an error when there is no term.
    pub fn write_back(&self, spec: &DeviceSpec, undo: &Path) -> anyhow::Result<Vec<String>> {
        let Some(term) = self.fit.current.as_ref() else {
            bail!(
                "not written to {spec}: no current term was found (the compensation would be zero)"
            );
        };
        let a = self.calibration.as_ref().map_or(IDENTITY, |(_, a)| *a);
        Ok(write_back_current(spec, term.coef_ut_per_a(), &a, undo)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hover_is_the_median_above_idle() {
        let currents = [1.0, 1.0, 1.1, 5.0, 9.0, 12.0, 30.0];
        assert_eq!(hover_current_a(&currents, (1.0, 30.0)), (9.0 + 12.0) / 2.0);
        assert_eq!(hover_current_a(&[2.0, 2.0], (2.0, 2.0)), 2.0);
    }

    #[test]
    fn estimates_carry_two_digits_of_their_error() {
        assert_eq!(with_se(0.123456, 0.0042), "+0.1235 ± 0.0042");
        assert_eq!(with_se(-1.0, 0.25), "-1.00 ± 0.25");
    }
}
