//! The verdict: good, usable or redo, from the heading error the calibration leaves ([`crate::heading`]), with the
//! reason and the one thing to do.
//!
//! The gate: **good** when the heading error left is at most [`GOOD_DEG`] at its worst heading, **usable** up to
//! [`USABLE_DEG`], **redo** above. What is left is built from the fit's standard errors and the part of the residual
//! the noise measured in the recording does not account for, at the recording's own field, so the gate follows the
//! sensor's noise and the local field; no field range or offset limit is assumed. Without the direction of the local
//! field the heading error cannot be stated: the verdict is then at best usable, and redo when even the most
//! favourable direction (a horizontal field) leaves more than [`USABLE_DEG`]. A fit the last checks warn about
//! (units, gains, field range, a huge hard iron: [`crate::checks`]) is at best usable.

use magcal_calib::diagnosis::Diagnosis;
use magcal_calib::effects::Effect;
use magcal_calib::frames;
use magcal_recording::Recording;

use crate::fit::Calibration;
use crate::heading::{HeadingErrors, HeadingInput, LocalField, heading_errors};
use crate::uncertainty::FieldUncertainty;

/// The most heading error a good calibration leaves, degrees (worst heading): about what a hand-held compass can be
/// read to.
pub const GOOD_DEG: f64 = 1.0;
/// The most a usable one leaves, degrees: about what ArduPilot's default fitness limit (16 mGauss of residual)
/// allows in a 20 µT horizontal field, and MotionCal's 5 % fit error at mid latitudes.
pub const USABLE_DEG: f64 = 5.0;

/// The grade, worst first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum)]
pub enum Grade {
    /// Record again.
    #[value(skip)]
    Redo,
    /// Usable, with a stated limitation.
    Usable,
    /// Good.
    Good,
}

impl Grade {
    /// In words, as printed.
    pub fn name(self) -> &'static str {
        match self {
            Grade::Redo => "redo",
            Grade::Usable => "usable",
            Grade::Good => "good",
        }
    }
}

/// The verdict on a calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// Good, usable or redo.
    pub grade: Grade,
    /// Why, in a sentence.
    pub reason: String,
    /// The one thing to do next.
    pub todo: String,
}

/// The heading figures and the verdict of a calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct Assessment {
    /// The heading figures the verdict is on, when the local field's direction is known.
    pub heading: Option<HeadingErrors>,
    /// When the final model has body-fixed corrections: the number of them, and the heading figures of the base fit
    /// (`A` and `b` fitted without them: what exports and devices get), when the field's direction is known.
    pub without_corrections: Option<(usize, Option<HeadingErrors>)>,
    /// Whether `heading` and the verdict are of the base fit (the target cannot hold the corrections).
    pub linear_only: bool,
    /// The verdict.
    pub verdict: Verdict,
}

/// What the verdict's advice can point at.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Hints {
    /// The recording had an attitude reference (vector method).
    pub vector: bool,
    /// Time spans where the misfit was located, s, when they are a small part of the recording.
    pub spans_s: Vec<(f64, f64)>,
    /// Fraction of the sphere of directions covered.
    pub coverage: f64,
    /// The diagnosis was skipped (`--no-diagnose`): running it would say what the model leaves out.
    pub diagnosis_skipped: bool,
    /// The sensor's noise could not be measured (rows that change orientation from one to the next): the whole
    /// residual counts as error, and the verdict says why.
    pub noise_unmeasured: bool,
    /// The diagnosis found the field's declination off by this much from the one given (true minus assumed),
    /// degrees, when more than [`GOOD_DEG`]: the calibration models it, but a heading computed with the declination
    /// given is off by as much.
    pub declination_off_deg: Option<f64>,
    /// The rows the (base) fit left out as grossly off, of the rows it could use (those with a reference, for the
    /// vector method): `(left out, could use)`.
    pub excluded: (usize, usize),
}

impl Hints {
    /// The share of the rows the fit could use that it left out as grossly off.
    pub fn excluded_share(&self) -> f64 {
        self.excluded.0 as f64 / self.excluded.1.max(1) as f64
    }

