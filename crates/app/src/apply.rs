//! Applying a parameters file to a recording (`magcal-apply`): the calibrated readings, and how well the parameters
//! fit this recording — the check of a calibration on a second recording.
//!
//! The residual is measured against what the recording offers: the expected field per sample (an attitude
//! reference plus the world field, or `rx,ry,rz`), or else the field magnitude. With an attitude reference the
//! heading error is also *measured*, sample by sample, as a tilt-compensated compass with a perfect attitude would
//! see it. The heading figures over 360 level headings and the verdict follow [`crate::heading`] and
//! [`crate::verdict`], with this recording's residual and noise (the parameters' own uncertainty is not in a
//! parameters file, so it is not included).

use magcal_calib::coverage::Coverage;
use magcal_calib::diagnosis::{self, DiagnosisInput, Disturbed, Glitch, GrossSpan, Reference};
use magcal_calib::effects::Need;
use magcal_calib::noise::{self, NoiseFloor};
use magcal_calib::{Model, frames};
use magcal_recording::Recording;

use crate::field::ReferenceField;
use crate::heading::{HeadingErrors, HeadingInput, LocalField, heading_errors};
use crate::params::ParamsFile;
use crate::readings::{calibrate_rows, expected_field, noise_measurable};
use crate::verdict::{Grade, Hints, Verdict, fmt_deg, judge, judge_without_direction};

/// What the residual is measured against.
#[derive(Clone, Debug, PartialEq)]
pub enum Against {
    /// The expected field per sample: residual per axis.
    Vector,
    /// The field magnitude: residual of |B|.
    Magnitude {
        /// The magnitude, µT.
        field_ut: f64,
        /// Whether it was known (otherwise the mean calibrated magnitude of this recording).
        known: bool,
    },
}

/// The heading error measured sample by sample against the attitude reference, degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredHeading {
    /// RMS over the samples, raw readings used as if calibrated.
    pub raw_rms_deg: f64,
    /// RMS over the samples, calibrated.
    pub rms_deg: f64,
    /// 95 % of the calibrated samples are within this, degrees.
    pub p95_deg: f64,
}

/// A parameters file applied to a recording.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// The calibrated field per row, µT (NaN where a channel a correction needs is missing).
    pub calibrated_ut: Vec<[f64; 3]>,
    /// What the residual is measured against.
    pub against: Against,
    /// Rows measured.
    pub samples_used: usize,
    /// Residual RMS of the calibrated readings, µT (per axis, or of |B|).
    pub residual_rms_ut: f64,
    /// The same for the raw readings used as if calibrated, µT.
    pub raw_residual_rms_ut: f64,
    /// The recording's noise floor in calibrated units, µT.
    pub noise_floor_ut: f64,
    /// Measured against the attitude reference, when there is one.
    pub measured: Option<MeasuredHeading>,
    /// Over 360 level headings, when the field's direction is known.
    pub heading: Option<HeadingErrors>,
    /// What the check can resolve of the heading error left.
    pub resolution: Resolution,
    /// The verdict.
    pub verdict: Verdict,
    /// What the user must not miss: the parameters may not hold here for a reason the figures do not show.
    pub warnings: Vec<String>,
    /// The spans the parameters leave grossly off, left out of the figures.
    pub disturbed: Vec<GrossSpan>,
    /// The glitches also left out (spans too short to be a field, or within what the noise makes by chance).
    pub glitches: Vec<Glitch>,
    /// Rows in the spans and glitches.
    pub samples_left_out: usize,
}

/// What a check can resolve of the heading error left: a finite recording measures its residual's mean square only to
/// a standard error (batch means over blocks of time, [`Misfit::mean_square_se_ut2`]; and the noise floor's own, from
/// its differences), so the residual beyond the noise is known only to that.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Resolution {
    /// The standard error of the heading error left (any heading: the check has no parameter uncertainty), degrees.
    pub se_deg: f64,
    /// The residual beyond the noise is within two standard errors of none: the figures left are then an upper
    /// bound (what the check can resolve), not an estimate.
    pub bound: bool,
}

/// Why a parameters file cannot be applied to a recording.
#[derive(Debug, thiserror::Error)]
pub enum ApplyError {
    /// The model needs a channel the recording lacks.
    #[error("the parameters need {0}, which this recording does not have")]
    MissingChannel(String),
}

