//! The samples the diagnosis works on: the rows where every channel it uses is present, with the field, its rate
//! and the attitude worked out once.

use std::borrow::Cow;

use crate::chunks;
use crate::effects::{Context, WorldContext};
use crate::frames::{self, Mat3};
use crate::model::{Inputs, Model};

use super::{DiagnosisInput, Reference, timing};

/// Per-sample data, for the rows the diagnosis uses.
pub(crate) struct Samples<'a> {
    /// Row index in the recording.
    pub rows: Vec<usize>,
    /// Raw reading, µT.
    pub raw: Cow<'a, [[f64; 3]]>,
    /// The field in calibrated sensor axes: the reference (vector) or the base-calibrated reading (scalar).
    pub field: Vec<[f64; 3]>,
    /// Its rate of change, µT/s (zero without time or reference).
    pub rate: Vec<[f64; 3]>,
    /// The recording's attitude quaternions (sensor → NED, by recording row), when the attitude is known.
    pub quat: Option<&'a [[f64; 4]]>,
    /// The assumed world field, when the attitude is known.
    pub field_ned_ut: Option<[f64; 3]>,
    /// Time, s (zero without a time column).
    pub t: Cow<'a, [f64]>,
    pub has_time: bool,
    /// Temperature, °C (NaN without one).
    pub temp: Cow<'a, [f64]>,
    pub has_temp: bool,
    /// Currents, row-major with `n_currents` per sample.
    pub currents: Vec<f64>,
    pub n_currents: usize,
    /// Rows of the recording left out (a channel missing).
    pub left_out: usize,
    /// Kept by the robust base fit (not grossly off).
    pub kept: Vec<bool>,
    /// The lag the field and its rate are linearised at ([`timing`]), s; 0 when not.
    pub lag0_s: f64,
    /// Each sample is every `stride`-th usable row ([`MOST_SAMPLES`]); 1: every one.
    pub stride: usize,
}

/// The diagnosis works on at most about this many samples: a longer recording is diagnosed on every `stride`-th of
/// its usable rows (the smallest `stride` that leaves at most this many), the field's rate (a central difference over
/// `stride` rows each side) and the coarse lag found from them. At 10⁶ samples (100 Hz for 2.8 hours) its spans are
/// then located to 5 samples, and its tests have the power of 200,000 samples, where an effect too small to be found
/// is far below what a heading or a gain would notice; the physical recordings, the studies and the fixtures are
/// shorter and diagnosed sample by sample.
pub const MOST_SAMPLES: usize = 200_000;

/// The attitudes (sensor → NED) of consecutive samples, worked out from the quaternions when asked for.
#[derive(Clone, Copy)]
pub(crate) struct Attitudes<'a> {
    quat: &'a [[f64; 4]],
    /// The samples' recording rows.
    rows: &'a [usize],
}

impl Attitudes<'_> {
    /// Sample `i`'s.
    pub fn at(&self, i: usize) -> Mat3 {
        frames::quat_to_matrix(self.quat[self.rows[i]])
    }

    /// Those of samples `a..b`.
    pub fn range(&self, a: usize, b: usize) -> Self {
        Attitudes {
            quat: self.quat,
            rows: &self.rows[a..b],
        }
    }
}

impl<'a> Samples<'a> {
    pub fn len(&self) -> usize {
        self.raw.len()
    }

