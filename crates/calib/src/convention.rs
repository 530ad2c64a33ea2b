//! Attitude references written in another convention than magcal's.
//!
//! magcal reads a quaternion `qw,qx,qy,qz` as the turn of the sensor's axes into the world's NED axes, and the field
//! in NED ([`crate::frames`]). Loggers also write the inverse turn (world into sensor), the scalar last (`x,y,z,w`
//! under magcal's names), or an ENU world. A constant turn or mirror between the sensor's axes and the reference's is
//! part of `A` and needs nothing; these are not constant, and a fit against them is no calibration. It is not always
//! plain to see: on a recording that turns slowly the robust fit finds stretches that the wrong reference happens to
//! match and leaves the rest out as "disturbed" (the BROAD recording with its quaternions inverted: 37 % left out,
//! 1.1 µT on the rest, and nine magnets that were never there).
//!
//! [`better_convention`] fits the readings (plain least squares, on a subsample) against the reference in each of
//! the eight combinations and says when one of them fits far better than the reference as given. On the physical
//! recordings the convention as given fits best by a factor of 2.2 or more (median misfit); with their quaternions
//! inverted, the inverse fits 3 times better.

use crate::frames;
use crate::vector::{self, VectorOptions};

/// How an attitude reference may have been written, against magcal's convention.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Convention {
    /// The quaternion turns the world's axes into the sensor's (the inverse of magcal's).
    pub inverse: bool,
    /// The columns `qw,qx,qy,qz` hold `x, y, z, w` (the scalar last).
    pub scalar_last: bool,
    /// The world is east-north-up, not north-east-down.
    pub enu: bool,
}

impl Convention {
    /// magcal's own convention.
    pub const MAGCAL: Convention = Convention {
        inverse: false,
        scalar_last: false,
        enu: false,
    };

    /// Every combination, magcal's first.
    pub fn all() -> impl Iterator<Item = Convention> {
        (0..8u8).map(|k| Convention {
            inverse: k & 1 != 0,
            scalar_last: k & 2 != 0,
            enu: k & 4 != 0,
        })
    }

    /// The quaternion and NED field magcal's convention takes for a file's `q` (as read, `qw,qx,qy,qz`) and
    /// `field_ned_ut`, if the file is in this convention.
    pub fn to_magcal(self, q: [f64; 4], field_ned_ut: [f64; 3]) -> ([f64; 4], [f64; 3]) {
        let [w, x, y, z] = if self.scalar_last {
            [q[3], q[0], q[1], q[2]]
        } else {
            q
        };
        let q = if self.inverse {
            [w, -x, -y, -z]
        } else {
            [w, x, y, z]
        };
        // A turn into ENU axes read as one into NED: the field it should meet is the NED field in ENU order.
        let [n, e, d] = field_ned_ut;
        let field = if self.enu { [e, n, -d] } else { field_ned_ut };
        (q, field)
    }

    /// What the convention is, in words (for a message: "read as …").
    pub fn describe(self) -> String {
        let mut parts = Vec::new();
        if self.inverse {
            parts.push("the inverse quaternion (turning the world's axes into the sensor's)");
        }
        if self.scalar_last {
            parts.push("the scalar last (the columns qw,qx,qy,qz holding x, y, z, w)");
        }
        if self.enu {
            parts.push("an east-north-up world");
        }
        if parts.is_empty() {
            "magcal's convention".to_owned()
        } else {
            parts.join(", with ")
        }
    }
}

/// How far the readings are from a reference under the best plain fit, µT (the norm of the residual per sample).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Misfit {
    /// Median.
    pub median_ut: f64,
    /// Root mean square.
    pub rms_ut: f64,
}

/// A convention that fits the readings far better than the reference as given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Better {
    /// The convention the reference fits far better in.
    pub convention: Convention,
    /// The misfit against the reference as given.
    pub given: Misfit,
    /// The misfit against the reference read in `convention`.
    pub better: Misfit,
}

/// Samples the conventions are compared on, at most (spread evenly over the recording).
pub const SAMPLES: usize = 20_000;

/// Another convention is reported when its median misfit is below this share of the given one's (and its RMS misfit
/// below the given one's: a disturbance in part of a recording weighs on both alike).
pub const BETTER_SHARE: f64 = 0.5;

