//! From a recording to a fitted calibration: pick the method, build the expected field, check, fit, measure.

use magcal_calib::convention;
use magcal_calib::diagnosis::{self, Diagnosis, DiagnosisInput, Reference};
use magcal_calib::directions::fraction_of;
use magcal_calib::fit::Halves;
use magcal_calib::frames;
use magcal_calib::noise::{self, NoiseFloor, rms3};
use std::borrow::Cow;

use magcal_calib::coverage::CoverageError;
use magcal_calib::faults;
use magcal_calib::robust;
use magcal_calib::scalar::{self, ScalarProblem};
use magcal_calib::vector::{VectorFit, VectorProblem};
use magcal_calib::{Effect, FitError, Frame, Model};
use magcal_recording::{AttitudeToReference, Metadata, ReadOptions, Recording};
use std::path::Path;

use crate::checks;
use crate::field::ReferenceField;
use crate::fit::{
    Calibration, Fit, Method, ReferenceDoubt, ReferenceHeading, RobustSummary, SampleCounts,
    UndeterminedPart,
};
use crate::readings::{
    MissingReference, calibrate_row, expected_field, noise_measurable, noise_source,
    radial_floor_ut,
};
use crate::reference_heading::{self, Search};
use crate::units::{ChipOption, Units};

/// The attitude in the conventions loggers also use (the inverse turn, the scalar last, ENU or NWU worlds), then,
/// if the fit `looks_off`, the reference `expected_ut` shifted in time; each fitted from the samples the robust fit
/// `kept`.
fn reference_out_of_convention(
    rec: &Recording,
    expected_ut: &[[f64; 3]],
    field: &ReferenceField,
    kept: &[bool],
    looks_off: bool,
) -> ReferenceDoubt {
    let convention = match (&rec.quat, field.vector()) {
        (Some(q), Some(f)) => convention::better_convention(&rec.mag_ut, q, f, Some(kept)),
        _ => None,
    };
    let offset = match (&convention, &rec.t_s) {
        (None, Some(t)) if looks_off => {
            convention::clock_offset(&rec.mag_ut, expected_ut, t, Some(kept))
        }
        _ => None,
    };
    ReferenceDoubt {
        convention,
        offset,
        part: None,
    }
}

/// Why a recording could not be calibrated.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// The vector method was asked for without an attitude reference.
    #[error(
        "the vector method needs the expected field per sample: columns rx,ry,rz, or qw,qx,qy,qz plus the world field \
         (--field-ned N,E,D, --location LAT,LON,ALT --date YYYY-MM-DD, or field_ned_ut / location + date in the \
         recording's metadata); {0}"
    )]
    NoReference(&'static str),
    /// Every reading is (nearly) zero: the sensor returned nothing but zeros.
    #[error(
        "every reading is zero (|m| below {ZERO_READING:e} in all {rows} rows): the sensor returned only zeros — \
         it was not powered, not configured (never started measuring), or there is a wiring fault — and there is \
         nothing to calibrate; check the sensor's power, configuration and wiring, and record again"
    )]
    AllZero {
        /// Rows in the recording.
        rows: usize,
    },
    /// The readings hardly vary and lie near zero: another unit than µT.
    #[error(
        "the readings hardly vary and lie {median:.3} units from zero, where the Earth's field is 22–67 µT: they are \
         not in µT (gauss is a hundredth of it: multiply such readings by 100); convert the recording to µT"
    )]
    NotMicrotesla {
        /// The readings' median magnitude, in their units.
        median: f64,
    },
    /// The fit failed for want of directions, while the readings spread further than turning in the field can take
    /// them: two states (something magnetic on the board for part of the recording), or another unit.
    #[error(
        "the readings spread over {spread_ut:.0} µT along sensor axis {axis}, more than turning in a field of \
         {field_ut:.1} µT can take them (about twice the field): most likely something magnetic was on or near the \
         sensor for part of the recording, and the readings sit on two centres — remove it and record again (or the \
         readings are not in µT). The fit itself says: {fit}"
    )]
    TwoCentres {
        /// Why the fit failed.
        fit: FitError,
        /// The readings' spread (1st to 99th percentile) along `axis`, µT.
        spread_ut: f64,
        /// The sensor axis with the largest spread.
        axis: char,
        /// The field's magnitude, µT.
        field_ut: f64,
    },
    /// The fit failed.
    #[error(transparent)]
    Fit(#[from] FitError),
}

impl From<MissingReference> for CalibrateError {
    fn from(m: MissingReference) -> CalibrateError {
        CalibrateError::NoReference(m.0)
    }
}

/// A reading of a magnitude below this is zero: no sensor in any unit reads a field that small.
const ZERO_READING: f64 = 1e-9;

/// The spread a reading can have by turning in a field, in units of the field: twice it, and a gain of up to this.
const TURNING_SPREAD_GAIN: f64 = 1.5;

/// Why a fit was refused, in the user's terms: [`CalibrateError::AllZero`] when every reading is zero (below
/// [`ZERO_READING`]), `e`, or [`CalibrateError::NotMicrotesla`] when the readings hardly vary because they are all
/// near zero (below a tenth of the Earth's weakest field), or [`CalibrateError::TwoCentres`]
/// when the fit failed for want of directions while the readings spread over more than turning in a field of
/// `field_ut` can take them (`2·`[`TURNING_SPREAD_GAIN`] times it): a fit refused as a "planar rotation" of the
/// physical BROAD 02 recording with 300 µT on its board for the middle 90 s told the user to turn the sensor more.
fn refusal(e: FitError, raw_ut: &[[f64; 3]], field_ut: Option<f64>) -> CalibrateError {
    if !raw_ut.is_empty() && raw_ut.iter().all(|m| frames::norm(*m) < ZERO_READING) {
        return CalibrateError::AllZero { rows: raw_ut.len() };
    }
    let wants_directions = matches!(
        e,
        FitError::Coverage(CoverageError::Planar { .. } | CoverageError::OneDirection { .. })
            | FitError::Undetermined { .. }
            | FitError::NoiseDominates { .. }
    );
    if let (true, Some(field_ut)) = (wants_directions, field_ut) {
        let spreads: [f64; 3] = std::array::from_fn(|k| {
            let mut v: Vec<f64> = raw_ut
                .iter()
                .step_by((raw_ut.len() / 10_000).max(1))
                .map(|m| m[k])
                .filter(|x| x.is_finite())
                .collect();
            v.sort_by(f64::total_cmp);
            let at = |p: f64| v.get((p * (v.len().max(1) - 1) as f64).round() as usize);
            match (at(0.01), at(0.99)) {
                (Some(lo), Some(hi)) => hi - lo,
                _ => 0.0,
            }
        });
        let k = (0..3)
            .max_by(|&i, &j| spreads[i].total_cmp(&spreads[j]))
            .expect("three axes");
        if spreads[k] > 2.0 * TURNING_SPREAD_GAIN * field_ut {
            return CalibrateError::TwoCentres {
                fit: e,
                spread_ut: spreads[k],
                axis: ['X', 'Y', 'Z'][k],
                field_ut,
            };
        }
        return e.into();
    }
    if !matches!(e, FitError::Coverage(CoverageError::Still { .. })) {
        return e.into();
    }
    let mut norms: Vec<f64> = raw_ut
        .iter()
        .step_by((raw_ut.len() / 10_000).max(1))
        .map(|m| frames::norm(*m))
        .filter(|n| n.is_finite())
        .collect();
    // NaN (no finite reading) is not below anything.
    let median = checks::median(&mut norms);
    if median < 0.1 * checks::EARTH_FIELD_UT.0 {
        CalibrateError::NotMicrotesla { median }
    } else {
        e.into()
    }
}

