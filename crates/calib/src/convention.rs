//! Attitude references written in another convention than magcal's, or out of step with the readings.
//!
//! magcal reads a quaternion `qw,qx,qy,qz` as the turn of the sensor's axes into the world's NED axes, and the field
//! in NED ([`crate::frames`]). Loggers also write the inverse turn (world into sensor), the scalar last (`x,y,z,w`
//! under magcal's names), or an ENU or NWU world. A constant turn or mirror between the sensor's axes and the
//! reference's is part of `A` and needs nothing; these are not constant, and a fit against them is no calibration. It
//! is not always plain to see: on a recording that turns slowly the robust fit finds stretches that the wrong
//! reference happens to match and leaves the rest out as "disturbed" (the BROAD recording with its quaternions
//! inverted: 37 % left out, 1.1 µT on the rest, and nine magnets that were never there).
//!
//! [`better_convention`] fits the readings (trimmed least squares, on a subsample) against the reference in each of
//! the sixteen combinations (a field given with its vertical reversed among them: the fix is the same, and where the
//! field has no east component it cannot be told from a north-west-up world) and says when one of them explains
//! far more of the recording than the reference as given ([`EXPLAINED_MORE`]). Explained, not merely fitted: a
//! disturbance drags a plain fit, and one of a wrong convention can then come out with the smaller median misfit (on
//! BROAD 02 with 250 µT in the room for a sixth of it, twice as small), while a trimmed fit in the right convention
//! explains all but the disturbed part.

use crate::frames;
use crate::robust::median;
use crate::vector::{self, VectorOptions};

/// The world axes a quaternion turns the sensor's into, or the field given against them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum World {
    /// North-east-down, magcal's.
    #[default]
    Ned,
    /// East-north-up (Android's rotation vector, ROS).
    Enu,
    /// North-west-up (some AHRS filters).
    Nwu,
    /// North-east-down axes, but the field given with its vertical component reversed (up taken as positive).
    FieldUp,
}

impl World {
    const ALL: [World; 4] = [World::Ned, World::Enu, World::Nwu, World::FieldUp];

    /// Its name in reports: `ned`, `enu`, `nwu`, `field_up`.
    pub fn as_str(self) -> &'static str {
        match self {
            World::Ned => "ned",
            World::Enu => "enu",
            World::Nwu => "nwu",
            World::FieldUp => "field_up",
        }
    }

    /// The field a turn into these axes, read as one into NED, should meet: the NED field in these axes.
    fn field(self, [n, e, d]: [f64; 3]) -> [f64; 3] {
        match self {
            World::Ned => [n, e, d],
            World::Enu => [e, n, -d],
            World::Nwu => [n, -e, -d],
            World::FieldUp => [n, e, -d],
        }
    }
}

/// How an attitude reference may have been written, against magcal's convention.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Convention {
    /// The quaternion turns the world's axes into the sensor's (the inverse of magcal's).
    pub inverse: bool,
    /// The columns `qw,qx,qy,qz` hold `x, y, z, w` (the scalar last).
    pub scalar_last: bool,
    /// The world's axes.
    pub world: World,
}

impl Convention {
    /// magcal's own convention.
    pub const MAGCAL: Convention = Convention {
        inverse: false,
        scalar_last: false,
        world: World::Ned,
    };

