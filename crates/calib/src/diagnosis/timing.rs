//! A timing offset between the magnetometer and the attitude reference too large for a first-order term.
//!
//! The `time_lag` effect models readings `θ` late against the reference as `−θ·Ḃ`: exact to first order, which is
//! what a lag of a sample or two needs. While the sensor turns at ω, the field turns by ω·θ in the lag, and the
//! second-order term, `(ω·θ)²/2` of the field, is already 4–5 µT at 0.45 rad (64 ms on a bench turned at 7 rad/s,
//! BROAD 02's fastest): the residual left where the sensor turns fast then looks like a string of disturbances.
//! So the lag is first found coarsely — the shift of the reference that fits the base model best where the sensor
//! turns — and the effect is linearised there: the field becomes `B(t − θ₀) + θ₀·Ḃ(t − θ₀)` and its rate
//! `Ḃ(t − θ₀)`, so that `time_lag` at `θ` models `B(t − θ)` exactly at `θ = θ₀` and to first order in `θ − θ₀`
//! around it (at `θ₀ = 0` nothing changes).

use rayon::prelude::*;

use crate::frames;
use crate::model::Model;

/// The largest offset looked for, s.
const MAX_LAG_S: f64 = 0.5;
/// The coarse grid's step, s (or the sampling's, if longer): the misfit grows smoothly away from the lag.
const COARSE_STEP_S: f64 = 0.01;
/// Fine steps in each coarse step around the best (the first-order term does the rest).
const FINE_STEPS: usize = 10;
/// Samples the field's median speed is taken over, at most.
const SPEED_SAMPLES: usize = 1 << 16;
/// Samples the criterion is taken over, at most.
const CRITERION_SAMPLES: usize = 5_000;
/// The offset is used only when it lowers the criterion by at least this share: the first-order term handles the
/// rest (a lag of a sample or two on a bench turned slowly lowers it by a few per cent).
const MIN_GAIN: f64 = 0.1;
/// The quantile of the misfit the offset minimises.
const CRITERION_QUANTILE: f64 = 0.25;

/// Consecutive samples `j`, `j + 1` between which the field may be interpolated (and differenced).
pub(crate) type Links = [bool];

/// The coarse offset θ₀ (s; 0 when none helps by [`MIN_GAIN`]) at which `field` (the reference per sample, at
/// times `t`, whose typical step is `step_s`: [`typical_step`]) fits the base model's readings `raw` best where the field moves fastest: by the lower quartile of the
/// misfit there, which a magnet on the board for a third of the turning does not reach (its median did: 146 ms
/// on BROAD 33, whose lag is 16 ms), nor the samples the base fit excluded for the lag itself (over the samples it
/// kept, a lag of 83 ms was found at 44).
pub(crate) fn coarse_lag_s(
    raw: &[[f64; 3]],
    field: &[[f64; 3]],
    rate: &[[f64; 3]],
    t: &[f64],
    step_s: f64,
    links: &Links,
    base: &Model,
) -> f64 {
    let n = field.len();
    let speed = |j: usize| frames::norm(rate[j]);
    let spread: Vec<f64> = (0..n)
        .step_by(n.div_ceil(SPEED_SAMPLES).max(1))
        .map(speed)
        .collect();
    let moving_above = crate::robust::median(&spread);
    if moving_above.is_nan() || moving_above <= 0.0 {
        return 0.0;
    }
    let moving = || (0..n).filter(|&j| speed(j) > moving_above);
    let stride = moving().count().div_ceil(CRITERION_SAMPLES).max(1);
    let picked: Vec<usize> = moving().step_by(stride).collect();
    let calibrated: Vec<[f64; 3]> = picked
        .iter()
        .map(|&j| frames::add(frames::mat_vec(&base.a, raw[j]), base.b_ut))
        .collect();
    // The misfit's lower quartile over the picked samples against the field `lag` earlier (those it cannot be
    // interpolated for left out).
    let criterion = |lag: f64| {
        let e: Vec<f64> = picked
            .iter()
            .zip(&calibrated)
            .filter_map(|(&j, c)| {
                interpolate(field, t, links, t[j] - lag, j)
                    .map(|f| frames::norm(frames::sub(*c, f)))
            })
            .collect();
        // Too few samples for the shift: not a candidate.
        if e.len() * 2 < picked.len() {
            f64::INFINITY
        } else {
            crate::robust::quantile(&e, CRITERION_QUANTILE)
        }
    };
    if step_s.is_nan() || step_s <= 0.0 {
        return 0.0;
    }
    let step = step_s.max(COARSE_STEP_S);
    let steps = (MAX_LAG_S / step) as i64;
    // The grid's lags, fitted on all threads, the best kept (the first of equals).
    let best_of = |grid: Vec<f64>| {
        grid.par_iter()
            .map(|&lag| (criterion(lag), lag))
            .collect::<Vec<_>>()
            .into_iter()
            .fold((f64::INFINITY, 0.0), |m, c| if c.0 < m.0 { c } else { m })
    };
    let (_, coarse) = best_of((-steps..=steps).map(|k| k as f64 * step).collect());
    let fine = FINE_STEPS as i64;
    let (best, lag) = best_of(
        (-fine..=fine)
            .map(|k| coarse + k as f64 * step / fine as f64)
            .collect(),
    );
    if best < (1.0 - MIN_GAIN) * criterion(0.0) {
        lag
    } else {
        0.0
    }
}

