//! A recording's readings under a model: calibrated row by row, the expected field per row, and the noise floor in
//! calibrated units.

use std::borrow::Cow;

use magcal_calib::noise::{NoiseFloor, NoiseSource};
use magcal_calib::{Inputs, Model, frames};
use magcal_recording::Recording;
use rayon::prelude::*;

use crate::field::ReferenceField;

/// A recording without the reference a vector fit needs: why, in words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MissingReference(pub &'static str);

/// The expected field in sensor axes per sample (NaN where the reference is missing), if the recording has one:
/// its `rx,ry,rz` columns borrowed, or its attitude turned.
pub fn expected_field<'a>(
    rec: &'a Recording,
    field: &ReferenceField,
) -> Result<Cow<'a, [[f64; 3]]>, MissingReference> {
    if let Some(r) = &rec.ref_ut {
        return Ok(Cow::Borrowed(r));
    }
    let Some(q) = &rec.quat else {
        return Err(MissingReference("this recording has neither"));
    };
    let Some(f) = field.vector() else {
        return Err(MissingReference(
            "this recording has the attitude but no world field vector",
        ));
    };
    Ok(Cow::Owned(
        q.par_iter()
            .with_min_len(1 << 12)
            .map(|q| frames::expected_sensor_field(*q, f))
            .collect(),
    ))
}

/// Applies `model` to every row of `rec`.
pub fn calibrate_rows(model: &Model, rec: &Recording) -> Vec<[f64; 3]> {
    let mut currents = vec![0.0; rec.currents.len()];
    (0..rec.len())
        .map(|i| calibrate_row(model, rec, i, &mut currents))
        .collect()
}

/// `model` applied to row `i` of `rec`, with its time, temperature and currents (`currents`: room for them, one per
/// channel).
pub fn calibrate_row(model: &Model, rec: &Recording, i: usize, currents: &mut [f64]) -> [f64; 3] {
    for (c, ch) in currents.iter_mut().zip(&rec.currents) {
        *c = ch.values[i];
    }
    let inputs = Inputs {
        t_s: rec.t_s.as_ref().map_or(0.0, |t| t[i]),
        temp_c: rec.temp_c.as_ref().map_or(f64::NAN, |t| t[i]),
        currents_a: currents,
    };
    model.apply(rec.mag_ut[i], &inputs)
}

/// A noise floor from the readings' differences above the fit's residual by more than `1 / this` is not the noise:
/// the rows change orientation from one to the next, and the differences measure the rotation.
const UNMEASURED_NOISE_BOUND: f64 = 0.8;

/// Whether `floor_ut`, the noise the readings' differences give (calibrated units), can be the noise of a fit that
/// leaves `residual_ut` ([`UNMEASURED_NOISE_BOUND`]).
pub fn noise_measurable(floor_ut: f64, residual_ut: f64) -> bool {
    !(floor_ut > 0.0 && residual_ut < UNMEASURED_NOISE_BOUND * floor_ut)
}

/// The noise of |B| in calibrated units: the calibrated noise along the field direction, averaged over the
/// recording (at most ~10 000 readings looked at).
pub fn radial_floor_ut(noise: &NoiseFloor, model: &Model, raw_ut: &[[f64; 3]]) -> f64 {
    let f = noise.floor_ut;
    let stride = (raw_ut.len() / 10_000).max(1);
    let (sum, count) = raw_ut
        .iter()
        .step_by(stride)
        .map(|m| model.apply(*m, &Inputs::NONE))
        .filter(|b| b.iter().all(|v| v.is_finite()) && frames::norm(*b) > 0.0)
        .map(|b| {
            let u = frames::scale(b, 1.0 / frames::norm(b));
            let au = frames::mat_t_vec(&model.a, u);
            (0..3).map(|k| (au[k] * f[k]).powi(2)).sum::<f64>()
        })
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (sum / count.max(1) as f64).sqrt()
}

/// Where a noise figure came from, in words.
pub fn noise_source(noise: &NoiseFloor) -> String {
    match noise.source {
        NoiseSource::Poses { runs, dof } => {
            format!("the spread within {runs} poses ({dof} degrees of freedom)")
        }
        NoiseSource::Still { start, end } => format!("still segment, samples {start}–{end}"),
        NoiseSource::Differences { order, spacing: 1 } => format!("differences of order {order}"),
        NoiseSource::Differences { order, spacing } => format!(
            "differences of order {order}, their taps {spacing} samples apart (the noise is alike in neighbouring \
             samples)"
        ),
    }
}