    /// Every combination, magcal's first.
    pub fn all() -> impl Iterator<Item = Convention> {
        World::ALL.into_iter().flat_map(|world| {
            (0..4u8).map(move |k| Convention {
                inverse: k & 1 != 0,
                scalar_last: k & 2 != 0,
                world,
            })
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
        (q, self.world.field(field_ned_ut))
    }

    /// What a file in this convention holds for magcal's quaternion `q` and NED field `field_ned_ut` (the inverse
    /// of [`Convention::to_magcal`]).
    pub fn written(self, q: [f64; 4], field_ned_ut: [f64; 3]) -> ([f64; 4], [f64; 3]) {
        let [w, x, y, z] = if self.inverse {
            [q[0], -q[1], -q[2], -q[3]]
        } else {
            q
        };
        let q = if self.scalar_last {
            [x, y, z, w]
        } else {
            [w, x, y, z]
        };
        // Each world's field is its own inverse (a half turn, or a reflection).
        (q, self.world.field(field_ned_ut))
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
        match self.world {
            World::Ned => {}
            World::Enu => parts.push("an east-north-up world"),
            World::Nwu => parts.push("a north-west-up world"),
            World::FieldUp => {
                parts.push("the field's vertical component reversed (given up-positive)")
            }
        }
        if parts.is_empty() {
            "magcal's convention".to_owned()
        } else {
            parts.join(", with ")
        }
    }
}

/// How well the readings fit a reference under a trimmed least-squares fit (each pass refitted on the samples within
/// [`TRIM_MEDIANS`] times the median residual of the one before).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Misfit {
    /// The median residual (its norm per sample), µT.
    pub median_ut: f64,
    /// The share of the samples within [`EXPLAINED_SCALES`] times the smallest median of the references compared
    /// (conventions, or shifts in time): the part of the recording the reference explains.
    pub explained: f64,
}

/// A convention that fits the readings far better than the reference as given.
#[derive(Clone, Debug, PartialEq)]
pub struct Better {
    /// The convention the reference fits best in.
    pub convention: Convention,
    /// Others it fits about as well in (median misfit within [`TIE_SHARE`] of the best): the recording cannot tell
    /// them apart (a north-west-up world and a reversed vertical field where the field has no east component).
    pub also: Vec<Convention>,
    /// The misfit against the reference as given.
    pub given: Misfit,
    /// The misfit against the reference read in `convention`.
    pub better: Misfit,
}

impl Better {
    /// The convention in words, with those it fits about as well in.
    pub fn describe(&self) -> String {
        let mut text = self.convention.describe();
        for c in &self.also {
            text += &format!(" (or, as well, {})", c.describe());
        }
        text
    }
}

/// Samples the conventions are compared on, at most (spread evenly over the recording).
pub const SAMPLES: usize = 20_000;
/// Refits of the trimmed fit after the first.
pub const TRIM_PASSES: usize = 3;
/// Each refit keeps the samples within this many times the median residual.
pub const TRIM_MEDIANS: f64 = 2.0;
/// A sample is explained by a reference within this many times the smallest median misfit.
pub const EXPLAINED_SCALES: f64 = 3.0;
/// Another convention is reported when it explains this much more of the recording than the reference as given
/// (and its median misfit is smaller). On the physical recordings as given no other convention explains as much as
/// magcal's, nor on BROAD 02 with fields of 180–280 µT added for a sixth to a fifth of it; with 250 µT on the board
/// for 45 % of it (where the robust fit itself fails) one explains 0.01 more. Written in another convention, the
/// right one explains 0.29 to 0.97 more.
pub const EXPLAINED_MORE: f64 = 0.15;
/// Conventions whose median misfit is within this share of the best one's are named with it.
pub const TIE_SHARE: f64 = 1.1;

/// The convention the readings `raw_ut` fit far better against than the attitude `quat` as given (with the world
/// field `field_ned_ut`), if there is one ([`EXPLAINED_MORE`]). Every trimmed fit starts from the samples `start`
/// keeps, when given: those a robust fit against the reference as given kept. A field of hundreds of µT on the board
/// for a fifth of the recording drags a fit from all samples so far that trimming does not recover (on BROAD 02 the
/// reference as given then explained 53 % of it, a wrong convention 69 %); from the robust fit's samples, the right
/// convention fits them as it fits the rest, and a wrong one does not.
pub fn better_convention(
    raw_ut: &[[f64; 3]],
    quat: &[[f64; 4]],
    field_ned_ut: [f64; 3],
    start: Option<&[bool]>,
) -> Option<Better> {
    let usable: Vec<usize> = (0..raw_ut.len().min(quat.len()))
        .filter(|&i| raw_ut[i].iter().chain(&quat[i]).all(|v| v.is_finite()))
        .collect();
    let stride = usable.len().div_ceil(SAMPLES).max(1);
    let rows: Vec<usize> = usable.into_iter().step_by(stride).collect();
    let raw: Vec<[f64; 3]> = rows.iter().map(|&i| raw_ut[i]).collect();
    let kept: Vec<bool> = rows.iter().map(|&i| start.is_none_or(|k| k[i])).collect();
    // The residuals' norms of a trimmed fit against the reference in convention `c`.
    let residuals = |c: Convention| -> Option<Vec<f64>> {
        let expected: Vec<[f64; 3]> = rows
            .iter()
            .map(|&i| {
                let (q, f) = c.to_magcal(quat[i], field_ned_ut);
                frames::expected_sensor_field(q, f)
            })
            .collect();
        trimmed_residuals(&raw, &expected, kept.clone())
    };
    let all: Vec<(Convention, Vec<f64>)> = Convention::all()
        .filter_map(|c| Some((c, residuals(c)?)))
        .collect();
    let (given_convention, given) = all.first()?;
    if *given_convention != Convention::MAGCAL {
        return None;
    }
    let scale = smallest_median(all.iter().map(|(_, r)| r));
    let misfit = |r: &[f64]| Misfit::of(r, scale);
    let given = misfit(given);
    let mut better: Vec<(Convention, Misfit)> = all[1..]
        .iter()
        .map(|(c, r)| (*c, misfit(r)))
        .filter(|(_, m)| {
            m.explained >= given.explained + EXPLAINED_MORE && m.median_ut < given.median_ut
        })
        .collect();
    better.sort_by(|a, b| a.1.median_ut.total_cmp(&b.1.median_ut));
    let (&(convention, best), rest) = better.split_first()?;
    Some(Better {
        convention,
        also: rest
            .iter()
            .filter(|(_, m)| m.median_ut <= TIE_SHARE * best.median_ut)
            .map(|(c, _)| *c)
            .collect(),
        given,
        better: best,
    })
}

impl Misfit {
    /// The misfit of the residual norms `r` when the best reference's median is `scale`.
    fn of(r: &[f64], scale: f64) -> Misfit {
        Misfit {
            median_ut: median(r),
            explained: r.iter().filter(|e| **e <= EXPLAINED_SCALES * scale).count() as f64
                / r.len() as f64,
        }
    }
}

/// The residuals' norms (µT) of `raw` against `expected` under a trimmed fit ([`TRIM_PASSES`], [`TRIM_MEDIANS`])
/// that starts from the samples `kept`; `None` if a fit cannot be made.
fn trimmed_residuals(
    raw: &[[f64; 3]],
    expected: &[[f64; 3]],
    mut kept: Vec<bool>,
) -> Option<Vec<f64>> {
    let mut norms = Vec::new();
    for _ in 0..=TRIM_PASSES {
        let opts = VectorOptions {
            skip_coverage_check: true,
            estimates_only: true,
            kept: Some(&kept),
            ..VectorOptions::default()
        };
        let fit = vector::fit(raw, expected, &opts).ok()?;
        norms = raw
            .iter()
            .zip(expected)
            .map(|(m, e)| {
                let calibrated = frames::add(frames::mat_vec(&fit.a, *m), fit.b_ut);
                frames::norm(frames::sub(calibrated, *e))
            })
            .collect();
        let limit = TRIM_MEDIANS * median(&norms);
        kept = norms.iter().map(|r| *r <= limit).collect();
    }
    Some(norms)
}

/// The smallest median of the references' residual norms: the scale of [`Misfit::explained`].
fn smallest_median<'a>(residuals: impl Iterator<Item = &'a Vec<f64>>) -> f64 {
    residuals.map(|r| median(r)).fold(f64::INFINITY, f64::min)
}