/// Reads a recording to calibrate it with `method` against the field `resolve` finds for its metadata. Without the
/// diagnosis, a vector fit sees the attitude only through the expected field, so the quaternions are turned into it
/// as the rows are read (the recording then has `ref_ut` and no `quat`): 24 bytes a row kept instead of 32, and no
/// column made from them for the fit; and the temperature, which only the diagnosis uses, is not kept. The scalar
/// method without the diagnosis keeps neither the attitude nor the temperature.
pub fn read_to_calibrate(
    path: &Path,
    method: Method,
    diagnose: bool,
    resolve: impl FnOnce(&Metadata) -> anyhow::Result<ReferenceField>,
) -> anyhow::Result<(Recording, ReferenceField)> {
    if diagnose || method == Method::Scalar {
        let options = ReadOptions {
            skip_temperature: !diagnose,
            skip_attitude: !diagnose,
            ..ReadOptions::default()
        };
        let rec = Recording::read_with(path, options)?;
        let field = resolve(&rec.meta)?;
        return Ok((rec, field));
    }
    let field = resolve(&Recording::read_metadata(path)?)?;
    let turn = field
        .vector()
        .map(|f| move |q: [f64; 4]| frames::expected_sensor_field(q, f));
    let options = ReadOptions {
        attitude_to_reference: turn.as_ref().map(|t| t as AttitudeToReference),
        skip_temperature: true,
        ..ReadOptions::default()
    };
    let rec = Recording::read_with(path, options)?;
    Ok((rec, field))
}

/// Whether a fit looks off in a way a reference in another convention or out of step leaves it: more than 1 % of
/// its `total` rows `excluded` as grossly off, or a residual above three times the noise (both RMS, µT).
fn fit_looks_off(excluded: usize, total: usize, residual_ut: f64, noise_ut: f64) -> bool {
    100 * excluded > total || residual_ut > 3.0 * noise_ut
}

/// A vector fit's residual this many times the noise may be a reference whose north is off true north: on a cube24
/// of each of the five simulated chips, an edge 1° off leaves 1.14–1.39 times the noise (0.5°: 1.04–2.6).
const HEADING_CHECK_RATIO: f64 = 1.1;

/// Whether a vector fit made without the quaternions (turned into the expected field as they were read, see
/// [`read_to_calibrate`]) looks off enough to be made again with them kept, so that a reference in another
/// convention ([`convention`]) or whose north is not true north ([`reference_heading`]) can be recognised:
/// [`fit_looks_off`], a residual that is a good part of the field, or one [`HEADING_CHECK_RATIO`] times the noise.
pub fn attitude_worth_checking(cal: &Calibration, rec: &Recording) -> bool {
    matches!(cal.fit, Fit::Vector(_))
        && rec.quat.is_none()
        && rec.ref_ut.is_some()
        && cal.field.vector().is_some()
        && attitude_in_doubt(
            cal.samples.excluded,
            cal.samples.total,
            cal.residual_rms_ut,
            cal.noise_floor_ut,
            &cal.field,
        )
}

/// Whether a vector fit leaves room for a reference in another convention, out of step or whose north is not true
/// north, which the attitude is then checked for (with the diagnosis, or without it by [`attitude_worth_checking`]):
/// [`fit_looks_off`], a residual that is a good part of the field, or one [`HEADING_CHECK_RATIO`] times the noise (or
/// a noise not measured). A fit that leaves the noise and no more has no misfit for another reference to explain.
fn attitude_in_doubt(
    excluded: usize,
    total: usize,
    residual_ut: f64,
    noise_ut: f64,
    field: &ReferenceField,
) -> bool {
    fit_looks_off(excluded, total, residual_ut, noise_ut)
        || noise_ut.is_nan()
        || residual_ut > HEADING_CHECK_RATIO * noise_ut
        || field
            .magnitude()
            .is_some_and(|f| residual_ut > crate::fit::REFERENCE_OFF_SHARE * f)
}

/// Leaves out the rows of `rec` a fault of the sensor's output made ([`faults`]): an axis at its extreme while the
/// sensor turns (the sensor's range clipped it), or the same reading many times in a row (a frozen output); and says
/// so, one warning per fault found.
pub fn drop_faulty(rec: &mut Recording) -> Vec<String> {
    let pinned = faults::pinned(&rec.mag_ut);
    let mut left_out = faults::rows_pinned(&rec.mag_ut, &pinned);
    let mut warnings = Vec::new();
    let share = |n: usize| 100.0 * n as f64 / rec.len().max(1) as f64;
    if !pinned.is_empty() {
        let n = left_out.iter().filter(|c| **c).count();
        let axes: Vec<String> = pinned
            .iter()
            .map(|p| {
                format!(
                    "m{} at {} ({} samples)",
                    ["x", "y", "z"][p.axis],
                    p.value,
                    p.samples
                )
            })
            .collect();
        warnings.push(format!(
            "{n} samples ({:.1} %) left out as clipped: {} — one value, the axis's extreme, held while the other \
             axes swept on. The sensor's range was too small for the field it saw there (a magnet near, or a range \
             setting too sensitive): set a wider range or keep magnets away, and record again if those directions \
             matter",
            share(n),
            axes.join(", ")
        ));
    }
    // A recording that is one frozen run is left whole: the fit refuses it for what it is (all zeros, no turning).
    let frozen: Vec<(usize, usize)> = faults::frozen_runs(&rec.mag_ut)
        .into_iter()
        .filter(|&(a, b)| b - a < rec.len())
        .collect();
    if !frozen.is_empty() {
        let n: usize = frozen.iter().map(|(a, b)| b - a).sum();
        let at: Vec<String> = frozen
            .iter()
            .take(3)
            .map(|&(a, b)| match &rec.t_s {
                Some(t) => format!("{:.2}–{:.2} s", t[a], t[b - 1]),
                None => format!("samples {}–{}", a + 1, b),
            })
            .collect();
        warnings.push(format!(
            "{n} samples ({:.1} %) left out as frozen: the same reading, to the last digit, {} or more times in a row \
             ({}{}) — the sensor stopped converting or the driver repeated its last value; check the sensor's mode \
             and the reading loop",
            share(n),
            faults::FROZEN_RUN,
            at.join(", "),
            if frozen.len() > 3 { ", …" } else { "" }
        ));
        for (a, b) in frozen {
            left_out[a..b].fill(true);
        }
    }
    if left_out.iter().any(|l| *l) {
        rec.retain_rows(&left_out.iter().map(|l| !l).collect::<Vec<bool>>());
    }
    warnings
}

/// Row `i`'s raw reading with the body-fixed corrections of `model` taken out: `A⁻¹·(B − b)` for the field `B` the
/// model gives (the reading itself for a model without corrections).
fn without_corrections(model: &Model, rec: &Recording, i: usize) -> [f64; 3] {
    let raw = rec.mag_ut[i];
    if model.corrections().next().is_none() {
        return raw;
    }
    let a = nalgebra::Matrix3::from_fn(|j, k| model.a[j][k]);
    let Some(a_inv) = a.try_inverse() else {
        return raw;
    };
    let mut currents = vec![0.0; rec.currents.len()];
    let calibrated = calibrate_row(model, rec, i, &mut currents);
    let field = frames::sub(calibrated, model.b_ut);
    let m = a_inv * nalgebra::Vector3::from(field);
    [m.x, m.y, m.z]
}