/// The convention the readings `raw_ut` fit far better against than the attitude `quat` as given (with the world
/// field `field_ned_ut`), if there is one ([`BETTER_SHARE`]).
pub fn better_convention(
    raw_ut: &[[f64; 3]],
    quat: &[[f64; 4]],
    field_ned_ut: [f64; 3],
) -> Option<Better> {
    let usable: Vec<usize> = (0..raw_ut.len().min(quat.len()))
        .filter(|&i| raw_ut[i].iter().chain(&quat[i]).all(|v| v.is_finite()))
        .collect();
    let stride = usable.len().div_ceil(SAMPLES).max(1);
    let rows: Vec<usize> = usable.into_iter().step_by(stride).collect();
    let raw: Vec<[f64; 3]> = rows.iter().map(|&i| raw_ut[i]).collect();
    let misfit = |c: Convention| -> Option<Misfit> {
        let expected: Vec<[f64; 3]> = rows
            .iter()
            .map(|&i| {
                let (q, f) = c.to_magcal(quat[i], field_ned_ut);
                frames::expected_sensor_field(q, f)
            })
            .collect();
        let opts = VectorOptions {
            skip_coverage_check: true,
            estimates_only: true,
            ..VectorOptions::default()
        };
        let fit = vector::fit(&raw, &expected, &opts).ok()?;
        let mut norms: Vec<f64> = raw
            .iter()
            .zip(&expected)
            .map(|(m, e)| {
                let calibrated = frames::add(frames::mat_vec(&fit.a, *m), fit.b_ut);
                frames::norm(frames::sub(calibrated, *e))
            })
            .collect();
        let rms_ut = (norms.iter().map(|r| r * r).sum::<f64>() / norms.len() as f64).sqrt();
        let mid = norms.len() / 2;
        let median_ut = *norms.select_nth_unstable_by(mid, f64::total_cmp).1;
        Some(Misfit { median_ut, rms_ut })
    };
    let given = misfit(Convention::MAGCAL)?;
    Convention::all()
        .skip(1)
        .filter_map(|c| Some((c, misfit(c)?)))
        .filter(|(_, m)| m.median_ut < BETTER_SHARE * given.median_ut && m.rms_ut < given.rms_ut)
        .min_by(|a, b| a.1.median_ut.total_cmp(&b.1.median_ut))
        .map(|(convention, better)| Better {
            convention,
            given,
            better,
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// Readings of a sensor (gains, a hard iron, noise) turned through random attitudes, with the attitude as
    /// magcal reads it.
    fn recording(n: usize) -> (Vec<[f64; 3]>, Vec<[f64; 4]>, [f64; 3]) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let field = [19.0, 1.2, 45.0];
        let mut raw = Vec::new();
        let mut quat = Vec::new();
        for _ in 0..n {
            let q: [f64; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
            let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            let q = q.map(|v| v / norm);
            let e = frames::expected_sensor_field(q, field);
            raw.push(std::array::from_fn(|k| {
                1.05 * e[k] + [12.0, -7.0, 30.0][k] + rng.random_range(-0.3..0.3)
            }));
            quat.push(q);
        }
        (raw, quat, field)
    }

    #[test]
    fn every_convention_is_tried_once_and_magcals_is_the_identity() {
        let all: Vec<Convention> = Convention::all().collect();
        assert_eq!(all.len(), 8);
        assert_eq!(all[0], Convention::MAGCAL);
        for (k, c) in all.iter().enumerate() {
            assert!(!all[..k].contains(c));
        }
        let q = [0.5, -0.5, 0.5, 0.5];
        assert_eq!(
            Convention::MAGCAL.to_magcal(q, [1.0, 2.0, 3.0]),
            (q, [1.0, 2.0, 3.0])
        );
    }

    #[test]
    fn a_reference_in_magcals_convention_is_left_alone() {
        let (raw, quat, field) = recording(3000);
        assert_eq!(better_convention(&raw, &quat, field), None);
    }

    #[test]
    fn a_reference_written_in_another_convention_is_named() {
        let (raw, quat, field) = recording(3000);
        for c in Convention::all().skip(1) {
            // The file as a logger in convention `c` would have written it: undo what `to_magcal` does.
            let written: Vec<[f64; 4]> = quat
                .iter()
                .map(|&[w, x, y, z]| {
                    let [w, x, y, z] = if c.inverse {
                        [w, -x, -y, -z]
                    } else {
                        [w, x, y, z]
                    };
                    if c.scalar_last {
                        [x, y, z, w]
                    } else {
                        [w, x, y, z]
                    }
                })
                .collect();
            let [n, e, d] = field;
            let given_field = if c.enu { [e, n, -d] } else { field };
            let found = better_convention(&raw, &written, given_field)
                .unwrap_or_else(|| panic!("{c:?} not found"));
            assert_eq!(found.convention, c, "{}", c.describe());
            assert!(found.better.rms_ut < 0.5, "{:?}", found.better);
            assert!(found.given.rms_ut > 5.0, "{:?}", found.given);
        }
    }
}