/// The model of `params` for `rec`'s channels.
pub fn model_for(params: &ParamsFile, rec: &Recording) -> Result<Model, ApplyError> {
    let channels: Vec<String> = rec.currents.iter().map(|c| c.name.clone()).collect();
    let model = params
        .model(&channels)
        .map_err(ApplyError::MissingChannel)?;
    let needs_temp = model
        .corrections()
        .any(|e| e.id().descriptor().needs.contains(&Need::Temperature));
    if needs_temp && rec.temp_c.is_none() {
        return Err(ApplyError::MissingChannel(
            "a temperature column (temp) for their temperature correction".to_owned(),
        ));
    }
    Ok(model)
}

fn rms(sum_sq: f64, n: usize) -> f64 {
    (sum_sq / n.max(1) as f64).sqrt()
}

/// The angle of a NED vector's horizontal part east of north, radians.
fn azimuth(v: [f64; 3]) -> f64 {
    v[1].atan2(v[0])
}

fn wrap_deg(x: f64) -> f64 {
    (x + 180.0).rem_euclid(360.0) - 180.0
}

/// How far calibrated readings are from a recording's reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Misfit {
    /// What the residual is measured against.
    pub against: Against,
    /// Residual RMS of the calibrated readings, µT (per axis, or of |B|).
    pub residual_rms_ut: f64,
    /// The same for the raw readings used as if calibrated, µT.
    pub raw_residual_rms_ut: f64,
    /// Rows measured.
    pub samples_used: usize,
    /// The standard error of the calibrated residual's mean square, µT², by batch means over [`CHECK_BLOCKS`] blocks
    /// of time (so that residuals correlated over seconds, as a reference's errors are, count for what they are).
    pub mean_square_se_ut2: f64,
}

/// Blocks of time the standard error of a check's mean square residual is taken over (batch means).
pub const CHECK_BLOCKS: usize = 20;

/// The standard error of the mean of `v` (in order) by batch means: the spread of the means of up to
/// [`CHECK_BLOCKS`] consecutive blocks of at least 10 values, over the square root of their number; infinite for
/// fewer than two blocks.
pub fn batch_mean_se(v: &[f64]) -> f64 {
    let blocks = (v.len() / 10).min(CHECK_BLOCKS);
    if blocks < 2 {
        return f64::INFINITY;
    }
    let means: Vec<f64> = (0..blocks)
        .map(|b| {
            let block = &v[b * v.len() / blocks..(b + 1) * v.len() / blocks];
            block.iter().sum::<f64>() / block.len() as f64
        })
        .collect();
    let mean = means.iter().sum::<f64>() / blocks as f64;
    let var = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (blocks - 1) as f64;
    (var / blocks as f64).sqrt()
}

/// The misfit of `calibrated_ut` (one per row of `rec`; non-finite rows and those `left_out` are left out) against
/// the expected field per row when given, otherwise against the magnitude `field_ut` (or, without it, the mean
/// calibrated magnitude).
pub fn misfit(
    calibrated_ut: &[[f64; 3]],
    rec: &Recording,
    expected: Option<&[[f64; 3]]>,
    field_ut: Option<f64>,
    left_out: Option<&[bool]>,
) -> Misfit {
    let ok =
        |i: usize| calibrated_ut[i].iter().all(|v| v.is_finite()) && left_out.is_none_or(|l| !l[i]);
    match expected {
        Some(e) => {
            let rows: Vec<usize> = (0..rec.len())
                .filter(|&i| ok(i) && e[i].iter().all(|v| v.is_finite()))
                .collect();
            let ss = |x: &dyn Fn(usize) -> [f64; 3]| {
                rows.iter()
                    .map(|&i| {
                        let d = frames::sub(x(i), e[i]);
                        frames::dot(d, d)
                    })
                    .sum::<f64>()
            };
            // Per row, the mean square over the axes, in time order.
            let squares: Vec<f64> = rows
                .iter()
                .map(|&i| {
                    let d = frames::sub(calibrated_ut[i], e[i]);
                    frames::dot(d, d) / 3.0
                })
                .collect();
            Misfit {
                against: Against::Vector,
                residual_rms_ut: rms(ss(&|i| calibrated_ut[i]), 3 * rows.len()),
                raw_residual_rms_ut: rms(ss(&|i| rec.mag_ut[i]), 3 * rows.len()),
                samples_used: rows.len(),
                mean_square_se_ut2: batch_mean_se(&squares),
            }
        }
        None => {
            let rows: Vec<usize> = (0..rec.len()).filter(|&i| ok(i)).collect();
            let norms: Vec<f64> = rows
                .iter()
                .map(|&i| frames::norm(calibrated_ut[i]))
                .collect();
            let (field_ut, known) = match field_ut {
                Some(f) => (f, true),
                None => (norms.iter().sum::<f64>() / norms.len().max(1) as f64, false),
            };
            let raw_ss: f64 = rows
                .iter()
                .map(|&i| (frames::norm(rec.mag_ut[i]) - field_ut).powi(2))
                .sum();
            let squares: Vec<f64> = norms.iter().map(|n| (n - field_ut).powi(2)).collect();
            Misfit {
                against: Against::Magnitude { field_ut, known },
                residual_rms_ut: rms(squares.iter().sum(), rows.len()),
                raw_residual_rms_ut: rms(raw_ss, rows.len()),
                samples_used: rows.len(),
                mean_square_se_ut2: batch_mean_se(&squares),
            }
        }
    }
}

