//! Flight logs in the fit workflow (`magcal-fit FLIGHT.ulg`, `FLIGHT.bin`): the log read into a recording
//! ([`magcal_flightlog`]), the magnetometer picked, what the log cannot determine said plainly instead of fitted,
//! and the reference given the heading of a fit to the field's magnitude and dip — the estimator's heading is partly
//! the compass's own ([`magcal_flightlog::heading`]).

use std::path::Path;

use anyhow::bail;
use magcal_flightlog::heading::{self, Deviation, MagnitudeDipFit, Rows};
use magcal_flightlog::{FlightLog, FlightRecording, Instance, LoggedCalibration};
use magcal_recording::{Date, Metadata, Recording};

use crate::field::{FieldArgs, FieldError, ReferenceField, resolve, wmm};
use crate::tellln;

/// What the user said about a flight log.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LogOptions {
    /// `--mag N`: the magnetometer, by its place in the list the tool prints (default: the one the autopilot used).
    pub mag: Option<usize>,
}

/// Least span of headings a level flight must cover for the offsets to be determined, degrees.
pub const MIN_HEADING_SPAN_DEG: f64 = 180.0;

/// A tilt from which on the headings' span does not matter: the vehicle was turned about more than the vertical
/// (a hand-held or tumbling log), degrees.
pub const TUMBLE_TILT_DEG: f64 = 45.0;

/// Whether `path` names a flight log magcal reads (`.ulg`, PX4; `.bin`, ArduPilot; whatever the case).
pub fn is_flight_log(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("ulg") || e.eq_ignore_ascii_case("bin"))
}

/// A flight log made ready for the fit.
#[derive(Debug)]
pub struct FlightInput {
    /// The recording, its quaternions re-headed ([`heading::rehead`]).
    pub rec: Recording,
    /// The world field.
    pub field: ReferenceField,
    /// The estimator's own attitude (sensor → NED), one per row, before the re-heading.
    pub estimator_quat: Vec<[f64; 4]>,
    /// The field with the logged calibration applied (sensor axes, µT), one per row, where the log has a slot.
    pub logged_ut: Option<Vec<[f64; 3]>>,
    /// The calibration the autopilot applied to this magnetometer, where the log has its slot.
    pub logged: Option<LoggedCalibration>,
    /// The fit to the magnitude and the dip that gave the reference its heading.
    pub heading_fit: MagnitudeDipFit,
    /// The estimator's heading error found against that fit, and whether it was taken out.
    pub deviation: Deviation,
}

/// The log's magnetometers in words, one line each, with their logged calibration.
pub fn describe(log: &FlightLog) -> Vec<String> {
    log.mags
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let t = &m.field_g.t_us;
            let span_s = (t[t.len() - 1] - t[0]) as f64 * 1e-6;
            let rate = if span_s > 0.0 {
                (t.len() - 1) as f64 / span_s
            } else {
                0.0
            };
            let cal = m
                .calibration
                .as_ref()
                .map_or("no CAL_MAGn slot for it".to_owned(), |c| c.describe());
            let kind = if m.calibrated {
                "calibrated, body axes"
            } else {
                "raw"
            };
            format!(
                "magnetometer {i}: {} ({kind}), {} samples at {rate:.1} Hz; logged {cal}",
                m.name(),
                t.len()
            )
        })
        .collect()
}

/// The field for a flight log: the command line's, else the World Magnetic Model at the first GPS fix. A log older
/// (or newer) than the model's years takes the model at its nearest day, and says so.
fn field_for(args: &FieldArgs, meta: &Metadata) -> anyhow::Result<ReferenceField> {
    match resolve(args, meta) {
        Err(FieldError::Wmm { .. }) if args == &FieldArgs::default() => {
            let (Some(loc), Some(date)) = (&meta.location, &meta.date) else {
                bail!("no field");
            };
            let nearest: Date = if date.year < 2025 {
                "2025-01-01"
            } else {
                "2029-12-31"
            }
            .parse()?;
            let via = format!(
                "the log's first GPS fix; the log's date {date} is outside the model's years, so its field on \
                 {nearest} is used (the field drifts by about 0.1 µT a year)"
            );
            Ok(wmm(loc, &nearest, &via)?)
        }
        other => Ok(other?),
    }
}

/// What the flight cannot determine, in words: the field without a GPS fix, the offsets without enough turning.
fn undeterminable(
    file: &str,
    log: &FlightLog,
    fr: &FlightRecording,
    field: &ReferenceField,
) -> Option<String> {
    let mut why = Vec::new();
    if field.vector().is_none() {
        let fixes = log.gps.len();
        why.push(format!(
            "the World Magnetic Model cannot be evaluated: the log has no GPS fix ({fixes} GPS samples, none with a \
             3-D fix and a position), so the field's magnitude and dip — what a flight log's compass is checked \
             against — are unknown; give the place and day (--location LAT,LON,ALT --date YYYY-MM-DD) or the field \
             (--field-ned N,E,D)"
        ));
    }
    let quat = fr.rec.quat.as_deref().unwrap_or(&[]);
    let (span, tilt) = heading::turned(quat);
    if span < MIN_HEADING_SPAN_DEG && tilt < TUMBLE_TILT_DEG {
        why.push(format!(
            "the offsets (hard iron) and scales cannot be determined: the heading spans only {span:.0}° (tilt up to \
             {tilt:.0}°) over {} samples; a calibration needs the vehicle turned through all headings — fly a few \
             slow full turns (or turn it by hand through 360° of yaw and ±45° of tilt) and log again",
            fr.rec.len()
        ));
    }
    (!why.is_empty()).then(|| {
        format!(
            "{file}: cannot calibrate from this log: {}",
            why.join("; and ")
        )
    })
}