    /// The rows left out as grossly off, said with their base: "8343 of the 22048 readings with an attitude
    /// reference (38 %)", the summary's first line's numbers.
    fn excluded_words(&self) -> String {
        format!(
            "{} of the {} readings{} ({:.0} %)",
            self.excluded.0,
            self.excluded.1,
            if self.vector {
                " with an attitude reference"
            } else {
                ""
            },
            100.0 * self.excluded_share()
        )
    }
}

/// From this share of the rows left out as grossly off, a fit made uncertain by what it could keep is not helped by
/// recording longer as it was: what made them grossly off must go first.
pub const EXCLUDED_NOT_LONGER: f64 = 0.1;

/// Degrees in two significant figures below 10, whole degrees above.
pub fn fmt_deg(x: f64) -> String {
    if x >= 9.95 {
        format!("{x:.0}°")
    } else if x >= 0.995 {
        format!("{x:.1}°")
    } else if x >= 0.0995 {
        format!("{x:.2}°")
    } else {
        format!("{x:.3}°")
    }
}

/// The verdict from the heading figures; a declination found off is added to what to do.
pub fn judge(h: &HeadingErrors, hints: &Hints) -> Verdict {
    let mut verdict = judge_heading(h, hints);
    if let Some(off_deg) = hints.declination_off_deg {
        verdict.todo = format!(
            "{}; and mind the local field: the recording shows it {off_deg:+.1}° in declination from the one given \
             (or the attitude reference's north is off by as much), so a heading computed with the declination \
             given is off by as much",
            verdict.todo
        );
    }
    verdict
}

/// The verdict from the heading figures alone.
fn judge_heading(h: &HeadingErrors, hints: &Hints) -> Verdict {
    let left = h.left.worst_deg;
    let grade = if left <= GOOD_DEG {
        Grade::Good
    } else if left <= USABLE_DEG {
        Grade::Usable
    } else {
        Grade::Redo
    };
    if grade == Grade::Good {
        return Verdict {
            grade,
            reason: format!(
                "{} of heading error left at worst (the raw readings were off by up to {})",
                fmt_deg(left),
                fmt_deg(h.before.worst_deg)
            ),
            todo: "check it on a second recording with magcal-apply".to_owned(),
        };
    }
    let unexplained_deg = (h.unexplained_ut / h.field.horizontal_ut).to_degrees();
    let misfit = if hints.vector {
        "the readings and the attitude reference disagree"
    } else {
        "the readings depart from a sphere"
    };
    let (reason, todo) = if unexplained_deg >= h.parameters_deg && hints.noise_unmeasured {
        (
            format!(
                "{} of heading error left: {misfit} by {:.2} µT, and the sensor's noise, which could not be measured \
                 (the rows change orientation from one to the next), may explain none of it",
                fmt_deg(left),
                h.unexplained_ut
            ),
            "record with the rows in time order at the sensor's rate (consecutive readings of one moving sensor), so \
             that its noise can be measured and told from the misfit"
                .to_owned(),
        )
    } else if unexplained_deg >= h.parameters_deg {
        let why = format!(
            "{} of heading error left: {misfit} by {:.2} µT more than the sensor's noise explains",
            fmt_deg(left),
            h.unexplained_ut
        );
        let todo = match hints.spans_s.first() {
            _ if hints.diagnosis_skipped => {
                "run the fit without --no-diagnose: the diagnosis finds what the model leaves out".to_owned()
            }
            Some(&(t0, t1)) => format!(
                "record again with magnets, metal and cables away from the sensor (the misfit is worst at {t0:.0}–{t1:.0} s{})",
                if hints.spans_s.len() > 1 {
                    format!(" and {} more spans", hints.spans_s.len() - 1)
                } else {
                    String::new()
                }
            ),
            None if hints.vector => {
                "check the attitude reference (its axes and timing against the sensor's, the local field), then \
                 record again away from magnets and metal"
                    .to_owned()
            }
            None => "record again away from magnets, metal and cables, turning the sensor slowly through every \
                     direction"
                .to_owned(),
        };
        (why, todo)
    } else if hints.excluded_share() >= EXCLUDED_NOT_LONGER {
        let excluded = hints.excluded_words();
        (
            format!(
                "{} of heading error left: the fit itself is uncertain ({:.0} % of the directions covered; the base \
                 fit left out {excluded} as grossly off)",
                fmt_deg(left),
                100.0 * hints.coverage
            ),
            format!(
                "record again with magnets, metal and cables away from the sensor rather than for longer: the base \
                 fit left out {excluded} (the notes below say when){}",
                if hints.vector {
                    "; if nothing magnetic was near, check the attitude reference there (its convention, axes and \
                     clock against the sensor's)"
                } else {
                    ""
                }
            ),
        )
    } else {
        (
            format!(
                "{} of heading error left: the fit itself is uncertain ({:.0} % of the directions covered)",
                fmt_deg(left),
                100.0 * hints.coverage
            ),
            "record again for longer, turning the sensor through every direction".to_owned(),
        )
    };
    Verdict {
        grade,
        reason,
        todo,
    }
}