/// Applies `params` to `rec` and measures the fit; `field` is the world field (from the command line or the
/// recording's metadata); `fitted_on_it`: `rec` is the recording the parameters were fitted on (corrections tied to
/// its clock hold there). The spans the parameters leave grossly off (a magnet on the board or near the bench) are
/// located and left out of the figures, as a fit leaves them out ([`magcal_calib::diagnosis::disturbed`]).
pub fn check(
    params: &ParamsFile,
    rec: &Recording,
    field: &ReferenceField,
    fitted_on_it: bool,
) -> Result<Check, ApplyError> {
    let model = model_for(params, rec)?;
    let calibrated_ut = calibrate_rows(&model, rec);
    let expected = expected_field(rec, field).ok();
    let noise = noise::estimate(&rec.mag_ut, expected.as_deref());
    let disturbed = disturbed_spans(rec, field, &calibrated_ut, &model, noise);
    let left_out = disturbed.as_ref().map(|d| d.left_out.as_slice());
    let misfit = misfit(
        &calibrated_ut,
        rec,
        expected.as_deref(),
        field.magnitude(),
        left_out,
    );
    let noise_floor_ut = noise.calibrated_rms_ut(&model.a);
    // Differences above the residual measure the rotation, not the noise: it then explains none of the residual.
    let noise_unmeasured = !noise_measurable(noise_floor_ut, misfit.residual_rms_ut);
    let noise_floor_ut = if noise_unmeasured {
        0.0
    } else {
        noise_floor_ut
    };
    let measured = match (&rec.quat, field.vector()) {
        (Some(q), Some(f)) => measured_heading(q, f, &rec.mag_ut, &calibrated_ut, left_out),
        _ => None,
    };
    let magnitude_ut = match &misfit.against {
        Against::Magnitude { field_ut, .. } => *field_ut,
        Against::Vector => field
            .magnitude()
            .unwrap_or_else(|| mean_magnitude(expected.as_deref().unwrap_or_default())),
    };
    let (heading, verdict, resolution) = graded(
        &model,
        &misfit,
        field,
        magnitude_ut,
        (noise_floor_ut, noise_unmeasured),
    );
    let (spans, glitches, samples_left_out) = disturbed.map_or((Vec::new(), Vec::new(), 0), |d| {
        let n = d.rows_left_out();
        (d.spans, d.glitches, n)
    });
    let mut warnings = apply_warnings(params, &misfit.against, fitted_on_it);
    warnings.extend(left_out_warning(samples_left_out, rec.len(), spans.len()));
    let verdict = overruled(verdict, &misfit, &calibrated_ut, rec, &warnings);
    Ok(Check {
        calibrated_ut,
        against: misfit.against,
        samples_used: misfit.samples_used,
        residual_rms_ut: misfit.residual_rms_ut,
        raw_residual_rms_ut: misfit.raw_residual_rms_ut,
        noise_floor_ut,
        measured,
        heading,
        resolution,
        verdict,
        warnings,
        disturbed: spans,
        glitches,
        samples_left_out,
    })
}