/// Reads a flight log for the fit: the magnetometer `options` pick (telling the user which, and the others), the
/// field, the checks of what the log can determine, the reference re-headed by a fit to magnitude and dip.
pub fn read_flight(
    path: &Path,
    options: &LogOptions,
    args: &FieldArgs,
) -> anyhow::Result<FlightInput> {
    let file = path.display().to_string();
    let log = magcal_flightlog::read(path)?;
    for line in describe(&log) {
        tellln!("{file}: {line}");
    }
    for note in &log.notes {
        tellln!("{file}: NOTE: {note}");
    }
    let fr = log.recording(options.mag.map(Instance))?;
    let which = if options.mag.is_some() {
        "as asked"
    } else {
        "the one the autopilot used; --mag N picks another"
    };
    tellln!("{file}: fitting {} ({which})", fr.mag);
    let field = field_for(args, &fr.rec.meta)?;
    if let Some(why) = undeterminable(&file, &log, &fr, &field) {
        bail!(why);
    }
    let field_ned = field.vector().expect("checked by undeterminable");
    let FlightRecording {
        mut rec, logged_ut, ..
    } = fr;
    let estimator_quat = rec.quat.clone().unwrap_or_default();
    let logged = log.mags[log_index(&log, options)].calibration.clone();
    let (heading_fit, deviation) =
        give_heading(&mut rec, field_ned, logged.as_ref()).ok_or_else(|| {
            anyhow::anyhow!(
                "{file}: the fit to the field's magnitude and dip failed: too few samples"
            )
        })?;
    let verdict = heading_verdict(&deviation);
    tellln!(
        "{file}: reference: the estimator's attitude checked against a fit to the World Magnetic Model's magnitude \
         and dip (|B| RMS {:.2} µT, down component RMS {:.2} µT), its heading being partly this compass's own: \
         {verdict}",
        heading_fit.magnitude_rms_ut,
        heading_fit.down_rms_ut
    );
    rec.meta
        .other
        .push(("reference_heading".to_owned(), verdict));
    Ok(FlightInput {
        rec,
        field,
        estimator_quat,
        logged_ut,
        logged,
        heading_fit,
        deviation,
    })
}

/// The estimator's heading in words: kept, or corrected by its deviation curve.
fn heading_verdict(d: &Deviation) -> String {
    if d.applied {
        format!(
            "its heading was off by up to {:.1}° as a compass deviation curve (χ² {:.0}), and is corrected",
            d.max_deg, d.chi2
        )
    } else {
        format!(
            "its heading agrees (a deviation curve of up to {:.1}°, χ² {:.1}, is within chance), and is kept",
            d.max_deg, d.chi2
        )
    }
}

/// The index of the magnetometer `options` pick.
fn log_index(log: &FlightLog, options: &LogOptions) -> usize {
    options.mag.or_else(|| log.default_instance()).unwrap_or(0)
}

/// Fits the magnitude and the dip of `field_ned` (µT), starting from the `logged` calibration (or a sphere about the
/// readings' mean), and takes the estimator's heading error against it out of the recording's quaternions where
/// there is one ([`heading::rehead`]); `None` if a fit fails.
pub fn give_heading(
    rec: &mut Recording,
    field_ned: [f64; 3],
    logged: Option<&LoggedCalibration>,
) -> Option<(MagnitudeDipFit, Deviation)> {
    let quat = rec.quat.as_mut()?;
    let down: Vec<[f64; 3]> = quat.iter().map(|q| heading::down_in_sensor(*q)).collect();
    let currents: Vec<Vec<f64>> = (0..rec.mag_ut.len())
        .map(|i| rec.currents.iter().map(|c| c.values[i]).collect())
        .collect();
    let start = match logged {
        Some(c) => {
            let b = magcal_calib::frames::mat_vec(&c.scale, c.offset_g);
            (c.scale, b.map(|v| -100.0 * v))
        }
        None => {
            let n = rec.mag_ut.len() as f64;
            let mean: [f64; 3] =
                std::array::from_fn(|k| rec.mag_ut.iter().map(|m| m[k]).sum::<f64>() / n);
            (magcal_calib::frames::IDENTITY, mean.map(|v| -v))
        }
    };
    let rows = Rows {
        raw_ut: &rec.mag_ut,
        down: &down,
        currents_a: &currents,
    };
    let fit = heading::fit_magnitude_dip(&rows, field_ned, start)?;
    let fields: Vec<[f64; 3]> = (0..rec.mag_ut.len())
        .map(|i| fit.field_ut(rec.mag_ut[i], &currents[i]))
        .collect();
    let t_s = rec.t_s.as_deref()?;
    let rate = heading::angular_rate_ned(quat, t_s);
    let deviation = heading::rehead(quat, &fields, field_ned, &rate)?;
    Some((fit, deviation))
}