    /// Every sample's attitude, when known.
    pub fn rot(&self) -> Option<Attitudes<'_>> {
        self.quat.map(|quat| Attitudes {
            quat,
            rows: &self.rows,
        })
    }

    /// The effect context of sample `i`.
    pub fn context(&self, i: usize) -> Context<'_> {
        Context {
            t_s: self.t[i],
            temp_c: self.temp[i],
            currents_a: &self.currents[i * self.n_currents..(i + 1) * self.n_currents],
            field_ut: self.field[i],
            field_rate_ut_per_s: self.rate[i],
            world: match (self.quat, self.field_ned_ut) {
                (Some(q), Some(f)) => Some(WorldContext {
                    sensor_to_ned: frames::quat_to_matrix(q[self.rows[i]]),
                    field_ned_ut: f,
                    position_m: [0.0; 3],
                }),
                _ => None,
            },
        }
    }

    /// Gathers the usable rows (every `stride`-th of them beyond [`MOST_SAMPLES`]). `base` calibrates readings for
    /// the scalar method's field estimate (and finds the coarse lag); the field is linearised at that lag if
    /// `linearise`.
    pub fn gather(input: &DiagnosisInput<'a>, base: &Model, linearise: bool) -> Samples<'a> {
        Samples::gather_at_most(input, base, linearise, MOST_SAMPLES)
    }

    /// [`Samples::gather`], thinned beyond `most` samples.
    fn gather_at_most(
        input: &DiagnosisInput<'a>,
        base: &Model,
        linearise: bool,
        most: usize,
    ) -> Samples<'a> {
        let n = input.raw_ut.len();
        let finite3 = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        let usable = |i: usize| {
            finite3(&input.raw_ut[i])
                && match &input.reference {
                    Reference::Attitude { quat, .. } => quat[i].iter().all(|x| x.is_finite()),
                    Reference::Field { expected_ut } => finite3(&expected_ut[i]),
                    Reference::Magnitude { .. } => true,
                }
                && input.t_s.is_none_or(|t| t[i].is_finite())
                && input.temp_c.is_none_or(|t| t[i].is_finite())
                && input.currents.iter().all(|(_, c)| c[i].is_finite())
        };
        let mut index: Vec<usize> = (0..n).filter(|&i| usable(i)).collect();
        let usable_rows = index.len();
        let stride = usable_rows.div_ceil(most).max(1);
        if stride > 1 {
            index = index.into_iter().step_by(stride).collect();
        }
        let expected: Option<Vec<[f64; 3]>> = match &input.reference {
            Reference::Attitude { quat, field_ned_ut } => {
                let e = chunks::map(index.len(), |k| {
                    frames::expected_sensor_field(quat[index[k]], *field_ned_ut)
                });
                // A finite quaternion that turns into no attitude (all zeros) is no reference.
                if e.iter().all(finite3) {
                    Some(e)
                } else {
                    // (Rare enough to count each such sample as one row left out when thinned.)
                    let (i, e): (Vec<usize>, Vec<[f64; 3]>) = index
                        .iter()
                        .zip(e)
                        .filter(|(_, e)| finite3(e))
                        .map(|(i, e)| (*i, e))
                        .unzip();
                    index = i;
                    Some(e)
                }
            }
            Reference::Field { expected_ut } => {
                Some(index.iter().map(|&i| expected_ut[i]).collect())
            }
            Reference::Magnitude { .. } => None,
        };
        // The recording's own columns when every row is usable.
        fn pick<'c, T: Copy>(column: &'c [T], index: &[usize]) -> Cow<'c, [T]> {
            if index.len() == column.len() {
                Cow::Borrowed(column)
            } else {
                Cow::Owned(index.iter().map(|&i| column[i]).collect())
            }
        }
        let raw = pick(input.raw_ut, &index);
        let has_expected = expected.is_some();
        let mut field: Vec<[f64; 3]> = match expected {
            Some(e) => e,
            None => raw.iter().map(|m| base.apply(*m, &Inputs::NONE)).collect(),
        };
        let t = match input.t_s {
            Some(t) => pick(t, &index),
            None => Cow::Owned(vec![0.0; index.len()]),
        };
        let mut lag0_s = 0.0;
        let rate = match (has_expected, input.t_s) {
            (true, Some(_)) => {
                let step_s = timing::typical_step(&t);
                let links = links(&t, &index, stride, step_s);
                let mut rate = field_rate(&field, &t, &links);
                if linearise {
                    lag0_s = timing::coarse_lag_s(&raw, &field, &rate, &t, step_s, &links, base);
                }
                if lag0_s != 0.0 {
                    timing::linearise_at(&mut field, &mut rate, &t, &links, lag0_s);
                }
                rate
            }
            _ => vec![[0.0; 3]; index.len()],
        };
        let (quat, field_ned_ut) = match input.reference {
            Reference::Attitude { quat, field_ned_ut } => (Some(quat), Some(field_ned_ut)),
            _ => (None, None),
        };
        let n_currents = input.currents.len();
        let mut currents = Vec::with_capacity(index.len() * n_currents);
        for &i in &index {
            currents.extend(input.currents.iter().map(|(_, c)| c[i]));
        }
        Samples {
            kept: index
                .iter()
                .map(|&i| input.kept.is_none_or(|k| k[i]))
                .collect(),
            lag0_s,
            // Rows thinned out are not left out: each sample stands for `stride` of them.
            left_out: n - usable_rows + (usable_rows.div_ceil(stride) - index.len()),
            stride,
            temp: match input.temp_c {
                Some(tc) => pick(tc, &index),
                None => Cow::Owned(vec![f64::NAN; index.len()]),
            },
            has_temp: input.temp_c.is_some(),
            has_time: input.t_s.is_some(),
            rows: index,
            raw,
            field,
            rate,
            quat,
            field_ned_ut,
            t,
            currents,
            n_currents,
        }
    }
}