/// The spans the model leaves grossly off in `rec` (the calibrated readings `calibrated_ut`), against the expected
/// field per row when the recording gives it, else the field's magnitude (given, or the calibrated readings' median
/// magnitude); `None` when the recording is too short to tell.
fn disturbed_spans(
    rec: &Recording,
    field: &ReferenceField,
    calibrated_ut: &[[f64; 3]],
    model: &Model,
    noise: NoiseFloor,
) -> Option<Disturbed> {
    let reference = match (&rec.ref_ut, &rec.quat, field.vector()) {
        (Some(r), _, _) => Reference::Field { expected_ut: r },
        (None, Some(q), Some(f)) => Reference::Attitude {
            quat: q,
            field_ned_ut: f,
        },
        _ => Reference::Magnitude {
            field_ut: field.magnitude().unwrap_or_else(|| {
                let mut norms: Vec<f64> = calibrated_ut
                    .iter()
                    .map(|m| frames::norm(*m))
                    .filter(|n| n.is_finite())
                    .collect();
                crate::checks::median(&mut norms)
            }),
        },
    };
    let input = DiagnosisInput {
        raw_ut: &rec.mag_ut,
        t_s: rec.t_s.as_deref(),
        temp_c: rec.temp_c.as_deref(),
        currents: rec
            .currents
            .iter()
            .map(|c| (c.name.as_str(), c.values.as_slice()))
            .collect(),
        reference,
        noise,
        kept: None,
        scale_ut: f64::NAN,
    };
    diagnosis::disturbed(&input, model).ok()
}

/// The mean magnitude of the finite vectors among `v`, µT.
fn mean_magnitude(v: &[[f64; 3]]) -> f64 {
    let n: Vec<f64> = v
        .iter()
        .map(|v| frames::norm(*v))
        .filter(|n| n.is_finite())
        .collect();
    n.iter().sum::<f64>() / n.len().max(1) as f64
}

/// The residual the heading figures are made with, and what the check resolves: `r` as measured when the part beyond
/// the noise (`u² = r² − f²`) stands two standard errors clear of none, else the residual of the upper bound
/// `u² + 2·se` ([`Resolution`]). The standard error of `u²` combines the batch means' of `r²` and the noise floor's
/// (`f²·√(2/N)`, its differences being nearly independent); `horizontal_ut` turns it into degrees.
fn resolved_residual(
    misfit: &Misfit,
    noise_floor_ut: f64,
    horizontal_ut: f64,
) -> (f64, Resolution) {
    let (r, f) = (misfit.residual_rms_ut, noise_floor_ut);
    let u2 = r * r - f * f;
    let se_f2 = f * f * (2.0 / misfit.samples_used.max(1) as f64).sqrt();
    let se_u2 = misfit.mean_square_se_ut2.hypot(se_f2);
    let deg = |ut: f64| (ut / horizontal_ut).to_degrees();
    if u2 > 2.0 * se_u2 {
        let u = u2.sqrt();
        (
            r,
            Resolution {
                se_deg: deg(se_u2 / (2.0 * u)),
                bound: false,
            },
        )
    } else {
        let bound2 = u2.max(0.0) + 2.0 * se_u2;
        (
            (f * f + bound2).sqrt(),
            Resolution {
                se_deg: deg(se_u2.sqrt()),
                bound: true,
            },
        )
    }
}

/// The heading figures of `model` on the recording (when the field's direction is known), the verdict they give and
/// what the check resolves, with the misfit measured and the noise floor (`noise_floor_ut`, zero when not measured,
/// and whether it was not). Figures the check cannot resolve are upper bounds, said in the verdict.
fn graded(
    model: &Model,
    misfit: &Misfit,
    field: &ReferenceField,
    magnitude_ut: f64,
    (noise_floor_ut, noise_unmeasured): (f64, bool),
) -> (Option<HeadingErrors>, Verdict, Resolution) {
    let inclination_deg = field.vector().map_or(0.0, |f| frames::field_angles(f).1);
    let local = LocalField::new(inclination_deg, magnitude_ut);
    let (residual_rms_ut, resolution) =
        resolved_residual(misfit, noise_floor_ut, local.horizontal_ut);
    let input = HeadingInput {
        a: model.a,
        b_ut: model.b_ut,
        field: local,
        uncertainty: None,
        residual_rms_ut,
        noise_floor_ut,
    };
    let hints = Hints {
        vector: misfit.against == Against::Vector,
        spans_s: Vec::new(),
        coverage: 1.0,
        diagnosis_skipped: false,
        noise_unmeasured,
        declination_off_deg: None,
        excluded: (0, 0),
    };
    let h = heading_errors(&input);
    match field.vector() {
        Some(_) => {
            let mut v = judge(&h, &hints);
            if resolution.bound {
                v.reason = format!(
                    "at most {}; this check resolves no less (its standard error is ±{})",
                    v.reason,
                    fmt_deg(resolution.se_deg)
                );
            }
            (Some(h), v, resolution)
        }
        None => (
            None,
            judge_without_direction(h.left.worst_deg, &hints),
            resolution,
        ),
    }
}