/// The verdict when the local field's direction is unknown: `lower_bound_deg` is what is left with the whole field
/// horizontal (the least a compass can be off by).
pub fn judge_without_direction(lower_bound_deg: f64, hints: &Hints) -> Verdict {
    let todo =
        "give the local field: --location LAT,LON,ALT --date YYYY-MM-DD (or --field-ned N,E,D)"
            .to_owned();
    if lower_bound_deg > USABLE_DEG {
        return Verdict {
            grade: Grade::Redo,
            reason: format!(
                "at least {} of heading error left, whatever the local field",
                fmt_deg(lower_bound_deg)
            ),
            todo: if hints.vector {
                "record again away from magnets and metal, and check the attitude reference"
                    .to_owned()
            } else {
                "record again away from magnets, metal and cables, turning the sensor slowly through every direction"
                    .to_owned()
            },
        };
    }
    Verdict {
        grade: Grade::Usable,
        reason: "the heading error depends on the local field's inclination, which this recording does not give"
            .to_owned(),
        todo,
    }
}

/// The declination error the diagnosis found, degrees, when it exceeds [`GOOD_DEG`].
fn declination_off_deg(d: &Diagnosis) -> Option<f64> {
    d.effects.iter().find_map(|e| match e.effect {
        Effect::FieldDirectionError {
            declination_error_deg,
            ..
        } if declination_error_deg.abs() > GOOD_DEG => Some(declination_error_deg),
        _ => None,
    })
}

/// The declination a heading computed with the field given would be off by, degrees, when the reference's north was
/// found off true north by more than [`GOOD_DEG`] and not on magnetic north: the recording cannot tell a capture
/// volume turned from a declination given wrong ([`crate::reference_heading::declination_off_deg`]). Not for the
/// cube jig, whose edge is lined up by hand with whatever is at hand: its heading is the likely story, and the summary
/// names the other.
fn heading_off_deg(cal: &Calibration) -> Option<f64> {
    let h = cal.reference_heading.as_ref().filter(|h| !h.jig)?;
    crate::reference_heading::declination_off_deg(h, &cal.field).filter(|d| d.abs() > GOOD_DEG)
}

/// The magnitude of the field in the model's calibrated units, µT: the field vector's, the scalar fit's target, or
/// the mean of the expected field (`rx,ry,rz`).
fn model_field_ut(cal: &Calibration, rec: &Recording) -> Option<f64> {
    cal.fit.face().magnitude_ut().or_else(|| {
        cal.field.magnitude().or_else(|| {
            let r = rec.ref_ut.as_ref()?;
            let norms: Vec<f64> = r
                .iter()
                .map(|v| frames::norm(*v))
                .filter(|n| n.is_finite())
                .collect();
            (!norms.is_empty()).then(|| norms.iter().sum::<f64>() / norms.len() as f64)
        })
    })
}

/// The model an export or a device gets: the final model when it has no body-fixed corrections, the base fit
/// otherwise. A target that holds `A` and `b` only needs the best `A` and `b` without the corrections; the final
/// model's `A` and `b` were fitted together with them and, used alone, can leave far more (a nonlinearity absorbs
/// part of the scale).
pub fn target_model(cal: &Calibration) -> magcal_calib::Model {
    let model = cal.model();
    if model.corrections().count() > 0 {
        cal.base_model()
    } else {
        model
    }
}

/// Spans that cover less than this share of the recording are worth pointing at.
const SPAN_SHARE: f64 = 0.5;

