//! A timing offset between the magnetometer and the attitude reference too large for a first-order term.
//!
//! The `time_lag` effect models the reference read `θ` late as `−θ·Ḃ`: exact to first order, which is what a lag of
//! a sample or two needs. While the sensor turns at ω, the field turns by ω·θ in the lag, and the second-order
//! term, `(ω·θ)²/2` of the field, is already 5 µT at 0.5 rad (about 65 ms on a bench turned at 7 rad/s, the BROAD
//! 02 recording's fastest): the residual left where the sensor turns fast then looks like a string of disturbances.
//! So the lag is first found coarsely — the shift of the reference that fits the base model best where the sensor
//! turns — and the effect is linearised there: the field becomes `B(t − θ₀) + θ₀·Ḃ(t − θ₀)` and its rate
//! `Ḃ(t − θ₀)`, so that `time_lag` at `θ` models `B(t − θ)` exactly at `θ = θ₀` and to first order in `θ − θ₀`
//! around it (at `θ₀ = 0` nothing changes).

use crate::frames;
use crate::model::Model;

/// The largest offset looked for, s.
const MAX_LAG_S: f64 = 0.5;
/// The coarse grid has at most this many steps each way (and steps no finer than the sampling).
const GRID_STEPS: usize = 200;
/// Fine steps in each coarse step around the best.
const FINE_STEPS: usize = 10;
/// Samples the criterion is taken over, at most.
const CRITERION_SAMPLES: usize = 20_000;
/// The offset is used only when it lowers the criterion by at least this share: the first-order term handles the
/// rest (a lag of a sample or two on a bench turned slowly lowers it by a few per cent).
const MIN_GAIN: f64 = 0.1;
/// The quantile of the misfit the offset minimises.
const CRITERION_QUANTILE: f64 = 0.25;

/// Consecutive samples `j`, `j + 1` between which the field may be interpolated (and differenced).
pub(crate) type Links = [bool];

/// The coarse offset θ₀ (s; 0 when none helps by [`MIN_GAIN`]) at which `field` (the reference per sample, at
/// times `t`) fits the base model's readings `raw` best where the field moves fastest: by the lower quartile of the
/// misfit there, which a magnet on the board for a third of the turning does not reach (its median did: 146 ms
/// on BROAD 33, whose lag is 16 ms), nor the samples the base fit excluded for the lag itself (over the samples it
/// kept, a lag of 83 ms was found at 44).
pub(crate) fn coarse_lag_s(
    raw: &[[f64; 3]],
    field: &[[f64; 3]],
    rate: &[[f64; 3]],
    t: &[f64],
    links: &Links,
    base: &Model,
) -> f64 {
    let n = field.len();
    let speed: Vec<f64> = rate.iter().map(|r| frames::norm(*r)).collect();
    let moving_above = crate::robust::median(&speed);
    if moving_above.is_nan() || moving_above <= 0.0 {
        return 0.0;
    }
    let moving: Vec<usize> = (0..n).filter(|&j| speed[j] > moving_above).collect();
    let stride = moving.len().div_ceil(CRITERION_SAMPLES).max(1);
    let picked: Vec<usize> = moving.into_iter().step_by(stride).collect();
    let calibrated: Vec<[f64; 3]> = picked
        .iter()
        .map(|&j| frames::add(frames::mat_vec(&base.a, raw[j]), base.b_ut))
        .collect();
    // The median misfit of the picked samples against the field `lag` earlier (those it cannot be interpolated
    // for left out).
    let criterion = |lag: f64| {
        let e: Vec<f64> = picked
            .iter()
            .zip(&calibrated)
            .filter_map(|(&j, c)| {
                interpolate(field, t, links, t[j] - lag).map(|f| frames::norm(frames::sub(*c, f)))
            })
            .collect();
        // Too few samples for the shift: not a candidate.
        if e.len() * 2 < picked.len() {
            f64::INFINITY
        } else {
            crate::robust::quantile(&e, CRITERION_QUANTILE)
        }
    };
    let dt = typical_step(t);
    if dt.is_nan() || dt <= 0.0 {
        return 0.0;
    }
    let step = dt.max(MAX_LAG_S / GRID_STEPS as f64);
    let steps = (MAX_LAG_S / step) as i64;
    let best_of = |grid: &mut dyn Iterator<Item = f64>| {
        grid.map(|lag| (criterion(lag), lag))
            .fold((f64::INFINITY, 0.0), |m, c| if c.0 < m.0 { c } else { m })
    };
    let (_, coarse) = best_of(&mut (-steps..=steps).map(|k| k as f64 * step));
    let fine = FINE_STEPS as i64;
    let (best, lag) = best_of(&mut (-fine..=fine).map(|k| coarse + k as f64 * step / fine as f64));
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
    let shifted: Vec<Option<([f64; 3], [f64; 3])>> = (0..field.len())
        .map(|j| {
            let u = t[j] - lag_s;
            Some((
                interpolate(field, t, links, u)?,
                interpolate(rate, t, links, u)?,
            ))
        })
        .collect();
    for (j, s) in shifted.into_iter().enumerate() {
        if let Some((f, r)) = s {
            field[j] = frames::add(f, frames::scale(r, lag_s));
            rate[j] = r;
        }
    }
}

/// `series` at time `u`, linear between the two linked samples around it (`None` outside them).
fn interpolate(series: &[[f64; 3]], t: &[f64], links: &Links, u: f64) -> Option<[f64; 3]> {
    let k = t.partition_point(|&x| x <= u);
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

    fn bench(lag_s: f64) -> (Vec<f64>, Vec<[f64; 3]>, Vec<[f64; 3]>, Vec<[f64; 3]>) {
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
    fn without_a_lag_nothing_is_shifted() {
        let (t, field, rate, raw) = bench(0.0);
        let links = vec![true; t.len() - 1];
        assert_eq!(
            coarse_lag_s(
                &raw,
                &field,
                &rate,
                &t,
                &links,
                &Model::linear(frames::IDENTITY, [0.0; 3])
            ),
            0.0
        );
    }
}