/// Calibrates a recording and, with `diagnose`, looks for what the base model leaves out. The coverage figure is the
/// recorder's ([`magcal_calib::directions`], the same for the same rows) over the rows the calibration used: rows
/// without a reference or in a state left out add no directions.
pub fn calibrate(
    rec: &Recording,
    method: Method,
    field: ReferenceField,
    diagnose: bool,
) -> Result<Calibration, CalibrateError> {
    calibrate_with(rec, method, field, diagnose, None)
}

/// [`calibrate`], with the chip whose raw counts the readings are, when the user says (`--chip`): it gives the
/// readings' units per gauss when they are not µT ([`Units`]).
pub fn calibrate_with(
    rec: &Recording,
    method: Method,
    field: ReferenceField,
    diagnose: bool,
    chip: Option<&ChipOption>,
) -> Result<Calibration, CalibrateError> {
    let mut warnings = Vec::new();
    let method = chosen_method(rec, method, &field, &mut warnings);
    warnings.extend(units_unread(&rec.meta));
    warnings.extend(time_unit_mismatch(rec));
    let mut notes = Vec::new();
    let base = match method {
        Method::Vector => vector_base(rec, &field, &mut notes, &mut warnings)?,
        _ => scalar_base(rec, &field, &mut notes, &mut warnings)?,
    };
    let mut cal = measured(rec, base, field, notes, warnings, chip)?;
    if diagnose {
        diagnose_into(rec, &mut cal)?;
    }
    Ok(cal)
}

/// The method `asked` for: auto is the vector method when the recording has a reference (`rx,ry,rz`, or the
/// attitude and a world field vector), and the scalar one otherwise — with a warning when the recording looks as if
/// it had meant to give one (into `warnings`).
fn chosen_method(
    rec: &Recording,
    asked: Method,
    field: &ReferenceField,
    warnings: &mut Vec<String>,
) -> Method {
    let has_reference = rec.ref_ut.is_some() || (rec.quat.is_some() && field.vector().is_some());
    match asked {
        Method::Auto if has_reference => Method::Vector,
        Method::Auto => {
            warnings.extend(no_reference_warning(rec, field));
            Method::Scalar
        }
        m => m,
    }
}

/// Why a recording fitted by the scalar method for want of a reference may have meant to give one, if it may: an
/// attitude with a magnitude alone given, quaternions or angles under other names than magcal's, or quaternions
/// without a world field vector.
fn no_reference_warning(rec: &Recording, field: &ReferenceField) -> Option<String> {
    // A magnitude alone comes from --field-ut (see crate::field::resolve).
    if rec.quat.is_some() && matches!(field, ReferenceField::Magnitude { .. }) {
        Some(
            "only the magnitude was fitted (scalar method: misalignment unobserved) though the recording has \
             attitude quaternions: --field-ut gives a magnitude alone and replaces any field vector the \
             recording's metadata holds. Drop --field-ut to use that vector, or give --field-ned N,E,D (µT), \
             to fit every component (vector method)"
                .to_owned(),
        )
    } else if let Some(columns) = quaternion_like_columns(rec) {
        Some(format!(
            "only the magnitude was fitted (scalar method: misalignment unobserved): the recording's columns \
             {columns} look like an attitude quaternion, but magcal reads the attitude from columns named \
             qw,qx,qy,qz (scalar first, turning sensor axes into NED). Named so, with the world field, they give \
             the vector method, which fits every component"
        ))
    } else if let Some(columns) = euler_like_columns(rec) {
        Some(format!(
            "only the magnitude was fitted (scalar method: misalignment unobserved): the recording's columns \
             {columns} look like an attitude in angles, which magcal does not read (their order and axes \
             differ from one program to the next). Written as a quaternion qw,qx,qy,qz (scalar first, turning \
             sensor axes into NED), with the world field, the attitude gives the vector method, which fits \
             every component"
        ))
    } else if rec.quat.is_some() {
        Some(format!(
            "the recording has attitude quaternions but no world field vector, so only the magnitude was \
             fitted (scalar method: misalignment unobserved). Give the field with --field-ned N,E,D (µT), or \
             --location LAT,LON,ALT --date YYYY-MM-DD, or a field_ned_ut line in the recording's metadata, \
             to fit every component (vector method){}",
            unread_field_keys(&rec.meta)
        ))
    } else {
        None
    }
}

/// The robust base fit and what was measured with it, before the checks.
struct Base {
    fit: Fit,
    /// The raw readings' noise floor.
    noise: NoiseFloor,
    /// Rows the fit used.
    used: usize,
    robust: RobustSummary,
    /// The coverage of the sphere of directions by the rows the fit used.
    rows_coverage: f64,
    reference: ReferenceDoubt,
    /// The reference's heading, when fitted (vector method).
    heading: Option<ReferenceHeading>,
}

/// The vector method's robust base fit against the expected field per row, with the reference's heading found and
/// fitted when it is material ([`reference_heading`]), and the reference checked for another convention or clock
/// when the fit looks off; neither is looked for when the fit leaves no room for them ([`attitude_in_doubt`]). What
/// the heading search says to know goes to `notes`.
fn vector_base(
    rec: &Recording,
    field: &ReferenceField,
    notes: &mut Vec<String>,
    warnings: &mut Vec<String>,
) -> Result<Base, CalibrateError> {
    let expected = expected_field(rec, field)?;
    let noise = noise::estimate(&rec.mag_ut, Some(&expected));
    let problem = VectorProblem {
        raw_ut: Cow::Borrowed(&rec.mag_ut),
        expected_ut: expected,
        raw_noise_var_ut2: noise.floor_ut.map(|f| f * f),
    };
    let first = robust::fit(&problem, rec.t_s.as_deref());
    let expected = &problem.expected_ut;
    let in_doubt = first.as_ref().map_or(true, |r| {
        attitude_in_doubt(
            r.excluded(),
            r.kept.len(),
            rms3(r.fit.residual_rms_ut),
            rms3(noise.floor_ut),
            field,
        )
    });
    if in_doubt {
        match reference_heading::search(rec, field, &noise, first.as_ref().ok()) {
            Search::Turned(turned) => {
                return Ok(turned_base(rec, field, expected, first, turned, noise));
            }
            Search::Left(Some(e)) if !e.determined() => {
                if let Ok(r) = &first
                    && looks_off(r, &noise)
                {
                    notes.push(reference_heading::undetermined_note(&e));
                }
            }
            Search::Left(_) | Search::NoAttitude => {}
        }
    }
    let mut r = first.map_err(|e| refusal(e, &rec.mag_ut, field.magnitude()))?;
    let mut reference = if in_doubt {
        reference_out_of_convention(rec, expected, field, &r.kept, looks_off(&r, &noise))
    } else {
        ReferenceDoubt::default()
    };
    // The majority's misfit would blame the reference (a good part of the field): does any part agree with it?
    let blamed = field
        .magnitude()
        .is_some_and(|f| rms3(r.fit.residual_rms_ut) > crate::fit::REFERENCE_OFF_SHARE * f);
    if !reference.is_some() && blamed {
        match consistent_part(&problem, rec, r) {
            Consistent::Part(part, warning) => {
                warnings.push(warning);
                r = part;
            }
            Consistent::Undetermined(majority, part) => {
                reference.part = Some(part);
                r = majority;
            }
            Consistent::None(majority) => r = majority,
        }
    }
    Ok(vector_base_of(rec, expected, r, noise, reference, None))
}