/// The verdict the heading figures gave, overruled where they do not tell the story: parameters that fit worse than
/// none, a calibrated field far outside the Earth's, readings that hardly turn, `warnings` on a good check.
fn overruled(
    mut verdict: Verdict,
    misfit: &Misfit,
    calibrated_ut: &[[f64; 3]],
    rec: &Recording,
    warnings: &[String],
) -> Verdict {
    let (residual_rms_ut, raw_residual_rms_ut) =
        (misfit.residual_rms_ut, misfit.raw_residual_rms_ut);
    // Parameters that leave more misfit than none at all are another sensor's (or another state's).
    if verdict.grade != Grade::Good && residual_rms_ut > raw_residual_rms_ut {
        verdict.todo = format!(
            "these parameters fit this recording worse than its raw readings do ({residual_rms_ut:.2} against \
             {raw_residual_rms_ut:.2} µT): they are not this sensor's, or its mounting or surroundings changed — fit \
             this recording with magcal-fit instead"
        );
    }
    // A calibrated field far outside the Earth's range is no calibration of these readings, however round it is.
    let (low, high) = crate::checks::EARTH_FIELD_UT;
    if let Against::Magnitude { field_ut, .. } = misfit.against
        && !(0.5 * low..=1.5 * high).contains(&field_ut)
    {
        verdict = Verdict {
            grade: Grade::Redo,
            reason: format!(
                "the calibrated field is {field_ut:.1} µT, far outside the Earth's {low:.0}–{high:.0} µT"
            ),
            todo:
                "use parameters fitted on this sensor, in the recording's units (the WARNING below)"
                    .to_owned(),
        };
    }
    if let Some(flat) = hardly_turns(calibrated_ut, &rec.mag_ut) {
        verdict = flat;
    }
    if verdict.grade == Grade::Good && !warnings.is_empty() {
        verdict = Verdict {
            grade: Grade::Usable,
            reason: format!(
                "{}, but {} warning(s) below",
                verdict.reason,
                warnings.len()
            ),
            todo: "read the WARNING below: it says what the figures do not show".to_owned(),
        };
    }
    if verdict.grade == Grade::Good {
        "use them: they hold on this recording too".clone_into(&mut verdict.todo);
    }
    verdict
}

/// From this share of a recording's rows in disturbed spans, the check leaves out enough to say so in a warning.
pub const LEFT_OUT_WARNED: f64 = 0.1;

/// A warning when the disturbed spans left out of the check hold [`LEFT_OUT_WARNED`] of the `rows` or more.
fn left_out_warning(left_out: usize, rows: usize, spans: usize) -> Option<String> {
    let share = left_out as f64 / rows.max(1) as f64;
    (share >= LEFT_OUT_WARNED).then(|| {
        format!(
            "{left_out} samples ({:.0} % of the recording) in {spans} disturbed span(s), listed below, were left out \
             of the check: the parameters were judged on the rest. Check them again on a recording made away from \
             magnets and metal to judge them on all of it",
            100.0 * share
        )
    })
}

/// A calibrated field that varies by less than this share of its magnitude hardly turned: its magnitude says nothing
/// of `A` (a sensor turned level through a few headings varies by a third of it).
const STILL_SHARE: f64 = 0.05;
/// Raw readings that vary by more than this share of their mean magnitude turned.
const TURNED_SHARE: f64 = 0.2;