/// The heading figures and verdict of a calibration of `rec`. With `linear_only` (the calibration goes to an export
/// or a device, which hold `A` and `b` only) and a final model with corrections, they are of the base fit: `A` and
/// `b` fitted without the corrections, with the residual they leave ([`target_model`]).
pub fn assess(cal: &Calibration, rec: &Recording, linear_only: bool) -> Assessment {
    let model = cal.model();
    // A noise that could not be measured explains none of the residual.
    let measured = |floor_ut: f64| if cal.noise_measured { floor_ut } else { 0.0 };
    let (residual_rms_ut, noise_floor_ut) = match &cal.diagnosis {
        Some(d) => (d.extended.rms_ut, measured(d.noise_floor_ut)),
        None => (cal.residual_rms_ut, measured(cal.noise_floor_ut)),
    };
    let hints = hints(cal, rec);
    let figures = Figures {
        uncertainty: FieldUncertainty::of(&cal.fit),
        magnitude_ut: model_field_ut(cal, rec).unwrap_or(f64::NAN),
        inclination_deg: cal.field.vector().map(|f| frames::field_angles(f).1),
    };
    let corrections = model.corrections().count();
    let without_corrections = (corrections > 0).then(|| {
        let base = cal.base_model();
        (
            corrections,
            figures.of(
                base.a,
                base.b_ut,
                cal.residual_rms_ut,
                measured(cal.noise_floor_ut),
            ),
        )
    });
    let linear_only = linear_only && without_corrections.is_some();
    let chosen = match (&without_corrections, linear_only) {
        (Some((_, f)), true) => f.clone(),
        _ => figures.of(model.a, model.b_ut, residual_rms_ut, noise_floor_ut),
    };
    let verdict = match &chosen {
        Ok(h) => judge(h, &hints),
        Err(lower_bound_deg) => judge_without_direction(*lower_bound_deg, &hints),
    };
    let verdict = overruled(verdict, cal, rec, &chosen);
    Assessment {
        heading: chosen.ok(),
        without_corrections: without_corrections.map(|(n, f)| (n, f.ok())),
        linear_only,
        verdict,
    }
}

/// What the verdict's advice can point at in a calibration of `rec`.
fn hints(cal: &Calibration, rec: &Recording) -> Hints {
    let spans_s: Vec<(f64, f64)> = cal.diagnosis.as_ref().map_or_else(Vec::new, |d| {
        d.located
            .segments
            .iter()
            .map(|s| (s.t0_s, s.t1_s))
            .collect()
    });
    let duration_s = rec.t_s.as_ref().map_or(0.0, |t| {
        t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0)
    });
    let covered: f64 = spans_s.iter().map(|(a, b)| b - a).sum();
    Hints {
        vector: cal.fit.is_vector(),
        spans_s: if covered < SPAN_SHARE * duration_s {
            spans_s
        } else {
            Vec::new()
        },
        coverage: cal.sphere_coverage,
        diagnosis_skipped: cal.diagnosis.is_none() && cal.diagnosis_failed.is_none(),
        noise_unmeasured: !cal.noise_measured,
        declination_off_deg: cal
            .diagnosis
            .as_ref()
            .and_then(declination_off_deg)
            .or_else(|| heading_off_deg(cal)),
        excluded: (
            cal.samples.excluded,
            cal.samples.used + cal.samples.excluded,
        ),
    }
}

/// What the heading figures of a model are taken with: the fit's uncertainty and the local field.
struct Figures {
    uncertainty: FieldUncertainty,
    /// The field's magnitude in the model's units, µT.
    magnitude_ut: f64,
    /// The field's inclination, when its direction is known, degrees.
    inclination_deg: Option<f64>,
}

impl Figures {
    /// The heading figures of the model `(a, b_ut)` leaving `residual_rms_ut` over a noise of `noise_floor_ut`; without
    /// the field's direction, the least error any field can give (all of it horizontal), degrees.
    fn of(
        &self,
        a: frames::Mat3,
        b_ut: [f64; 3],
        residual_rms_ut: f64,
        noise_floor_ut: f64,
    ) -> Result<HeadingErrors, f64> {
        let input = |field| HeadingInput {
            a,
            b_ut,
            field,
            uncertainty: Some(&self.uncertainty),
            residual_rms_ut,
            noise_floor_ut,
        };
        match self.inclination_deg {
            Some(inclination_deg) => Ok(heading_errors(&input(LocalField::new(
                inclination_deg,
                self.magnitude_ut,
            )))),
            None => Err(
                heading_errors(&input(LocalField::new(0.0, self.magnitude_ut)))
                    .left
                    .worst_deg,
            ),
        }
    }
}

