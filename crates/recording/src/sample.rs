//! One row of a recording as owned values ([`Sample`]) and the rules every row obeys.

use crate::layout::Flags;
use crate::limits::{self, Limit};

use crate::limits::QUAT_NORM_TOLERANCE;

/// One row of a recording, owned. NaN marks a value that is absent (no such column, or missing in this row);
/// a group (`quat`, `ref_ut`, `gyro_rad_s`) with any NaN component is missing as a whole.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Time, s.
    pub t_s: f64,
    /// Magnetic field in sensor axes, µT. Must be finite.
    pub mag_ut: [f64; 3],
    /// Temperature, °C.
    pub temp_c: f64,
    /// Attitude quaternion `[w, x, y, z]` rotating sensor-frame vectors into NED.
    pub quat: [f64; 4],
    /// Expected field in sensor axes, µT.
    pub ref_ut: [f64; 3],
    /// Angular rate in sensor axes, rad/s.
    pub gyro_rad_s: [f64; 3],
    /// One value per current channel of the layout, A.
    pub currents_a: Vec<f64>,
    /// One value per extra column of the layout, as text.
    pub extra: Vec<String>,
}

impl Default for Sample {
    /// Every value absent (NaN), no currents, no extra columns.
    fn default() -> Sample {
        Sample {
            t_s: f64::NAN,
            mag_ut: [f64::NAN; 3],
            temp_c: f64::NAN,
            quat: [f64::NAN; 4],
            ref_ut: [f64::NAN; 3],
            gyro_rad_s: [f64::NAN; 3],
            currents_a: Vec::new(),
            extra: Vec::new(),
        }
    }
}

/// Why a sample cannot be added to a recording or written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SampleError {
    /// A magnetic field component is NaN or infinite.
    #[error("magnetic field must be finite, got {0:?}")]
    NonFiniteMag([f64; 3]),
    /// The layout has `t` and the sample's `t_s` is NaN or infinite.
    #[error("t must be finite, got {0}")]
    NonFiniteTime(f64),
    /// `t_s` is smaller than in the previous sample.
    #[error("t goes backwards: {t_s} s after {previous_s} s")]
    TimeBackwards {
        /// `t_s` of the previous sample.
        previous_s: f64,
        /// `t_s` of this sample.
        t_s: f64,
    },
    /// A complete quaternion whose norm is outside 1 ± 0.01.
    #[error("quaternion far from unit length: |q| = {norm}")]
    QuatNotUnit {
        /// The quaternion's norm.
        norm: f64,
    },
    /// An optional channel holds an infinite value (NaN is how a missing value is written).
    #[error("infinite value in {0}")]
    Infinite(String),
    /// A finite value beyond what its column holds (see [`crate::limits`]).
    #[error("{what} = {value:e} is out of range (at most ±{limit:e} {unit})")]
    OutOfRange {
        /// The column or group.
        what: String,
        /// The value.
        value: f64,
        /// The largest magnitude allowed.
        limit: f64,
        /// Its unit.
        unit: &'static str,
    },
    /// The number of currents differs from the layout's.
    #[error("{found} currents for a layout with {expected}")]
    CurrentCount {
        /// Current channels in the layout.
        expected: usize,
        /// Currents in the sample.
        found: usize,
    },
    /// The number of extra values differs from the layout's.
    #[error("{found} extra values for a layout with {expected} extra columns")]
    ExtraCount {
        /// Extra columns in the layout.
        expected: usize,
        /// Extra values in the sample.
        found: usize,
    },
}

/// The fixed-size values of a row, shared by [`Sample`] and [`crate::Row`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Core {
    pub t_s: f64,
    pub mag_ut: [f64; 3],
    pub temp_c: f64,
    pub quat: [f64; 4],
    pub ref_ut: [f64; 3],
    pub gyro_rad_s: [f64; 3],
}

impl Sample {
    pub(crate) fn core(&self) -> Core {
        Core {
            t_s: self.t_s,
            mag_ut: self.mag_ut,
            temp_c: self.temp_c,
            quat: self.quat,
            ref_ut: self.ref_ut,
            gyro_rad_s: self.gyro_rad_s,
        }
    }
}

/// The quaternion scaled to unit length, or its norm if that is outside 1 ± [`QUAT_NORM_TOLERANCE`].
pub(crate) fn normalise_quat(q: [f64; 4]) -> Result<[f64; 4], f64> {
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if (norm - 1.0).abs() <= QUAT_NORM_TOLERANCE {
        Ok(q.map(|v| v / norm))
    } else {
        Err(norm)
    }
}

/// A group with any NaN component is missing as a whole.
pub(crate) fn group_or_nan<const N: usize>(g: [f64; N]) -> [f64; N] {
    if g.iter().any(|v| v.is_nan()) {
        [f64::NAN; N]
    } else {
        g
    }
}