/// A consistent part's residual scale at most this share of the majority fit's replaces it ([`consistent_part`]).
const CONSISTENT_PART_RATIO: f64 = 0.5;

/// What [`consistent_part`] makes of a mostly disturbed recording.
enum Consistent {
    /// The consistent part, which determines the calibration, and the warning that says so.
    Part(robust::Robust<VectorFit>, String),
    /// The majority's fit, and the consistent part that does not determine the calibration.
    Undetermined(robust::Robust<VectorFit>, UndeterminedPart),
    /// The majority's fit: no part agrees with the reference.
    None(robust::Robust<VectorFit>),
}

/// The robust fit `majority` of a recording whose misfit would blame the reference (a good part of the field), or
/// the consistent part of it when there is one ([`robust::consistent_part`]) whose residual's scale is at most
/// [`CONSISTENT_PART_RATIO`] of the majority's: most of the recording disturbed, the rest agreeing with the
/// reference. It calibrates when it holds through the recording ([`robust::holds_out`]); otherwise it is said, with
/// what it lacks, and the reference is not blamed. Smaller misfits are the diagnosis' to explain (a motor current
/// on for most of a recording is an effect, not a disturbance).
fn consistent_part(
    problem: &VectorProblem,
    rec: &Recording,
    majority: robust::Robust<VectorFit>,
) -> Consistent {
    let t_s = rec.t_s.as_deref();
    let part = match robust::consistent_part(problem, t_s) {
        Some(part) if part.sigma_ut <= CONSISTENT_PART_RATIO * majority.sigma_ut => part,
        _ => return Consistent::None(majority),
    };
    let usable = part.residual_ut.iter().filter(|e| e.is_finite()).count();
    let inside: Vec<bool> = (0..part.kept.len())
        .map(|i| part.kept[i] && part.residual_ut[i].is_finite())
        .collect();
    let share = inside.iter().filter(|k| **k).count() as f64 / usable.max(1) as f64;
    let check = robust::holds_out(problem, &part, t_s);
    if check == robust::PartCheck::Holds {
        let warning = format!(
            "most of this recording disagrees with the attitude reference: only {:.0} % of the readings with a \
             reference agree with it under one calibration, to {:.2} µT per axis (a fit of the majority misses by \
             {:.2} µT), and the calibration comes from them; the rest is left out as disturbed (the spans below). \
             Check them, and record again away from magnets and metal to confirm",
            100.0 * share,
            part.sigma_ut,
            majority.sigma_ut
        );
        return Consistent::Part(part, warning);
    }
    let covered = robust::RobustProblem::covered(problem, &part.fit, &inside);
    let undetermined = UndeterminedPart {
        share,
        sigma_ut: part.sigma_ut,
        majority_sigma_ut: majority.sigma_ut,
        stretches: longest_stretches(rec, &inside),
        covered,
        brief: check == robust::PartCheck::Brief,
    };
    Consistent::Undetermined(majority, undetermined)
}

/// The longest stretches of rows `inside` (at most four, in time order), as `(t0_s, t1_s)`, or 1-based rows
/// without time.
fn longest_stretches(rec: &Recording, inside: &[bool]) -> Vec<(f64, f64)> {
    const SHOWN: usize = 4;
    let outside: Vec<bool> = inside.iter().map(|k| !k).collect();
    let mut runs = robust::excluded_runs(&outside);
    runs.sort_by_key(|(a, b)| std::cmp::Reverse(b - a));
    runs.truncate(SHOWN);
    runs.sort_unstable();
    runs.into_iter()
        .map(|(a, b)| match &rec.t_s {
            Some(t) => (t[a], t[b - 1]),
            None => ((a + 1) as f64, b as f64),
        })
        .collect()
}

/// Whether a robust vector fit looks off ([`fit_looks_off`]) against the raw readings' `noise`. The search for a
/// reference out of step is not made for a fit that fits (it takes about as long as the fit of 10⁶ rows).
fn looks_off(r: &robust::Robust<VectorFit>, noise: &NoiseFloor) -> bool {
    fit_looks_off(
        r.excluded(),
        r.kept.len(),
        rms3(r.fit.residual_rms_ut),
        rms3(noise.floor_ut),
    )
}

/// The base of the fit against the field turned by the reference's heading, or of the fit against the field as
/// given (`first`, against `expected`) when that one is no worse (its residual's scale) or, the turned fit still
/// looking off, the reference as given is found in another convention or out of step: a heading that does not
/// explain the mismatch is not fitted.
fn turned_base(
    rec: &Recording,
    field: &ReferenceField,
    expected: &[[f64; 3]],
    first: Result<robust::Robust<VectorFit>, FitError>,
    turned: reference_heading::Turned,
    noise: NoiseFloor,
) -> Base {
    let turned_off = looks_off(&turned.robust, &noise);
    if let Ok(r) = first {
        let worse = turned.robust.sigma_ut > r.sigma_ut;
        let doubt = (worse || turned_off).then(|| {
            reference_out_of_convention(rec, expected, field, &r.kept, looks_off(&r, &noise))
        });
        if worse || doubt.as_ref().is_some_and(ReferenceDoubt::is_some) {
            return vector_base_of(rec, expected, r, noise, doubt.unwrap_or_default(), None);
        }
    }
    let in_reference = ReferenceField::Vector {
        field_ned_ut: turned.heading.field_ned_ut,
        source: field.source().to_owned(),
    };
    let reference = reference_out_of_convention(
        rec,
        &turned.expected_ut,
        &in_reference,
        &turned.robust.kept,
        turned_off,
    );
    vector_base_of(
        rec,
        &turned.expected_ut,
        turned.robust,
        noise,
        reference,
        Some(turned.heading),
    )
}

/// The base of a robust vector fit `r` against the expected field `expected`, with what was found of the reference.
fn vector_base_of(
    rec: &Recording,
    expected: &[[f64; 3]],
    r: robust::Robust<VectorFit>,
    noise: NoiseFloor,
    reference: ReferenceDoubt,
    heading: Option<ReferenceHeading>,
) -> Base {
    // The rows the fit used: kept, with a reference.
    let rows_coverage = fraction_of(expected.len(), |i| {
        (r.kept[i] && expected[i].iter().all(|v| v.is_finite())).then_some(rec.mag_ut[i])
    });
    Base {
        used: r.fit.n,
        fit: Fit::Vector(r.fit),
        noise,
        robust: RobustSummary::of(r.kept, r.sigma_ut, rec, false),
        rows_coverage,
        reference,
        heading,
    }
}