/// Per sample but the last, whether it and the next are consecutive samples of the recording (its rows, or every
/// `stride`-th of them, none missing between), in time order and at most five typical steps apart (the field may be
/// differenced and interpolated between them). `step_s` is the typical step ([`timing::typical_step`]; without one,
/// no gap is too long).
fn links(t: &[f64], index: &[usize], stride: usize, step_s: f64) -> Vec<bool> {
    let typical = if step_s > 0.0 { step_s } else { f64::INFINITY };
    (0..index.len().saturating_sub(1))
        .map(|a| {
            let dt = t[a + 1] - t[a];
            index[a + 1] - index[a] <= stride && dt > 0.0 && dt <= 5.0 * typical
        })
        .collect()
}

/// Central differences of the field over time; one-sided at the ends and at gaps (samples not [`links`]ed), zero
/// where neither side is usable. Computed on all threads.
fn field_rate(field: &[[f64; 3]], t: &[f64], links: &timing::Links) -> Vec<[f64; 3]> {
    let n = field.len();
    chunks::map(n, |i| {
        let prev = i > 0 && links[i - 1];
        let next = i + 1 < n && links[i];
        let (a, b) = match (prev, next) {
            (true, true) => (i - 1, i + 1),
            (true, false) => (i - 1, i),
            (false, true) => (i, i + 1),
            (false, false) => return [0.0; 3],
        };
        frames::scale(frames::sub(field[b], field[a]), 1.0 / (t[b] - t[a]))
    })
}

#[cfg(test)]
mod tests {
    use super::super::testbench::{Bench, true_model};

    use super::*;

    #[test]
    fn rows_missing_a_channel_are_left_out_and_counted() {
        let mut bench = Bench::new(300, &[], 4);
        bench.temp_c[10] = f64::NAN;
        bench.quat[20] = [f64::NAN; 4];
        let input = bench.input(None, f64::NAN);
        let s = Samples::gather(&input, &true_model(), false);
        assert_eq!((s.len(), s.left_out), (298, 2));
        assert!(!s.rows.contains(&10) && !s.rows.contains(&20));
        // Every sample carries its world context and the field's rate (the sensor turns).
        let ctx = s.context(50);
        assert!(ctx.world.is_some());
        assert!(frames::norm(ctx.field_rate_ut_per_s) > 1.0);
        assert!(s.has_time && s.has_temp && s.kept.iter().all(|k| *k));
    }

    #[test]
    fn a_long_recording_is_gathered_every_stride_th_row_with_the_rate_of_its_neighbours() {
        let mut bench = Bench::new(3000, &[], 5);
        bench.temp_c[7] = f64::NAN;
        let input = bench.input(None, f64::NAN);
        let all = Samples::gather(&input, &true_model(), false);
        let thin = Samples::gather_at_most(&input, &true_model(), false, 1000);
        assert_eq!((all.stride, thin.stride), (1, 3));
        // Every third usable row (row 7 is not one), each with its own values; none left out but row 7.
        assert_eq!(thin.len(), 1000);
        assert_eq!(thin.left_out, 1);
        let mut worst: f64 = 0.0;
        for (k, &row) in thin.rows.iter().enumerate() {
            let i = all.rows.iter().position(|&r| r == row).unwrap();
            assert_eq!(i, 3 * k);
            assert_eq!(
                (thin.raw[k], thin.field[k], thin.t[k]),
                (all.raw[i], all.field[i], all.t[i])
            );
            // The rate from the samples three rows away on each side: the field's own, to the curvature of the
            // turn (one side at the ends and at row 7, as all rows' is, over other steps).
            if k > 0 && k + 1 < thin.len() && row.abs_diff(7) > 3 {
                let (r, a) = (thin.rate[k], all.rate[i]);
                worst = worst.max(frames::norm(frames::sub(r, a)) / frames::norm(a));
            }
        }
        assert!(worst < 0.01, "{worst}");
    }
}
