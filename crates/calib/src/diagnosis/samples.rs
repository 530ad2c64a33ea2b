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
}

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

    /// Gathers the usable rows. `base` calibrates readings for the scalar method's field estimate (and finds the
    /// coarse lag); the field is linearised at that lag if `linearise`.
    pub fn gather(input: &DiagnosisInput<'a>, base: &Model, linearise: bool) -> Samples<'a> {
        let n = input.raw_ut.len();
        let expected: Option<Vec<[f64; 3]>> = match &input.reference {
            Reference::Attitude { quat, field_ned_ut } => Some(chunks::map(quat.len(), |i| {
                frames::expected_sensor_field(quat[i], *field_ned_ut)
            })),
            Reference::Field { expected_ut } => Some(expected_ut.to_vec()),
            Reference::Magnitude { .. } => None,
        };
        let finite3 = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        let usable = |i: usize| {
            finite3(&input.raw_ut[i])
                && expected.as_ref().is_none_or(|e| finite3(&e[i]))
                && input.t_s.is_none_or(|t| t[i].is_finite())
                && input.temp_c.is_none_or(|t| t[i].is_finite())
                && input.currents.iter().all(|(_, c)| c[i].is_finite())
        };
        let index: Vec<usize> = (0..n).filter(|&i| usable(i)).collect();
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
            // Every row usable: the expected field as it is.
            Some(e) if e.len() == index.len() => e,
            Some(e) => index.iter().map(|&i| e[i]).collect(),
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
                let links = links(&t, &index, step_s);
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
            left_out: n - index.len(),
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

/// Per sample but the last, whether it and the next are consecutive rows of the recording, in time order and at
/// most five typical steps apart (the field may be differenced and interpolated between them).
/// `step_s` is the typical step ([`timing::typical_step`]; without one, no gap is too long).
fn links(t: &[f64], index: &[usize], step_s: f64) -> Vec<bool> {
    let typical = if step_s > 0.0 { step_s } else { f64::INFINITY };
    (0..index.len().saturating_sub(1))
        .map(|a| {
            let dt = t[a + 1] - t[a];
            index[a + 1] == index[a] + 1 && dt > 0.0 && dt <= 5.0 * typical
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
}