/// The scalar method's robust base fit against the field's magnitude (given, or the raw ellipsoid's mean radius),
/// with what the method cannot see said in `notes` and what the fit kept though it looks like two states in
/// `warnings`.
fn scalar_base(
    rec: &Recording,
    field: &ReferenceField,
    notes: &mut Vec<String>,
    warnings: &mut Vec<String>,
) -> Result<Base, CalibrateError> {
    let noise = noise::estimate(&rec.mag_ut, None);
    let r = robust::fit(
        &ScalarProblem {
            raw_ut: Cow::Borrowed(&rec.mag_ut),
            field_ut: field.magnitude(),
            raw_noise_var_ut2: noise.floor_ut.map(|f| f * f),
        },
        rec.t_s.as_deref(),
    )
    .map_err(|e| refusal(e, &rec.mag_ut, field.magnitude()))?;
    warnings.extend(mixed_states(&r.mixed, rec));
    let s = r.fit;
    notes.push(format!(
        "rotation not observable: {}",
        scalar::ROTATION_NOTE
    ));
    if !s.field_given {
        notes.push(format!(
            "field magnitude unknown: the calibrated sphere keeps the raw ellipsoid's mean radius, {:.2} µT \
             (give --field-ut, --field-ned or --location/--date for absolute scale)",
            s.field_ut
        ));
    }
    warnings.extend(s.warning());
    let rows_coverage = fraction_of(rec.mag_ut.len(), |i| r.kept[i].then_some(rec.mag_ut[i]));
    // The rows the calibration stands on: a window with a centre of its own lends the fit its shape, not its state.
    let used = r
        .kept
        .iter()
        .zip(&rec.mag_ut)
        .filter(|(k, m)| **k && m.iter().all(|v| v.is_finite()))
        .count();
    Ok(Base {
        used,
        fit: Fit::Scalar(s),
        noise,
        robust: RobustSummary::of(r.kept, r.sigma_ut, rec, true),
        rows_coverage,
        reference: ReferenceDoubt::default(),
        heading: None,
    })
}

/// What the claims owe to the recording's two halves, when they disagree beyond chance ([`Halves::beyond_chance`]).
fn halves_note(halves: Halves) -> Option<String> {
    halves.beyond_chance().then(|| {
        let w = halves.widening();
        format!(
            "the recording's first and second halves, each fitted alone, disagree by {w:.1} times what their \
             standard errors allow (κ = {:.1}; noise alone gives about 1): the standard errors and the heading \
             figures are widened by {w:.1} times, to hold on the next recording. Something the model does not \
             explain changed along the recording — a field that varies along the sensor's path, an offset or a \
             reference that drifts; turning the sensor in one place, away from metal, narrows them",
            halves.kappa
        )
    })
}

/// The calibration of a base fit: what it left out and how well it covers, the noise (bounded by the residual when
/// the readings' differences cannot measure it), and the last checks on the fit.
fn measured(
    rec: &Recording,
    base: Base,
    field: ReferenceField,
    mut notes: Vec<String>,
    mut warnings: Vec<String>,
    chip: Option<&ChipOption>,
) -> Result<Calibration, CalibrateError> {
    let Base {
        fit,
        mut noise,
        used,
        robust,
        rows_coverage,
        reference,
        heading,
    } = base;
    if let Some(note) = robust.note() {
        notes.push(note);
    }
    let face = fit.face();
    let residual_rms_ut = face.residual_rms_ut();
    notes.extend(face.coverage().warning());
    notes.extend(halves_note(face.halves()));
    let model = face.model();
    let floor_of = |noise: &NoiseFloor| match &fit {
        Fit::Vector(_) => noise.calibrated_rms_ut(&model.a),
        Fit::Scalar(_) => radial_floor_ut(noise, &model, &rec.mag_ut),
    };
    // The sample-to-sample noise cannot exceed what the residual holds: rows that change pose every sample (or are
    // shuffled) make the differences measure the rotation, not the noise.
    let floor_now = floor_of(&noise);
    let noise_measured = noise_measurable(floor_now, residual_rms_ut);
    if !noise_measured {
        notes.push(format!(
            "the sample-to-sample noise could not be measured ({:.3} µT from {}, more than the fit's residual of \
             {residual_rms_ut:.3} µT allows: the rows change orientation from one to the next); the residual bounds \
             it instead",
            floor_now,
            noise_source(&noise),
        ));
        noise = noise.scaled(residual_rms_ut / floor_now);
    }
    let checked = checks::check(&model, &fit, &field, &rec.mag_ut, &robust.kept, &reference)?;
    warnings.extend(checked.warnings);
    let field_ut = match &fit {
        Fit::Scalar(s) => s.field_given.then_some(s.field_ut),
        // A vector fit's calibrated field is in the reference's units, µT.
        Fit::Vector(_) => Some(field.magnitude().unwrap_or_else(|| {
            let a = nalgebra::Matrix3::from_fn(|j, k| model.a[j][k]);
            checked.raw_radius * a.determinant().abs().cbrt()
        })),
    };
    let units = Units::resolve(
        checked.raw_not_ut,
        checked.raw_radius,
        field_ut,
        &rec.meta,
        chip,
    );
    if let Some(said) = units.statement() {
        if units.is_warning() {
            warnings.push(said);
        } else {
            notes.push(said);
        }
    }
    let noise_floor_ut = floor_of(&noise);
    Ok(Calibration {
        fit,
        field,
        noise,
        residual_rms_ut,
        noise_floor_ut,
        noise_measured,
        sphere_coverage: rows_coverage,
        samples: SampleCounts {
            total: rec.len(),
            used,
            missing_reference: rec.len() - used - robust.excluded(),
            excluded: robust.excluded(),
        },
        notes,
        warnings,
        raw_not_ut: checked.raw_not_ut,
        units,
        robust,
        diagnosis: None,
        diagnosis_failed: None,
        reference,
        reference_heading: heading,
    })
}

/// The diagnosis of a calibration, into it: not made against a reference in another convention or for too few
/// samples (a note says so); a diagnosis that cannot be made leaves the calibration as it is, said so: the base fit
/// stands on its own (a recording it calibrates is not refused for what the diagnosis could not do).
fn diagnose_into(rec: &Recording, cal: &mut Calibration) -> Result<(), CalibrateError> {
    let used = cal.samples.used;
    if cal.reference.part.is_some() {
        cal.notes.push(
            "not diagnosed: most of the recording is disturbed, and the part that agrees with the reference does not \
             determine a calibration to judge the rest against (the WARNING says when it agreed)"
                .to_owned(),
        );
        return Ok(());
    }
    if cal.reference.is_some() {
        cal.notes.push(
            "not diagnosed: the attitude reference fits far better in another convention or shifted in time (the \
             WARNING says how); against it as given, the diagnosis would find disturbances that are not there"
                .to_owned(),
        );
        return Ok(());
    }
    if used < diagnosis::MIN_SAMPLES {
        cal.notes.push(format!(
            "not diagnosed: the diagnosis needs at least {} samples and this recording has {used}; the calibration \
             above stands on its own",
            diagnosis::MIN_SAMPLES
        ));
        return Ok(());
    }
    match diagnose_refitted(rec, cal, &cal.base_model())? {
        Ok(d) => {
            let stride = d.residuals.stride;
            if stride > 1 {
                cal.notes.push(format!(
                    "the diagnosis looked at one sample in {stride} ({} samples; a recording this long has power to \
                     spare): its spans are located to {stride} samples and its counts of samples are of those it \
                     looked at; the calibration's own counts are of every row",
                    d.residuals.rows.len()
                ));
            }
            cal.warnings.extend(other_offset_state(&d, rec));
            cal.warnings.extend(drifting_offset(&d, rec, &cal.field));
            cal.sphere_coverage = used_coverage(rec, d.model, &d);
            cal.diagnosis = Some(d);
        }
        Err(e) => {
            cal.notes.push(format!(
                "not diagnosed: {e}; the calibration above is the robust base fit, standing on its own"
            ));
            cal.diagnosis_failed = Some(e.to_string());
        }
    }
    Ok(())
}

