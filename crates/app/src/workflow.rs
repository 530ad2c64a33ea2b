//! The fit workflow every tool runs, in one place: read the recording (as much of it as the fit needs), leave out
//! the rows a fault of the sensor's output made, calibrate (checks, the robust base fit, the diagnosis) and grade
//! the result (the heading figures and the verdict). `magcal` and `magcal-fit` call [`fit_file`]; `magcal-apply`
//! checks parameters already fitted with [`crate::apply::check`], which locates and leaves out the disturbed spans
//! the same way.

use std::path::Path;

use magcal_recording::Recording;

use crate::calibrate::{
    CalibrateError, attitude_worth_checking, calibrate, drop_faulty, read_to_calibrate,
};
use crate::field::{FieldArgs, resolve};
use crate::fit::{Calibration, Method};
use crate::flight::{LogOptions, is_flight_log, read_flight};
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
        /// Why.
        error: CalibrateError,
    },
}

/// Reads, calibrates and grades the recording at `path`: a magcal recording, or a flight log (`.ulg`, read by
/// [`read_flight`]).
///
/// Without the diagnosis the quaternions are turned into the expected field as the rows are read
/// ([`read_to_calibrate`]); a fit that looks off is then made again with them kept, and replaces the first if their
/// convention is not magcal's ([`attitude_worth_checking`]).
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
    let mut cal = match calibrate(&rec, request.method, field, request.diagnose) {
        Ok(cal) => cal,
        Err(error) => {
            return Err(NotFitted::Refused {
                rec: Box::new(rec),
                error,
            });
        }
    };
    if attitude_worth_checking(&cal, &rec) {
        let (mut full, field) = read_to_calibrate(path, request.method, true, |meta| {
            Ok(resolve(field_args, meta)?)
        })
        .map_err(NotFitted::Unread)?;
        let full_faulty = drop_faulty(&mut full);
        if let Ok(again) = calibrate(&full, request.method, field, false)
            && again.reference.convention.is_some()
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
