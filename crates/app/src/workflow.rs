//! The workflows the tools run, in one place. [`fit_file`] (`magcal`, `magcal-fit`, `magcal-batch`): read the
//! recording (as much of it as the fit needs), leave out the rows a fault of the sensor's output made, calibrate
//! (checks, the robust base fit, the diagnosis) and grade the result (the heading figures and the verdict).
//! [`check_file`] (`magcal-apply`): read a parameters file and a recording, and check the parameters on it
//! ([`crate::apply::check`]: the disturbed spans located and left out as a fit leaves them out, then graded).

use std::path::Path;

use magcal_recording::Recording;

use crate::apply::{Check, check};
use crate::calibrate::{
    CalibrateError, attitude_worth_checking, calibrate_with, drop_faulty, read_to_calibrate,
};
use crate::field::ReferenceField;
use crate::field::{FieldArgs, resolve};
use crate::fit::{Calibration, Method};
use crate::flight::{LogOptions, is_flight_log, read_flight};
use crate::params::{ParamsError, ParamsFile};
use crate::units::ChipOption;
use crate::verdict::{Assessment, assess};

/// What a fit is asked for.
#[derive(Clone, Debug)]
pub struct FitRequest<'a> {
    /// The method (auto: vector with an attitude reference, scalar otherwise).
    pub method: Method,
    /// Whether to diagnose what the base model leaves out.
    pub diagnose: bool,
    /// The world field as given on the command line (else the recording's metadata says it).
    pub field: &'a FieldArgs,
    /// Whether the result goes to a target that holds `A` and `b` only (an export or a device): the verdict is then
    /// of the base fit ([`crate::verdict::target_model`]).
    pub linear_only: bool,
    /// The chip whose raw counts the readings are, when the user says (`--chip`): see [`crate::units`].
    pub chip: Option<ChipOption>,
    /// For a flight log: which magnetometer.
    pub log: LogOptions,
}

/// A recording fitted and graded.
#[derive(Debug)]
pub struct Fitted {
    /// The recording as fitted (the faulty rows left out).
    pub rec: Recording,
    /// The calibration.
    pub cal: Calibration,
    /// Its heading figures and verdict.
    pub assessment: Assessment,
}

/// Why a recording was not fitted.
#[derive(Debug)]
pub enum NotFitted {
    /// It could not be read, or its field not resolved.
    Unread(anyhow::Error),
    /// It was read, and refused: the recording is there to show (a refused fit still shows its readings).
    Refused {
        /// The recording as read (the faulty rows left out).
        rec: Box<Recording>,
        /// Why (boxed: the refusal is the rare path, and `fit_file`'s result stays small).
        error: Box<CalibrateError>,
    },
}

/// Reads, calibrates and grades the recording at `path`: a magcal recording, or a flight log (`.ulg`, read by
/// [`read_flight`]).
///
/// Without the diagnosis the quaternions are turned into the expected field as the rows are read
/// ([`read_to_calibrate`]); a fit that looks off is then made again with them kept, and replaces the first if their
/// convention is not magcal's or their north is not true north ([`attitude_worth_checking`],
/// [`crate::reference_heading`]).
pub fn fit_file(path: &Path, request: &FitRequest<'_>) -> Result<Fitted, NotFitted> {
    let field_args = request.field;
    let (mut rec, field) = if is_flight_log(path) {
        let input = read_flight(path, &request.log, field_args).map_err(NotFitted::Unread)?;
        (input.rec, input.field)
    } else {
        read_to_calibrate(path, request.method, request.diagnose, |meta| {
            Ok(resolve(field_args, meta)?)
        })
        .map_err(NotFitted::Unread)?
    };
    let mut faulty = drop_faulty(&mut rec);
    let chip = request.chip.as_ref();
    let mut cal = match calibrate_with(&rec, request.method, field, request.diagnose, chip) {
        Ok(cal) => cal,
        Err(error) => {
            return Err(NotFitted::Refused {
                rec: Box::new(rec),
                error: Box::new(error),
            });
        }
    };
    if attitude_worth_checking(&cal, &rec) {
        let (mut full, field) = read_to_calibrate(path, request.method, true, |meta| {
            Ok(resolve(field_args, meta)?)
        })
        .map_err(NotFitted::Unread)?;
        let full_faulty = drop_faulty(&mut full);
        if let Ok(again) = calibrate_with(&full, request.method, field, false, chip)
            && (again.reference.convention.is_some() || again.reference_heading.is_some())
        {
            (rec, cal, faulty) = (full, again, full_faulty);
        }
    }
    cal.warnings.extend(faulty);
    let assessment = assess(&cal, &rec, request.linear_only);
    Ok(Fitted {
        rec,
        cal,
        assessment,
    })
}

/// A parameters file checked on a recording.
#[derive(Debug)]
pub struct Checked {
    /// The parameters.
    pub params: ParamsFile,
    /// The recording, as read.
    pub rec: Recording,
    /// The world field it was checked against.
    pub field: ReferenceField,
    /// The check.
    pub check: Check,
}

/// Reads the parameters file at `params` and the recording at `path` and checks the one on the other, against the
/// world field `field_args` gives (or the recording's metadata). Corrections tied to a recording's clock hold only
/// on the recording they were fitted on, recognised by its file name.
pub fn check_file(params: &Path, path: &Path, field_args: &FieldArgs) -> anyhow::Result<Checked> {
    let params_file = ParamsFile::read(params).map_err(swapped_hint)?;
    let rec = Recording::read(path)?;
    let field = resolve(field_args, &rec.meta)?;
    let fitted_on_it = params_file
        .recording
        .as_deref()
        .map(|r| Path::new(r).file_name())
        == Some(path.file_name());
    let check = check(&params_file, &rec, &field, fitted_on_it).map_err(|e| {
        anyhow::anyhow!("{}: cannot apply {}: {e}", path.display(), params.display())
    })?;
    Ok(Checked {
        params: params_file,
        rec,
        field,
        check,
    })
}

/// A recording given where the parameters go, with the order of the arguments; other errors as they are.
fn swapped_hint(e: ParamsError) -> anyhow::Error {
    match e {
        ParamsError::Recording { .. } => anyhow::anyhow!(
            "{e}: the parameters come first (magcal-apply PARAMS.toml RECORDING.csv)"
        ),
        e => e.into(),
    }
}