/// The coverage of the rows the final model of a diagnosis `d` used, as the sensor would have read them without
/// the body-fixed effects it models, one-off windows included (a magnet on the board for a third of BROAD 33 is
/// counted where its rows point, not 27 µT off the sphere); `model` is the calibration's final model.
fn used_coverage(rec: &Recording, mut model: Model, d: &Diagnosis) -> f64 {
    for found in d
        .effects
        .iter()
        .filter(|f| f.effect.id().frame() == Frame::Body)
    {
        if !model.corrections().any(|c| *c == found.effect) {
            let _ = model.add_correction(found.effect);
        }
    }
    let r = &d.residuals;
    fraction_of(r.rows.len(), |k| {
        (!r.excluded[k]).then(|| without_corrections(&model, rec, r.rows[k]))
    })
}

/// Four carried-along columns that look like an attitude quaternion under other names than magcal's (`q0`…`q3`,
/// `q1`…`q4`, `quat_w`…`quat_z`: names with a `q` in them that differ only in their last character, four of 0–4 or
/// of w, x, y, z), listed as found; `None` when there are none or the recording has magcal's.
fn quaternion_like_columns(rec: &Recording) -> Option<String> {
    if rec.quat.is_some() {
        return None;
    }
    // The columns by what their names share: the name less its last character, and that character's kind (a digit
    // or a letter); each with its last characters and names.
    type Group<'a> = ((String, bool), Vec<(char, &'a str)>);
    let mut groups: Vec<Group> = Vec::new();
    for c in &rec.extra {
        let name = c.name.trim();
        let lower = name.to_lowercase();
        let Some(last) = lower.chars().last() else {
            continue;
        };
        let digit = ('0'..='4').contains(&last);
        if !digit && !"wxyz".contains(last) {
            continue;
        }
        let prefix = lower[..lower.len() - 1].trim_end_matches(['_', '.', ' ']);
        if !prefix.contains('q') {
            continue;
        }
        let key = (prefix.to_owned(), digit);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, members)) => members.push((last, name)),
            None => groups.push((key, vec![(last, name)])),
        }
    }
    groups.into_iter().find_map(|(_, members)| {
        let mut ends: Vec<char> = members.iter().map(|m| m.0).collect();
        ends.sort_unstable();
        ends.dedup();
        (ends.len() == 4).then(|| members.iter().map(|m| m.1).collect::<Vec<_>>().join(", "))
    })
}

/// Carried-along columns that look like an attitude in angles (roll, pitch and yaw, heading or azimuth, with any
/// prefix or unit suffix), listed as found; `None` without roll and pitch and one of the others, or with quaternions.
fn euler_like_columns(rec: &Recording) -> Option<String> {
    if rec.quat.is_some() {
        return None;
    }
    let named = |word: &str| {
        rec.extra
            .iter()
            .find(|c| c.name.to_lowercase().contains(word))
            .map(|c| c.name.trim())
    };
    let (roll, pitch) = (named("roll")?, named("pitch")?);
    let turn = named("yaw")
        .or_else(|| named("heading"))
        .or_else(|| named("azimuth"))?;
    Some(format!("{roll}, {pitch}, {turn}"))
}

/// Metadata keys that look like the field's but are not read (a typo: `field_ned:`), as a clause to append.
fn unread_field_keys(meta: &Metadata) -> String {
    let looks_like = |k: &str| {
        ["field", "ned", "location", "lat", "date"]
            .iter()
            .any(|w| k.contains(w))
    };
    let keys: Vec<String> = meta
        .other
        .iter()
        .filter(|(k, _)| looks_like(&k.to_lowercase()))
        .map(|(k, _)| format!("`{k}`"))
        .collect();
    if keys.is_empty() {
        String::new()
    } else {
        format!(
            ". The metadata has {}, which magcal does not read: its keys are field_ned_ut, location and date",
            keys.join(", ")
        )
    }
}

/// A warning when the metadata's `units` says the readings are in another unit than µT, which magcal reads them in.
fn units_unread(meta: &Metadata) -> Option<String> {
    let (_, unit) = meta
        .other
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case("units"))?;
    let micro = ["µt", "ut", "microtesla", "micro tesla", "μt"];
    (!micro.contains(&unit.trim().to_lowercase().as_str())).then(|| {
        format!(
            "the metadata says `units: {unit}`, but magcal reads every field and reading as µT (the format's unit): \
             convert the recording to µT, or read every figure here as {unit} labelled µT"
        )
    })
}

/// A time step this many times larger or smaller than the metadata's sample interval is no jitter: the time column
/// is in another unit (ms), or the rate is wrong.
const TIME_STEP_MISMATCH: f64 = 3.0;
/// At most about this many steps give the median step of [`time_unit_mismatch`].
const TIME_STEPS_LOOKED_AT: usize = 10_000;

/// A warning when the time column disagrees with the metadata's `sample_rate_hz` by more than
/// [`TIME_STEP_MISMATCH`] both in its median step and in its mean step over the whole recording: time in
/// milliseconds read as seconds made a 20 ms lag one of 19.9 s, graded good. Either alone is no unit: host timestamps
/// come in bursts (the median step is a fraction of the interval), and the cube routine records only the poses (the
/// mean step spans the turns between them). Without a `sample_rate_hz`, times in whole numbers stepping by
/// [`MILLISECOND_STEP_MIN`] or more (a logger's `millis()`) are taken for milliseconds: a calibration turns the
/// sensor, and no logger that does takes a reading only every five seconds or more.
fn time_unit_mismatch(rec: &Recording) -> Option<String> {
    let t = rec.t_s.as_deref()?;
    let (first, last) = (t.first()?, t.last()?);
    let mean_step = (last - first) / (t.len() - 1).max(1) as f64;
    // The median over at most ~10,000 steps spread over the recording: a unit check needs no more.
    let stride = (t.len() / TIME_STEPS_LOOKED_AT).max(1);
    let mut steps: Vec<f64> = (1..t.len())
        .step_by(stride)
        .map(|i| t[i] - t[i - 1])
        .filter(|d| *d > 0.0)
        .collect();
    if steps.is_empty() {
        return None;
    }
    let mid = steps.len() / 2;
    let median_step = *steps.select_nth_unstable_by(mid, f64::total_cmp).1;
    let Some(rate_hz) = rec.meta.sample_rate_hz else {
        let whole = (0..t.len())
            .step_by(stride)
            .all(|i| !t[i].is_finite() || t[i].fract() == 0.0);
        return (whole && median_step >= MILLISECOND_STEP_MIN).then(|| {
            format!(
                "the time column `t` holds whole numbers stepping by {median_step} a sample (median): a reading every \
                 {median_step} s is too slow for a sensor being turned, so `t` is most likely in milliseconds — \
                 divide it by 1000 (t is in seconds). Every time, span and lag here is in the column's units"
            )
        });
    };
    let off =
        |step: f64| !(1.0 / TIME_STEP_MISMATCH..=TIME_STEP_MISMATCH).contains(&(step * rate_hz));
    (off(mean_step) && off(median_step)).then(|| {
        format!(
            "the time column `t` steps by {median_step:.4} a sample (median), but the metadata's sample_rate_hz \
             ({rate_hz} Hz) means {:.4} s: `t` must be in seconds (in milliseconds, divide it by 1000), or the rate \
             is wrong. Every time, span and lag here is in the column's units",
            1.0 / rate_hz
        )
    })
}

/// The least median step of whole-number times taken for milliseconds when no `sample_rate_hz` says otherwise (a
/// logger at 200 Hz or slower).
const MILLISECOND_STEP_MIN: f64 = 5.0;