/// The verdict when the calibrated readings hardly turn ([`STILL_SHARE`]): a constant vector fits any magnitude, so
/// the recording checks nothing — the sensor did not turn, or the parameters flatten readings that did (another
/// sensor's, or fitted in other units).
fn hardly_turns(calibrated_ut: &[[f64; 3]], raw: &[[f64; 3]]) -> Option<Verdict> {
    let finite = |v: &&[f64; 3]| v.iter().all(|x| x.is_finite());
    let spread_and_size = |rows: &[[f64; 3]]| {
        let rows: Vec<[f64; 3]> = rows.iter().filter(finite).copied().collect();
        let size = rows.iter().map(|v| frames::norm(*v)).sum::<f64>() / rows.len().max(1) as f64;
        (Coverage::of(&rows).spread_ut[0], size)
    };
    let (spread_ut, size_ut) = spread_and_size(calibrated_ut);
    if spread_ut.is_nan() || spread_ut >= STILL_SHARE * size_ut {
        return None;
    }
    let (raw_spread, raw_size) = spread_and_size(raw);
    let (reason, todo) = if raw_spread > TURNED_SHARE * raw_size {
        (
            format!(
                "the calibrated field hardly turns ({spread_ut:.2} µT of spread against {size_ut:.1} µT) where the \
                 raw readings do ({raw_spread:.3} against {raw_size:.3}): the parameters flatten the readings"
            ),
            "use parameters fitted on this sensor, in the recording's units".to_owned(),
        )
    } else {
        (
            format!(
                "the calibrated field hardly turns ({spread_ut:.2} µT of spread against {size_ut:.1} µT): the sensor \
                 was not turned, so the recording cannot check the parameters"
            ),
            "record again turning the sensor through many directions".to_owned(),
        )
    };
    Some(Verdict {
        grade: Grade::Redo,
        reason,
        todo,
    })
}

/// What applying `params` to another recording may get wrong that its figures do not show: corrections tied to the
/// clock of the recording they were fitted on (unless `fitted_on_it`), and a calibrated field outside the Earth's
/// range when no field was given to check against.
fn apply_warnings(params: &ParamsFile, against: &Against, fitted_on_it: bool) -> Vec<String> {
    let mut warnings = Vec::new();
    let timed: Vec<&str> = params
        .corrections
        .iter()
        .filter(|c| c.id.descriptor().needs.contains(&Need::Time))
        .map(|c| c.id.as_str())
        .collect();
    if !timed.is_empty() && !fitted_on_it {
        warnings.push(format!(
            "the parameters hold {} tied to the clock of the recording they were fitted on{}: here {} applied at this \
             recording's own times, which means something only for that recording. For others, use A and b fitted \
             without it (magcal-fit --no-diagnose)",
            timed.join(" and "),
            params
                .recording
                .as_ref()
                .map_or(String::new(), |r| format!(" ({r})")),
            if timed.len() == 1 { "it is" } else { "they are" }
        ));
    }
    let (low, high) = crate::checks::EARTH_FIELD_UT;
    if let Against::Magnitude {
        field_ut,
        known: false,
    } = against
        && !(low..=high).contains(field_ut)
    {
        warnings.push(format!(
            "the calibrated field is {field_ut:.1} µT on this recording, outside the Earth's {low:.0}–{high:.0} µT: \
             the parameters' gain does not fit these readings (another sensor, range or unit), or the place is \
             strongly disturbed. Give the field (--field-ut, --field-ned or --location/--date) to check against it"
        ));
    }
    warnings
}