/// The verdict the heading figures gave, overruled where they do not tell the story: a reference in another
/// convention or out of step, a mostly disturbed recording whose consistent part does not determine a calibration,
/// or a reference off by a good part of the field; a calibration of the state between two stretches
/// on another offset; a fit the last checks warn about.
fn overruled(
    mut verdict: Verdict,
    cal: &Calibration,
    rec: &Recording,
    chosen: &Result<HeadingErrors, f64>,
) -> Verdict {
    // A reference in another convention: its warning says what to try, not more recording.
    if let Some(b) = &cal.reference.convention {
        verdict = Verdict {
            grade: Grade::Redo,
            reason: format!(
                "the attitude reference explains {:.0} % of the readings read as {}, {:.0} % as the file gives it: \
                 the calibration is against a reference in the wrong convention",
                100.0 * b.better.explained,
                b.describe(),
                100.0 * b.given.explained
            ),
            todo: "rewrite the attitude (or the field) in magcal's convention (the WARNING below says how) and fit again"
                .to_owned(),
        };
    } else if let Some(o) = &cal.reference.offset {
        verdict = Verdict {
            grade: Grade::Redo,
            reason: format!(
                "the attitude reference explains {:.0} % of the readings shifted by {:+.0} ms, {:.0} % as the file \
                 gives it: the readings and the reference are out of step",
                100.0 * o.shifted.explained,
                1000.0 * o.offset_s,
                100.0 * o.given.explained
            ),
            todo: "put the readings and the reference on one clock (the WARNING below says by how much to shift) \
                   and fit again"
                .to_owned(),
        };
    } else if let Some(p) = &cal.reference.part {
        verdict = Verdict {
            grade: Grade::Redo,
            reason: format!(
                "only {:.0} % of the readings agree with the attitude reference under one calibration, and they do \
                 not determine it: the rest is disturbed",
                100.0 * p.share
            ),
            todo: "record again away from magnets and metal, turning through more directions (the WARNING below \
                   says when the readings agreed)"
                .to_owned(),
        };
    } else if verdict.grade != Grade::Good
        && let Some((rms_ut, field_ut)) = cal.fit.reference_off(&cal.field)
    {
        let left_deg = match chosen {
            Ok(h) => h.left.worst_deg,
            Err(lower_bound_deg) => *lower_bound_deg,
        };
        verdict.reason = format!(
            "{} of heading error left: the readings and the attitude reference disagree by {:.0} % of the field",
            fmt_deg(left_deg),
            100.0 * rms_ut / field_ut
        );
        "check the attitude reference's convention and timing: the WARNING below says what to try"
            .clone_into(&mut verdict.todo);
    }
    // A calibration of the state between two stretches on another offset is of something on the board.
    if verdict.grade != Grade::Redo
        && cal
            .diagnosis
            .as_ref()
            .is_some_and(|d| crate::calibrate::calibrated_state_in_between(d, rec))
    {
        verdict = Verdict {
            grade: Grade::Redo,
            reason: "the recording began and ended on another offset than the one calibrated: the calibration is \
                     most likely of something on the board while the sensor turned"
                .to_owned(),
            todo: "record again with nothing magnetic on or near the board (the WARNING below says when)"
                .to_owned(),
        };
    }
    // A fit the last checks warn about (units, gains, field range, a huge hard iron) is not good, whatever its
    // heading figures: the warning says what is wrong and what would fix it.
    if verdict.grade == Grade::Good && !cal.warnings.is_empty() {
        verdict = Verdict {
            grade: Grade::Usable,
            reason: format!(
                "{}, but the fit carries {} warning(s)",
                verdict.reason,
                cal.warnings.len()
            ),
            todo: "read the WARNING below: it says what looks wrong and what would fix it"
                .to_owned(),
        };
    } else if verdict.grade == Grade::Usable && !cal.warnings.is_empty() {
        verdict.reason = format!(
            "{}; the fit also carries {} warning(s): read them below",
            verdict.reason,
            cal.warnings.len()
        );
    }
    verdict
}