/// A warning when the scalar fit kept windows in which the magnitude sat apart from the rest (a field on the board
/// or in the room for that time, found by the window scan) because without them the recording would cover too few
/// directions: the calibration mixes two states, and nothing in its figures says by how much (5.6 µT on the board of
/// the physical BROAD 02 recording for the 53 s in which it turned most: the offset 5 µT off, graded usable at 4°).
fn mixed_states(windows: &[(usize, usize)], rec: &Recording) -> Option<String> {
    let t = rec.t_s.as_ref()?;
    if windows.is_empty() {
        return None;
    }
    let rows: usize = windows.iter().map(|(a, b)| b - a).sum();
    let when: Vec<String> = windows
        .iter()
        .map(|&(a, b)| format!("{:.1}–{:.1} s", t[a], t[b - 1]))
        .collect();
    Some(format!(
        "for {:.0} % of the recording ({}) the field's magnitude sat apart from the rest: most likely a field on the \
         board or in the room for that time. Those readings hold most of the directions the sensor turned through, so \
         they could not be left out, and the calibration mixes the two states: it may be off by as much as they \
         differ, which the figures above do not include. Record again with nothing magnetic on or near the sensor",
        100.0 * rows as f64 / rec.len().max(1) as f64,
        when.join(", "),
    ))
}

/// Spans fixed to the sensor covering at least this share of a recording make it a recording of two states.
const OTHER_STATE_SHARE: f64 = 0.25;

/// The spans of a constant field fixed to the sensor — something magnetic on the board — with the size of each.
fn sensor_fixed_spans(d: &Diagnosis) -> Vec<(&diagnosis::GrossSpan, f64)> {
    d.spans
        .iter()
        .filter_map(|s| match s.kind {
            diagnosis::SpanKind::SensorFixed { offset_ut, .. } => {
                Some((s, frames::norm(offset_ut)))
            }
            _ => None,
        })
        .collect()
}

/// The share of a recording's rows in `fixed` spans.
fn share_of(fixed: &[(&diagnosis::GrossSpan, f64)], rec: &Recording) -> f64 {
    fixed.iter().map(|(s, _)| s.samples).sum::<usize>() as f64 / rec.len().max(1) as f64
}

/// Spans within this share of the recording's duration of its start and of its end make the recording begin and
/// end in their state.
const BOOKEND_SHARE: f64 = 0.1;

/// Whether the recording began and ended on another offset than the one calibrated, for [`OTHER_STATE_SHARE`] of it
/// or more: the calibration is then of the state in between, most likely something on the board while the sensor
/// turned (a magnet attached for the middle 90 s of the physical BROAD 02 recording with 300 µT added gave a
/// calibration 300 µT off, graded usable).
pub fn calibrated_state_in_between(d: &Diagnosis, rec: &Recording) -> bool {
    let fixed = sensor_fixed_spans(d);
    let (Some(t), Some(first), Some(last)) = (rec.t_s.as_ref(), fixed.first(), fixed.last()) else {
        return false;
    };
    let (Some(&t0), Some(&t1)) = (t.first(), t.last()) else {
        return false;
    };
    let margin = BOOKEND_SHARE * (t1 - t0);
    share_of(&fixed, rec) >= OTHER_STATE_SHARE
        && first.0.t0_s <= t0 + margin
        && last.0.t1_s >= t1 - margin
}

/// A warning when spans of a constant field fixed to the sensor — something magnetic on the board — cover
/// [`OTHER_STATE_SHARE`] of the recording or more: the calibration is of the state the rest of it was in, which the
/// user may not mean (a magnet left on the board for most of a recording is the state most of it was in), and most
/// likely not the sensor's own when the recording began and ended in the other.
fn other_offset_state(d: &Diagnosis, rec: &Recording) -> Option<String> {
    let fixed = sensor_fixed_spans(d);
    let share = share_of(&fixed, rec);
    if share < OTHER_STATE_SHARE {
        return None;
    }
    let size_ut = fixed.iter().map(|(_, size)| *size).fold(0.0, f64::max);
    let when: Vec<String> = fixed
        .iter()
        .map(|(s, _)| format!("{:.1}–{:.1} s", s.t0_s, s.t1_s))
        .collect();
    let state = if calibrated_state_in_between(d, rec) {
        "The recording began and ended on that offset: the calibration is of the state in between, most likely \
         something on the board while the sensor turned, not the sensor's own; record again with nothing magnetic \
         on or near it"
    } else {
        "The calibration is of the state the rest of the recording was in; if the sensor will be used as it was \
         during those spans, record again in that state"
    };
    Some(format!(
        "for {:.0} % of the recording ({}) the readings sat on another offset, by up to {size_ut:.1} µT: something \
         magnetic on or near the board. {state}",
        100.0 * share,
        when.join(", ")
    ))
}

/// What an offset that drifted during the recording (a `bias_drift` the diagnosis kept) means for the next one: the
/// calibration's offset is of the drift's reference time, the readings were that far from it within the recording,
/// and a compass whose offset goes on drifting so gains heading error by the minute (`field`: for the horizontal
/// field). The parameters file and the exports hold no drift (it is of this recording's clock), so the claim of the
/// heading figures holds on the next recording only once the drift has stopped.
fn drifting_offset(d: &Diagnosis, rec: &Recording, field: &ReferenceField) -> Option<String> {
    let (found, rate_ut_per_s, t_ref_s) = d.effects.iter().find_map(|f| match f.effect {
        Effect::BiasDrift {
            rate_ut_per_s,
            t_ref_s,
        } => Some((f, rate_ut_per_s, t_ref_s)),
        _ => None,
    })?;
    let t = rec.t_s.as_deref()?;
    let (first, last) = (
        t.iter().copied().find(|v| v.is_finite())?,
        t.iter().copied().rfind(|v| v.is_finite())?,
    );
    let rate = frames::norm(rate_ut_per_s);
    let farthest_ut = rate * (t_ref_s - first).abs().max((last - t_ref_s).abs());
    let horizontal_ut = field.vector().map(|f| f[0].hypot(f[1]));
    let per_minute = match (horizontal_ut, field.magnitude()) {
        (Some(h), _) if h > 0.0 => format!(
            "a compass gains up to {:.1}° of heading error a minute (the horizontal field is {h:.1} µT)",
            (60.0 * rate / h).atan().to_degrees()
        ),
        (_, Some(f)) => format!(
            "the offset moves by {:.1} % of the field a minute",
            100.0 * 60.0 * rate / f
        ),
        _ => "the calibration's offset falls behind by that much every minute".to_owned(),
    };
    Some(format!(
        "{} (the diagnosis' bias_drift; the parameters and exports hold no drift): the calibration's offset is of \
         t = {t_ref_s:.1} s, and the readings were up to {farthest_ut:.2} µT from it within the recording. If it \
         goes on drifting so, {per_minute}, and the heading figures above hold only while it does not. An offset \
         drifts while a board warms up, or with a current or a temperature that changes: let the device settle (run \
         it for some minutes), record again, and check this calibration on that recording with magcal-apply",
        found.what
    ))
}

/// The diagnosis of `rec` against its base calibration `cal` (whose model is `model`), refitted around the spans it
/// locates ([`diagnosis::diagnose_around_spans`]): the base method's problem for the refit is made only when needed.
fn diagnose_refitted(
    rec: &Recording,
    cal: &Calibration,
    model: &Model,
) -> Result<Result<Diagnosis, FitError>, CalibrateError> {
    let input = diagnosis_input(rec, cal, &cal.robust.kept)?;
    let noise_var = cal.noise.floor_ut.map(|f| f * f);
    Ok(match &cal.fit {
        Fit::Vector(v) => diagnosis::diagnose_around_spans(
            &input,
            model,
            || {
                Some(VectorProblem {
                    raw_ut: Cow::Borrowed(&rec.mag_ut),
                    expected_ut: expected_field(rec, &cal.fitted_field()).ok()?,
                    raw_noise_var_ut2: noise_var,
                })
            },
            v,
        ),
        Fit::Scalar(s) => diagnosis::diagnose_around_spans(
            &input,
            model,
            || {
                Some(ScalarProblem {
                    raw_ut: Cow::Borrowed(&rec.mag_ut),
                    field_ut: cal.field.magnitude(),
                    raw_noise_var_ut2: noise_var,
                })
            },
            s,
        ),
    })
}