/// The heading error per sample with the attitude (but those `left_out`): the azimuth of the reading turned into
/// NED minus the field's.
fn measured_heading(
    quat: &[[f64; 4]],
    field_ned_ut: [f64; 3],
    raw_ut: &[[f64; 3]],
    calibrated_ut: &[[f64; 3]],
    left_out: Option<&[bool]>,
) -> Option<MeasuredHeading> {
    let north = azimuth(field_ned_ut);
    let mut raw_errors = Vec::new();
    let mut errors = Vec::new();
    for (i, ((q, raw), cal)) in quat.iter().zip(raw_ut).zip(calibrated_ut).enumerate() {
        if !(q.iter().all(|v| v.is_finite()) && cal.iter().all(|v| v.is_finite()))
            || left_out.is_some_and(|l| l[i])
        {
            continue;
        }
        let r = frames::quat_to_matrix(*q);
        let err = |m: [f64; 3]| -wrap_deg((azimuth(frames::mat_vec(&r, m)) - north).to_degrees());
        raw_errors.push(err(*raw));
        errors.push(err(*cal));
    }
    if errors.is_empty() {
        return None;
    }
    let rms_deg = |e: &[f64]| rms(e.iter().map(|x| x * x).sum(), e.len());
    let mut abs: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let p95_deg = abs[((abs.len() as f64 * 0.95).ceil() as usize).clamp(1, abs.len()) - 1];
    Some(MeasuredHeading {
        raw_rms_deg: rms_deg(&raw_errors),
        rms_deg: rms_deg(&errors),
        p95_deg,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use magcal_sim::{ChipModel, Scenario, SensorTruth, Trajectory, simulate};

    /// Parameters fitted on one simulated recording of a sensor fit a second recording of the same sensor (another
    /// seed for the motion and the noise): the residual is at the noise floor and the heading error measured with
    /// the attitude is small; the same parameters on another sensor do not fit.
    #[test]
    fn the_true_parameters_fit_a_second_recording_and_not_another_sensor() {
        let chip = ChipModel::by_name("lis3mdl").unwrap();
        let truth = SensorTruth::mounted(
            [[1.08, 0.03, -0.01], [0.02, 0.95, 0.04], [-0.03, 0.01, 1.12]],
            [12.0, -30.0, 8.0],
            [0.02, -0.03, 0.01],
        );
        let record = |seed: u64, sensor: SensorTruth| {
            let mut s = Scenario::new(
                &chip,
                Trajectory::Tumble {
                    duration_s: 30.0,
                    rate_rad_s: 1.0,
                },
                seed,
            );
            s.sensor = sensor;
            simulate(&s).unwrap().recording
        };
        let params = ParamsFile::new("vector", &Model::linear(truth.a, truth.b_ut), &[]);
        let second = record(8, truth);
        let field = ReferenceField::Vector {
            field_ned_ut: second.meta.field_ned_ut.unwrap(),
            source: "test".into(),
        };
        let c = check(&params, &second, &field, false).unwrap();
        assert_eq!(c.against, Against::Vector);
        assert!(
            (c.residual_rms_ut / c.noise_floor_ut - 1.0).abs() < 0.1,
            "{} vs {}",
            c.residual_rms_ut,
            c.noise_floor_ut
        );
        // With the true parameters, what is measured sample by sample is the noise.
        let m = c.measured.unwrap();
        let noise_deg = c.heading.as_ref().unwrap().noise_deg;
        assert!(
            (m.rms_deg / noise_deg - 1.0).abs() < 0.3 && m.raw_rms_deg > 10.0,
            "{m:?} against one reading's noise {noise_deg}°"
        );
        assert_eq!(c.verdict.grade, Grade::Good, "{:?}", c.verdict);

        let other = record(
            9,
            SensorTruth::mounted(truth.a, [-20.0, 10.0, 5.0], [0.0; 3]),
        );
        let c = check(&params, &other, &field, false).unwrap();
        assert!(c.residual_rms_ut > 10.0 * c.noise_floor_ut, "{c:?}");
        assert_eq!(c.verdict.grade, Grade::Redo);

        // Parameters fitted in nT (gains of 0.001) map these readings to about b, a constant vector: its magnitude is
        // the recording's own mean, checked against no field (it was graded usable).
        let flat = ParamsFile::new(
            "vector",
            &Model::linear(
                [[1e-3, 0.0, 0.0], [0.0, 1e-3, 0.0], [0.0, 0.0, 1e-3]],
                [-4.4, 29.3, 24.7],
            ),
            &[],
        );
        let c = check(&flat, &second, &ReferenceField::Unknown, false).unwrap();
        assert_eq!(c.verdict.grade, Grade::Redo, "{:?}", c.verdict);
        assert!(c.verdict.reason.contains("flatten"), "{:?}", c.verdict);
    }

    /// A sensor that was not turned checks nothing of `A`: any parameters fit its constant magnitude.
    #[test]
    fn a_recording_that_did_not_turn_cannot_check_parameters() {
        let chip = ChipModel::by_name("lis3mdl").unwrap();
        let mut s = Scenario::new(
            &chip,
            Trajectory::Tumble {
                duration_s: 30.0,
                rate_rad_s: 0.0,
            },
            3,
        );
        s.sensor = SensorTruth::mounted(
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [5.0; 3],
            [0.0; 3],
        );
        let still = simulate(&s).unwrap().recording;
        let params = ParamsFile::new("vector", &Model::linear(s.sensor.a, s.sensor.b_ut), &[]);
        let c = check(&params, &still, &ReferenceField::Unknown, false).unwrap();
        assert_eq!(c.verdict.grade, Grade::Redo, "{:?}", c.verdict);
        assert!(c.verdict.reason.contains("not turned"), "{:?}", c.verdict);
    }
}