/// `field` and `rate` linearised at the offset `lag_s` (see the module docs), where both can be interpolated there;
/// unchanged elsewhere (to second order the same).
pub(crate) fn linearise_at(
    field: &mut [[f64; 3]],
    rate: &mut [[f64; 3]],
    t: &[f64],
    links: &Links,
    lag_s: f64,
) {
    // In place: a sample is replaced after those it is interpolated from (earlier ones for a positive lag, later
    // ones for a negative) are read, and before they are replaced.
    let n = field.len();
    let order: Box<dyn Iterator<Item = usize>> = if lag_s > 0.0 {
        Box::new((0..n).rev())
    } else {
        Box::new(0..n)
    };
    for j in order {
        let u = t[j] - lag_s;
        if let (Some(f), Some(r)) = (
            interpolate(field, t, links, u, j),
            interpolate(rate, t, links, u, j),
        ) {
            field[j] = frames::add(f, frames::scale(r, lag_s));
            rate[j] = r;
        }
    }
}

/// `series` at time `u`, linear between the two linked samples around it (`None` outside them); the search for
/// them starts at sample `near` (a lag away from `u`: a few steps).
fn interpolate(
    series: &[[f64; 3]],
    t: &[f64],
    links: &Links,
    u: f64,
    near: usize,
) -> Option<[f64; 3]> {
    let k = partition_near(t, u, near);
    if k == 0 || k >= t.len() {
        return None;
    }
    let (a, b) = (k - 1, k);
    if !links[a] {
        return None;
    }
    let w = (u - t[a]) / (t[b] - t[a]);
    Some(std::array::from_fn(|c| {
        series[a][c] + w * (series[b][c] - series[a][c])
    }))
}

/// How many of the (ordered) times `t` are at most `u`, found by steps doubling away from index `near`.
fn partition_near(t: &[f64], u: f64, near: usize) -> usize {
    let n = t.len();
    if n == 0 {
        return 0;
    }
    let near = near.min(n - 1);
    // The answer lies in lo..=hi: every time before lo is at most u, every one from hi on is above it.
    let (lo, hi) = if t[near] <= u {
        let (mut lo, mut step) = (near + 1, 1);
        loop {
            let probe = near + step;
            if probe >= n {
                break (lo, n);
            }
            if t[probe] > u {
                break (lo, probe);
            }
            lo = probe + 1;
            step *= 2;
        }
    } else {
        let (mut hi, mut step) = (near, 1);
        loop {
            if step > near {
                break (0, hi);
            }
            let probe = near - step;
            if t[probe] <= u {
                break (probe + 1, hi);
            }
            hi = probe;
            step *= 2;
        }
    };
    lo + t[lo..hi].partition_point(|&x| x <= u)
}

/// The median step between consecutive times (NaN without two increasing ones).
pub(crate) fn typical_step(t: &[f64]) -> f64 {
    let steps: Vec<f64> = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    crate::robust::median(&steps)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A field turning about the sensor's z axis at a rate that varies (0 to 4.5 rad/s), sampled at 100 Hz.
    fn turning(t: f64) -> ([f64; 3], [f64; 3]) {
        let (angle, rate) = (3.0 * (0.5 * t).sin(), 1.5 * (0.5 * t).cos());
        let (s, c) = angle.sin_cos();
        (
            [40.0 * c, 40.0 * s, 20.0],
            [-40.0 * s * rate, 40.0 * c * rate, 0.0],
        )
    }

    /// Per sample: time, the reference's field and its rate, and the reading.
    type Bench = (Vec<f64>, Vec<[f64; 3]>, Vec<[f64; 3]>, Vec<[f64; 3]>);

    fn bench(lag_s: f64) -> Bench {
        let t: Vec<f64> = (0..3000).map(|i| i as f64 * 0.01).collect();
        let (field, rate) = t.iter().map(|&t| turning(t)).unzip();
        // The magnetometer reads the field `lag_s` earlier than the reference gives it.
        let raw = t.iter().map(|&t| turning(t - lag_s).0).collect();
        (t, field, rate, raw)
    }

    #[test]
    fn a_lag_of_80_ms_is_found_and_the_field_linearised_there_reads_the_earlier_field() {
        let (t, mut field, mut rate, raw) = bench(0.08);
        let links = vec![true; t.len() - 1];
        let lag = coarse_lag_s(
            &raw,
            &field,
            &rate,
            &t,
            typical_step(&t),
            &links,
            &Model::linear(frames::IDENTITY, [0.0; 3]),
        );
        assert!((lag - 0.08).abs() < 0.002, "{lag}");
        linearise_at(&mut field, &mut rate, &t, &links, lag);
        // time_lag at θ₀ (−θ₀·rate) reads the field θ₀ earlier, to the interpolation's error (the samples from the
        // lag on; before, nothing is there to interpolate).
        let worst = (10..t.len())
            .map(|j| {
                let modelled = frames::sub(field[j], frames::scale(rate[j], lag));
                frames::norm(frames::sub(modelled, turning(t[j] - lag).0))
            })
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "{worst} µT");
    }

    #[test]
    fn the_search_from_near_a_time_finds_what_a_binary_search_does() {
        let t: Vec<f64> = (0..200).map(|i| f64::from(i / 3) * 0.5).collect();
        for near in [0, 1, 57, 100, 198, 199, 500] {
            for k in -4..140 {
                let u = f64::from(k) * 0.25;
                assert_eq!(
                    partition_near(&t, u, near),
                    t.partition_point(|&x| x <= u),
                    "u {u}, near {near}"
                );
            }
        }
        assert_eq!(partition_near(&[], 1.0, 0), 0);
    }

    #[test]
    fn without_a_lag_nothing_is_shifted() {
        let (t, field, rate, raw) = bench(0.0);
        let links = vec![true; t.len() - 1];
        assert_eq!(
            coarse_lag_s(
                &raw,
                &field,
                &rate,
                &t,
                typical_step(&t),
                &links,
                &Model::linear(frames::IDENTITY, [0.0; 3])
            ),
            0.0
        );
    }
}