/// What the diagnosis needs from a recording and its base calibration, with the rows the base fit `kept`.
fn diagnosis_input<'a>(
    rec: &'a Recording,
    cal: &'a Calibration,
    kept: &'a [bool],
) -> Result<DiagnosisInput<'a>, CalibrateError> {
    let reference = match (
        &cal.fit,
        &rec.ref_ut,
        &rec.quat,
        cal.fitted_field().vector(),
    ) {
        (Fit::Vector(_), Some(r), _, _) => Reference::Field { expected_ut: r },
        (Fit::Vector(_), None, Some(q), Some(f)) => Reference::Attitude {
            quat: q,
            field_ned_ut: f,
        },
        (Fit::Vector(_), ..) => {
            return Err(CalibrateError::NoReference("this recording has neither"));
        }
        (Fit::Scalar(s), ..) => Reference::Magnitude {
            field_ut: s.field_ut,
        },
    };
    Ok(DiagnosisInput {
        raw_ut: &rec.mag_ut,
        t_s: rec.t_s.as_deref(),
        temp_c: rec.temp_c.as_deref(),
        currents: rec
            .currents
            .iter()
            .map(|c| (c.name.as_str(), c.values.as_slice()))
            .collect(),
        reference,
        noise: cal.noise,
        kept: Some(kept),
        scale_ut: cal.robust.scale_ut,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use magcal_sim::{AttitudeOutput, ChipModel, Scenario, SensorTruth, Trajectory, simulate};

    fn scenario(attitude: AttitudeOutput) -> Scenario {
        let chip = ChipModel::by_name("lis3mdl").unwrap();
        let mut s = Scenario::new(
            &chip,
            Trajectory::Tumble {
                duration_s: 60.0,
                rate_rad_s: 1.0,
            },
            11,
        );
        s.sensor = SensorTruth::mounted(
            [[1.08, 0.03, -0.01], [0.02, 0.95, 0.04], [-0.03, 0.01, 1.12]],
            [12.0, -30.0, 8.0],
            [0.02, -0.03, 0.01],
        );
        s.attitude = attitude;
        s
    }

    #[test]
    fn the_attitude_turned_while_reading_gives_the_fit_of_the_whole_recording() {
        let s = scenario(AttitudeOutput::Quaternion);
        let run = simulate(&s).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rec.csv");
        run.recording.write(&path).unwrap();
        let field = ReferenceField::Vector {
            field_ned_ut: s.field_ned_ut,
            source: "test".into(),
        };
        let whole = Recording::read(&path).unwrap();
        let want = calibrate(&whole, Method::Vector, field.clone(), false).unwrap();
        for method in [Method::Vector, Method::Auto] {
            let (rec, f) = read_to_calibrate(&path, method, false, |_| Ok(field.clone())).unwrap();
            // Read as the fit needs it: the expected field instead of the attitude, no temperature.
            assert!(rec.quat.is_none() && rec.temp_c.is_none() && rec.ref_ut.is_some());
            let got = calibrate(&rec, method, f, false).unwrap();
            assert_eq!(got.model(), want.model());
            assert_eq!(got.residual_rms_ut, want.residual_rms_ut);
        }
        // With the diagnosis, the recording is read whole.
        let (rec, _) =
            read_to_calibrate(&path, Method::Vector, true, |_| Ok(field.clone())).unwrap();
        assert_eq!(rec, whole);
        // The scalar method keeps neither the attitude nor the temperature, and fits as on the whole recording.
        let (rec, f) =
            read_to_calibrate(&path, Method::Scalar, false, |_| Ok(field.clone())).unwrap();
        assert!(rec.quat.is_none() && rec.ref_ut.is_none() && rec.temp_c.is_none());
        assert_eq!((&rec.mag_ut, &rec.t_s), (&whole.mag_ut, &whole.t_s));
        let want = calibrate(&whole, Method::Scalar, field.clone(), false).unwrap();
        let got = calibrate(&rec, Method::Scalar, f, false).unwrap();
        assert_eq!(got.model(), want.model());
    }

    #[test]
    fn auto_picks_vector_with_a_reference_and_scalar_without() {
        for (attitude, want) in [
            (AttitudeOutput::Quaternion, Method::Vector),
            (AttitudeOutput::ReferenceField, Method::Vector),
            (AttitudeOutput::None, Method::Scalar),
        ] {
            let s = scenario(attitude);
            let run = simulate(&s).unwrap();
            let field = ReferenceField::Vector {
                field_ned_ut: s.field_ned_ut,
                source: "test".into(),
            };
            let cal = calibrate(&run.recording, Method::Auto, field, true).unwrap();
            assert_eq!(cal.method(), want);
            // The residual sits at the noise floor (no effects injected).
            assert!(
                (cal.residual_rms_ut / cal.noise_floor_ut - 1.0).abs() < 0.1,
                "{cal:?}"
            );
            // A minute of tumbling at 1 rad/s visits about three quarters of 100 cells.
            assert!(
                cal.sphere_coverage > 0.6,
                "coverage {}",
                cal.sphere_coverage
            );
        }
    }

    #[test]
    fn vector_without_a_world_field_says_what_is_missing() {
        let run = simulate(&scenario(AttitudeOutput::Quaternion)).unwrap();
        let err = calibrate(
            &run.recording,
            Method::Vector,
            ReferenceField::Unknown,
            false,
        )
        .unwrap_err();
        assert!(err.to_string().contains("--field-ned"), "{err}");
    }

    #[test]
    fn readings_all_zero_are_a_sensor_returning_zeros_not_another_unit() {
        let still = |m: [f64; 3]| {
            let rows: String = (0..400)
                .map(|i| format!("{},{},{},{}\n", i as f64 * 0.01, m[0], m[1], m[2]))
                .collect();
            Recording::from_reader("rec.csv", format!("t,mx,my,mz\n{rows}").as_bytes()).unwrap()
        };
        let field = ReferenceField::Vector {
            field_ned_ut: [20.0, 1.0, 45.0],
            source: "test".into(),
        };
        for method in [Method::Scalar, Method::Auto] {
            let err = calibrate(&still([0.0; 3]), method, field.clone(), false).unwrap_err();
            assert!(
                matches!(err, CalibrateError::AllZero { rows: 400 }),
                "{err}"
            );
            let msg = err.to_string();
            assert!(
                msg.starts_with("every reading is zero (|m| below 1e-9 in all 400 rows): the sensor returned only zeros")
                    && msg.contains("nothing to calibrate")
                    && !msg.contains("gauss"),
                "{msg}"
            );
            // Readings near zero but not zero: another unit, as before.
            let err =
                calibrate(&still([0.2, -0.1, 0.4]), method, field.clone(), false).unwrap_err();
            assert!(matches!(err, CalibrateError::NotMicrotesla { .. }), "{err}");
            assert!(
                err.to_string().contains("multiply such readings by 100"),
                "{err}"
            );
        }
    }
}