/// Readings and a reference out of step: the readings late against the reference by `offset_s` (negative: early),
/// as when two streams were logged on different clocks and merged by their time stamps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutOfStep {
    /// How late the readings are against the reference, s (the sign of the diagnosis' `time_lag`).
    pub offset_s: f64,
    /// The misfit against the reference as given.
    pub given: Misfit,
    /// The misfit against the reference shifted by `offset_s`.
    pub shifted: Misfit,
}

/// Offsets searched, s either way.
pub const OFFSET_RANGE_S: f64 = 5.0;
/// The coarse search's step, s (or the sampling's, if longer); the best coarse offset is refined by samples.
pub const OFFSET_STEP_S: f64 = 0.1;
/// Samples the offsets are compared on, at most (fewer than the conventions': there are a hundred offsets and more).
pub const OFFSET_SAMPLES: usize = 2_000;
/// Offsets below this are the diagnosis' `time_lag`, which models them in the final fit (it found 162 ms where the
/// reference of BROAD 02 was moved 147 ms ahead); from 250 ms on it took them for a filter's delay on each axis
/// (`rate_coupling`, three delays within 2 ms of each other) and the fit was graded redo for want of directions.
pub const MIN_OFFSET_S: f64 = 0.2;

/// The offset between the readings `raw_ut` and the reference `expected_ut` (per sample, at times `t_s`) at which the
/// reference explains [`EXPLAINED_MORE`] more of the readings than as given, if it is [`MIN_OFFSET_S`] or more. The
/// samples are taken to be evenly spaced (the median step); each trimmed fit starts from the samples `start` keeps.
pub fn clock_offset(
    raw_ut: &[[f64; 3]],
    expected_ut: &[[f64; 3]],
    t_s: &[f64],
    start: Option<&[bool]>,
) -> Option<OutOfStep> {
    let n = raw_ut.len().min(expected_ut.len()).min(t_s.len());
    let steps: Vec<f64> = t_s[..n]
        .windows(2)
        .step_by((n / OFFSET_SAMPLES).max(1))
        .map(|w| w[1] - w[0])
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    let step_s = median(&steps);
    if step_s.is_nan() || step_s <= 0.0 {
        return None;
    }
    let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
    let usable: Vec<usize> = (0..n)
        .filter(|&i| finite(&raw_ut[i]) && finite(&expected_ut[i]))
        .collect();
    let stride = usable.len().div_ceil(OFFSET_SAMPLES).max(1);
    let rows: Vec<usize> = usable.into_iter().step_by(stride).collect();
    // The readings' rows paired with the reference `k` rows on (NaN past either end).
    let residuals = |k: isize| -> Option<Vec<f64>> {
        let paired: Vec<usize> = rows
            .iter()
            .copied()
            .filter(|&i| {
                i.checked_add_signed(k)
                    .is_some_and(|j| j < n && finite(&expected_ut[j]))
            })
            .collect();
        let raw: Vec<[f64; 3]> = paired.iter().map(|&i| raw_ut[i]).collect();
        let expected: Vec<[f64; 3]> = paired
            .iter()
            .map(|&i| expected_ut[i.wrapping_add_signed(k)])
            .collect();
        let kept = paired.iter().map(|&i| start.is_none_or(|s| s[i])).collect();
        trimmed_residuals(&raw, &expected, kept)
    };
    let coarse = (OFFSET_STEP_S / step_s).round().max(1.0) as isize;
    let reach = (OFFSET_RANGE_S / step_s).round() as isize;
    let mut shifts: Vec<(isize, Vec<f64>)> = (-reach / coarse..=reach / coarse)
        .filter_map(|c| Some((c * coarse, residuals(c * coarse)?)))
        .collect();
    let scale = |shifts: &[(isize, Vec<f64>)]| smallest_median(shifts.iter().map(|(_, r)| r));
    let best_of = |shifts: &[(isize, Vec<f64>)]| {
        let scale = scale(shifts);
        shifts
            .iter()
            .map(|(k, r)| (*k, Misfit::of(r, scale)))
            .max_by(|a, b| a.1.explained.total_cmp(&b.1.explained))
    };
    let (best, _) = best_of(&shifts)?;
    // Refined by samples around the best coarse shift.
    shifts.extend(
        (best - coarse + 1..best + coarse)
            .filter(|k| k % coarse != 0)
            .filter_map(|k| Some((k, residuals(k)?))),
    );
    let scale = scale(&shifts);
    let given = Misfit::of(&shifts.iter().find(|(k, _)| *k == 0)?.1, scale);
    let (best, shifted) = best_of(&shifts)?;
    let offset_s = -(best as f64) * step_s;
    (shifted.explained >= given.explained + EXPLAINED_MORE
        && shifted.median_ut < given.median_ut
        && offset_s.abs() >= MIN_OFFSET_S)
        .then_some(OutOfStep {
            offset_s,
            given,
            shifted,
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

    /// A sensor turned smoothly at 100 Hz (about an axis that wanders), and its readings.
    fn turning(n: usize) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, Vec<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let field = [19.0, 1.2, 45.0];
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
        let expected: Vec<[f64; 3]> = t
            .iter()
            .map(|&t| {
                let axis = [(0.3 * t).sin(), (0.2 * t).cos(), 0.5];
                let norm = frames::norm(axis);
                let half = 0.9 * t;
                let q = [
                    half.cos(),
                    half.sin() * axis[0] / norm,
                    half.sin() * axis[1] / norm,
                    half.sin() * axis[2] / norm,
                ];
                frames::expected_sensor_field(q, field)
            })
            .collect();
        let raw = expected
            .iter()
            .map(|e| {
                std::array::from_fn(|k| {
                    1.05 * e[k] + [12.0, -7.0, 30.0][k] + rng.random_range(-0.3..0.3)
                })
            })
            .collect();
        (raw, expected, t)
    }

    #[test]
    fn a_reference_out_of_step_is_found_and_one_in_step_or_nearly_is_left_alone() {
        let (raw, expected, t) = turning(6000);
        assert_eq!(clock_offset(&raw, &expected, &t, None), None);
        for (rows, found) in [(40isize, true), (-130, true), (10, false)] {
            // The reference `rows` ahead of the readings: each row holds the field `rows` later.
            let ahead: Vec<[f64; 3]> = (0..expected.len())
                .map(|i| {
                    i.checked_add_signed(rows)
                        .and_then(|j| expected.get(j))
                        .copied()
                        .unwrap_or([f64::NAN; 3])
                })
                .collect();
            let out = clock_offset(&raw, &ahead, &t, None);
            assert_eq!(out.is_some(), found, "{rows}: {out:?}");
            if let Some(o) = out {
                assert!(
                    (o.offset_s - 0.01 * rows as f64).abs() < 1e-9,
                    "{rows}: {o:?}"
                );
                assert!(
                    o.shifted.explained > 0.95 && o.given.explained < 0.8,
                    "{o:?}"
                );
            }
        }
    }

    #[test]
    fn every_convention_is_tried_once_and_magcals_is_the_identity() {
        let all: Vec<Convention> = Convention::all().collect();
        assert_eq!(all.len(), 16);
        assert_eq!(all[0], Convention::MAGCAL);
        let (q, f) = ([0.5, -0.5, 0.5, 0.5], [1.0, 2.0, 3.0]);
        assert_eq!(Convention::MAGCAL.to_magcal(q, f), (q, f));
        for (k, c) in all.iter().enumerate() {
            assert!(!all[..k].contains(c));
            let (wq, wf) = c.written(q, f);
            assert_eq!(c.to_magcal(wq, wf), (q, f), "{c:?}");
        }
    }

    #[test]
    fn a_reference_in_magcals_convention_is_left_alone() {
        let (raw, quat, field) = recording(3000);
        assert_eq!(better_convention(&raw, &quat, field, None), None);
    }

    #[test]
    fn a_reference_written_in_another_convention_is_named() {
        let (raw, quat, field) = recording(3000);
        for c in Convention::all().skip(1) {
            let written: Vec<([f64; 4], [f64; 3])> =
                quat.iter().map(|&q| c.written(q, field)).collect();
            let (written_quat, written_field): (Vec<[f64; 4]>, Vec<[f64; 3]>) =
                written.into_iter().unzip();
            let found = better_convention(&raw, &written_quat, written_field[0], None)
                .unwrap_or_else(|| panic!("{c:?} not found"));
            assert_eq!(found.convention, c, "{}", c.describe());
            assert!(found.also.is_empty(), "{found:?}");
            assert!(found.better.median_ut < 0.5, "{:?}", found.better);
            assert!(found.better.explained > 0.95, "{:?}", found.better);
        }
    }
}