/// Checks a row against the rules of the format and returns it as it is stored and written: quaternion
/// normalised, groups with a missing component entirely NaN, channels absent from the layout NaN.
/// `previous_t_s` is `t` of the row before, if any.
/// `current_names` and `n_extra` are those of the layout, `currents_a` and `extra_len` those of the row.
pub(crate) fn check_row<'n>(
    layout: Flags,
    previous_t_s: Option<f64>,
    core: &Core,
    currents_a: impl ExactSizeIterator<Item = f64>,
    current_names: impl ExactSizeIterator<Item = &'n str>,
    extra_len: usize,
    n_extra: usize,
) -> Result<Core, SampleError> {
    if !core.mag_ut.iter().all(|v| v.is_finite()) {
        return Err(SampleError::NonFiniteMag(core.mag_ut));
    }
    let in_range = |what: &str, values: &[f64], limit: Limit| match values
        .iter()
        .find(|v| limit.exceeded_by(**v))
    {
        Some(&value) => Err(SampleError::OutOfRange {
            what: what.to_owned(),
            value,
            limit: limit.max,
            unit: limit.unit,
        }),
        None => Ok(()),
    };
    in_range("mx,my,mz", &core.mag_ut, limits::FIELD)?;
    let mut out = Core {
        t_s: f64::NAN,
        mag_ut: core.mag_ut,
        temp_c: f64::NAN,
        quat: [f64::NAN; 4],
        ref_ut: [f64::NAN; 3],
        gyro_rad_s: [f64::NAN; 3],
    };
    if layout.t {
        if !core.t_s.is_finite() {
            return Err(SampleError::NonFiniteTime(core.t_s));
        }
        if let Some(previous_s) = previous_t_s
            && core.t_s < previous_s
        {
            return Err(SampleError::TimeBackwards {
                previous_s,
                t_s: core.t_s,
            });
        }
        in_range("t", &[core.t_s], limits::TIME)?;
        out.t_s = core.t_s;
    }
    let infinite = |name: &str| SampleError::Infinite(name.to_owned());
    if layout.temp {
        if core.temp_c.is_infinite() {
            return Err(infinite("temp"));
        }
        in_range("temp", &[core.temp_c], limits::TEMP)?;
        out.temp_c = core.temp_c;
    }
    if layout.quat {
        let q = group_or_nan(core.quat);
        if !q[0].is_nan() {
            out.quat = normalise_quat(q).map_err(|norm| SampleError::QuatNotUnit { norm })?;
        }
    }
    if layout.reference {
        if core.ref_ut.iter().any(|v| v.is_infinite()) {
            return Err(infinite("rx,ry,rz"));
        }
        in_range("rx,ry,rz", &core.ref_ut, limits::FIELD)?;
        out.ref_ut = group_or_nan(core.ref_ut);
    }
    if layout.gyro {
        if core.gyro_rad_s.iter().any(|v| v.is_infinite()) {
            return Err(infinite("gx,gy,gz"));
        }
        in_range("gx,gy,gz", &core.gyro_rad_s, limits::GYRO)?;
        out.gyro_rad_s = group_or_nan(core.gyro_rad_s);
    }
    if currents_a.len() != current_names.len() {
        return Err(SampleError::CurrentCount {
            expected: current_names.len(),
            found: currents_a.len(),
        });
    }
    for (value, name) in currents_a.zip(current_names) {
        if value.is_infinite() {
            return Err(infinite(name));
        }
        in_range(name, &[value], limits::CURRENT)?;
    }
    if extra_len != n_extra {
        return Err(SampleError::ExtraCount {
            expected: n_extra,
            found: extra_len,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::Layout;

    fn layout() -> Layout {
        Layout {
            t: true,
            temp: true,
            quat: true,
            currents: vec!["i_a".into()],
            ..Layout::default()
        }
    }

    fn sample() -> Sample {
        Sample {
            t_s: 1.0,
            mag_ut: [1.0, 2.0, 3.0],
            temp_c: 20.0,
            quat: [1.005, 0.0, 0.0, 0.0],
            currents_a: vec![0.5],
            ..Sample::default()
        }
    }

    fn check(s: &Sample, previous: Option<f64>) -> Result<Core, SampleError> {
        let l = layout();
        let names = l.currents.iter().map(String::as_str);
        check_row(
            l.flags(),
            previous,
            &s.core(),
            s.currents_a.iter().copied(),
            names,
            s.extra.len(),
            0,
        )
    }

    #[test]
    fn valid_rows_are_normalised() {
        let out = check(&sample(), Some(1.0)).unwrap();
        assert_eq!(out.quat, [1.0, 0.0, 0.0, 0.0]);
        assert!(out.ref_ut.iter().all(|v| v.is_nan()));
        let mut s = sample();
        s.quat[2] = f64::NAN;
        assert!(check(&s, None).unwrap().quat.iter().all(|v| v.is_nan()));
    }

    #[test]
    fn invalid_rows_are_rejected() {
        let mut s = sample();
        s.mag_ut[1] = f64::INFINITY;
        assert!(matches!(check(&s, None), Err(SampleError::NonFiniteMag(_))));
        assert!(matches!(
            check(&sample(), Some(1.5)),
            Err(SampleError::TimeBackwards { .. })
        ));
        let mut s = sample();
        s.t_s = f64::NAN;
        assert!(matches!(
            check(&s, None),
            Err(SampleError::NonFiniteTime(_))
        ));
        let mut s = sample();
        s.quat = [0.9, 0.0, 0.0, 0.0];
        assert!(matches!(
            check(&s, None),
            Err(SampleError::QuatNotUnit { .. })
        ));
        let mut s = sample();
        s.temp_c = f64::NEG_INFINITY;
        assert!(matches!(check(&s, None), Err(SampleError::Infinite(_))));
        let mut s = sample();
        s.mag_ut[2] = 1e308;
        let e = check(&s, None).unwrap_err();
        assert!(
            matches!(e, SampleError::OutOfRange { ref what, .. } if what == "mx,my,mz"),
            "{e}"
        );
        let mut s = sample();
        s.currents_a[0] = -2e6;
        assert!(
            matches!(check(&s, None), Err(SampleError::OutOfRange { ref what, .. }) if what == "i_a")
        );
        let mut s = sample();
        s.currents_a.push(1.0);
        assert!(matches!(
            check(&s, None),
            Err(SampleError::CurrentCount {
                expected: 1,
                found: 2
            })
        ));
        let mut s = sample();
        s.extra.push("x".into());
        assert!(matches!(
            check(&s, None),
            Err(SampleError::ExtraCount {
                expected: 0,
                found: 1
            })
        ));
    }
}
