//! A bench motor test: the vehicle held still while the throttle goes up and down, so the recording has one
//! orientation and the field changes only with the current. `A` and `b` cannot be fitted from it; what it gives is
//! the current term alone: per axis `B_j(t) = B0_j + k_j·I(t − lag)`, `B0` the field at zero current.
//!
//! The current term is the catalogue's `current_bias` ([`Effect::CurrentBias`]): its regressors are that effect's
//! own [`Effect::perturbation_ut`] per unit coefficient (the function the simulator injects), as a diagnosis
//! [`Candidate`]. The normal equations are summed per cross-validation block and autocorrelation batch into the
//! diagnosis' [`Problem`], and the term is kept only when the diagnosis' selection ([`select()`]) takes it — the
//! same Wald test with its BIC penalty, blocked cross-validation and share of the residual — against the constant
//! field alone. Its standard errors are, per axis, the larger of the residual-variance covariance (autocorrelation
//! and the axes' unequal noise allowed for, [`Problem::model_covariance`]) and the cluster-robust one
//! ([`Problem::cluster_covariance`]), as the diagnosis' parameters' are.
//!
//! The lag is tested at zero first (the selection is not given a scanned hyperparameter to search); once the term is
//! kept, the lag is scanned over a grid of sample intervals and reported when its profile interval (the residual
//! within one autocorrelation-scaled variance of its minimum) lies inside the grid; the coefficients are then those
//! at that lag. The lag is determined ([`Lag::determined`]) only when that interval is at most
//! [`MAX_LAG_HALF_WIDTH_S`] either side: its information is `Σ (k·dI/dt)²/σ²`, so slow ramps of the throttle with a
//! small coefficient leave it wide (±15 ms with 0.05 µT/A on each axis), and quick steps of the throttle narrow it;
//! and only when the current was measured about as often as the field was sampled ([`Lag::current_keeps_up`]).

use nalgebra::DMatrix;

use crate::FitError;
use crate::effects::{Context, Effect, EffectId};
use crate::frames::{self, Mat3};

use super::candidates::Candidate;
use super::select::{MIN_EXCESS_SHARE, SetAside, select};
use super::stats::{Batches, BlockStats, Problem, Solution};
use super::{AUTOCORRELATION_BATCHES, CV_BLOCKS, MIN_SAMPLES};

/// The columns of the problem: `B0` per axis, then the current term's three coefficients.
const COLUMNS: usize = 6;
/// The base model: the constant field.
const BASE: [usize; 3] = [0, 1, 2];
/// Most lag steps scanned on each side of zero.
const MAX_LAG_STEPS: usize = 200;

/// A motors recording, ready for the fit.
#[derive(Clone, Copy, Debug)]
pub struct MotorInput<'a> {
    /// Time, s (never decreasing).
    pub t_s: &'a [f64],
    /// The field in calibrated sensor axes, µT.
    pub field_ut: &'a [[f64; 3]],
    /// The current, A (NaN where missing: those rows are left out).
    pub current_a: &'a [f64],
    /// The noise floor per calibrated axis, µT.
    pub noise_floor_ut: [f64; 3],
    /// The largest lag scanned either way, s (0: none).
    pub max_lag_s: f64,
}

/// The current term, when the selection keeps it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentTerm {
    /// `current_bias` on channel 0 (the recording's current channel) with the fitted coefficients, µT/A.
    pub effect: Effect,
    /// Standard errors of the coefficients, µT/A.
    pub coef_se_ut_per_a: [f64; 3],
    /// The evidence it was kept with (the Wald statistic less its penalty, σ² units).
    pub evidence: f64,
    /// The lag, when the scan identifies it.
    pub lag: Option<Lag>,
}

impl CurrentTerm {
    /// The fitted coefficients, µT/A.
    pub fn coef_ut_per_a(&self) -> [f64; 3] {
        match self.effect {
            Effect::CurrentBias { coef_ut_per_a, .. } => coef_ut_per_a,
            _ => unreachable!("a current term is current_bias"),
        }
    }
}

/// The widest half-width of a lag's profile interval (one standard deviation) for the lag to count as determined, s:
/// two standard deviations within 5 ms.
pub const MAX_LAG_HALF_WIDTH_S: f64 = 0.0025;
/// The most field sample intervals between changes of the recorded current (the median) for the lag to count as
/// determined: a current measured less often than the field is held between measurements, late by up to that.
pub const MAX_CURRENT_UPDATE_INTERVALS: f64 = 1.5;

/// The current's lag behind the field (positive: the field follows the recorded current late).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lag {
    /// The lag with the least residual, s.
    pub lag_s: f64,
    /// Its profile interval (one standard deviation), s.
    pub interval_s: (f64, f64),
    /// The field's sample interval (the mean), s.
    pub sample_interval_s: f64,
    /// The median time between changes of the recorded current, s: the battery monitor's own interval when it
    /// measures less often than the field is sampled (ArduCopter reads it at 10 Hz).
    pub current_update_s: f64,
}

impl Lag {
    /// Half the width of the profile interval, s.
    pub fn half_width_s(&self) -> f64 {
        (self.interval_s.1 - self.interval_s.0) / 2.0
    }

    /// Whether the current was measured about as often as the field was sampled (at most
    /// [`MAX_CURRENT_UPDATE_INTERVALS`] sample intervals between its changes). Otherwise the recorded current is
    /// held between measurements and the lag found is off by tens of milliseconds (−12 ms with a 25 Hz current and
    /// a 50 Hz field, −64 ms at 10 Hz, in simulated tests), which its profile interval does not know.
    pub fn current_keeps_up(&self) -> bool {
        self.current_update_s <= MAX_CURRENT_UPDATE_INTERVALS * self.sample_interval_s
    }

    /// Whether the lag means something: the current kept up with the field
    /// ([`current_keeps_up`](Self::current_keeps_up)) and the profile interval is at most [`MAX_LAG_HALF_WIDTH_S`]
    /// either side.
    pub fn determined(&self) -> bool {
        self.current_keeps_up() && self.half_width_s() <= MAX_LAG_HALF_WIDTH_S
    }
}

/// What the fit of a motors recording gives.
#[derive(Clone, Debug, PartialEq)]
pub struct MotorFit {
    /// Rows used (both field and current present).
    pub samples: usize,
    /// The field at zero current, calibrated sensor axes, µT.
    pub offset_ut: [f64; 3],
    /// The current term, if the selection kept it.
    pub current: Option<CurrentTerm>,
    /// Why the term could not be tested, when it could not (the current did not vary, or the base absorbs it).
    pub untestable: Option<&'static str>,
    /// RMS residual per axis of the final model, µT.
    pub residual_rms_ut: f64,
    /// RMS residual per axis of the constant field alone, µT.
    pub constant_rms_ut: f64,
    /// The final residual's autocorrelation factor (1 for white noise).
    pub autocorrelation: f64,
}

/// Fits the current term of a motors recording; see the [module docs](self).
pub fn fit_motors(input: &MotorInput<'_>) -> Result<MotorFit, FitError> {
    let rows: Vec<usize> = (0..input.t_s.len())
        .filter(|&i| {
            input.current_a[i].is_finite() && input.field_ut[i].iter().all(|v| v.is_finite())
        })
        .collect();
    if rows.len() < MIN_SAMPLES {
        return Err(FitError::TooFewSamples {
            needed: MIN_SAMPLES,
            got: rows.len(),
        });
    }
    let mut cand = Candidate {
        template: Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: [0.0; 3],
        },
        n: 3,
        first: BASE.len(),
        channel: None,
        supersedes: None,
        scan_penalty: 0.0,
        scan: None,
        forced: false,
        active_rows: 0,
    };
    let problem = problem_at(input, &rows, 0.0, &mut cand);
    let floor2 = input.noise_floor_ut.iter().map(|f| f * f).sum::<f64>() / 3.0;
    let selection = select(
        &problem,
        &BASE,
        std::slice::from_ref(&cand),
        &[],
        floor2,
        MIN_EXCESS_SHARE,
    )
    .ok_or(FitError::Singular(
        "the motor test's constant field has no solution",
    ))?;
    let untestable = selection.set_aside.first().map(|(_, why)| match why {
        SetAside::NotExcited => EffectId::CurrentBias.descriptor().not_excited,
        SetAside::Absorbed { .. } => {
            "the current barely varied against its mean during the recording"
        }
    });
    let rms = |p: &Problem, sol: &Solution| (sol.rss / p.total.rows.max(1) as f64).sqrt();
    let constant_rms_ut = rms(&problem, &selection.base);
    let Some(step) = selection.steps.first() else {
        return Ok(MotorFit {
            samples: rows.len(),
            offset_ut: coefficients(&selection.base, 0),
            current: None,
            untestable,
            residual_rms_ut: constant_rms_ut,
            constant_rms_ut,
            autocorrelation: problem.autocorrelation(&selection.base),
        });
    };
    let evidence = step.evidence;
    let lag = scan_lag(input, &rows, &mut cand);
    let (problem, sol) = match lag {
        Some(l) => {
            let p = problem_at(input, &rows, l.lag_s, &mut cand);
            let sol = p
                .solve(&(0..COLUMNS).collect::<Vec<_>>(), None, false)
                .ok_or(FitError::Singular(
                    "the motor test's current term has no solution",
                ))?;
            (p, sol)
        }
        None => (problem, selection.last.clone()),
    };
    let se = standard_errors(&problem, &sol);
    Ok(MotorFit {
        samples: rows.len(),
        offset_ut: coefficients(&sol, 0),
        current: Some(CurrentTerm {
            effect: cand.template.with_params(coefficients(&sol, BASE.len())),
            coef_se_ut_per_a: std::array::from_fn(|k| se[BASE.len() + k]),
            evidence,
            lag,
        }),
        untestable: None,
        residual_rms_ut: rms(&problem, &sol),
        constant_rms_ut,
        autocorrelation: problem.autocorrelation(&sol),
    })
}

/// Columns `first..first + 3` of a solution (zero where left out).
fn coefficients(sol: &Solution, first: usize) -> [f64; 3] {
    std::array::from_fn(|k| {
        sol.columns
            .iter()
            .position(|&c| c == first + k)
            .map_or(0.0, |p| sol.beta[p])
    })
}

/// Per column of the problem, the larger of the two standard errors (residual variance, cluster-robust).
fn standard_errors(problem: &Problem, sol: &Solution) -> [f64; COLUMNS] {
    let model: DMatrix<f64> = problem.model_covariance(sol);
    let cluster = problem.cluster_covariance(sol);
    let mut se = [0.0; COLUMNS];
    for (p, &c) in sol.columns.iter().enumerate() {
        let var = cluster
            .as_ref()
            .map_or(model[(p, p)], |cl| cl[(p, p)].max(model[(p, p)]));
        se[c] = var.max(0.0).sqrt();
    }
    se
}

/// The current at `t_s`, linearly interpolated between the rows (held at the ends).
fn current_at(input: &MotorInput<'_>, rows: &[usize], t_s: f64) -> f64 {
    let (t, i) = (input.t_s, input.current_a);
    let after = rows.partition_point(|&r| t[r] <= t_s);
    match after {
        0 => i[rows[0]],
        n if n == rows.len() => i[rows[n - 1]],
        n => {
            let (a, b) = (rows[n - 1], rows[n]);
            let span = t[b] - t[a];
            if span <= 0.0 {
                i[b]
            } else {
                i[a] + (i[b] - i[a]) * (t_s - t[a]) / span
            }
        }
    }
}

/// The normal equations with the current taken at `t − lag_s`, per block and batch, three rows per sample (one per
/// calibrated axis); counts where the current term acts into `cand`.
fn problem_at(input: &MotorInput<'_>, rows: &[usize], lag_s: f64, cand: &mut Candidate) -> Problem {
    let probes = cand.probes();
    let n = rows.len();
    let mut blocks = vec![BlockStats::new(COLUMNS); CV_BLOCKS];
    let mut batch_stats = vec![BlockStats::new(COLUMNS); AUTOCORRELATION_BATCHES];
    let mut by_kind = vec![BlockStats::new(COLUMNS); 3];
    let mut batches = Batches::new(AUTOCORRELATION_BATCHES, 3, COLUMNS);
    let mut active = 0;
    for batch in 0..AUTOCORRELATION_BATCHES {
        let block = batch / (AUTOCORRELATION_BATCHES / CV_BLOCKS);
        let first = (batch * n).div_ceil(AUTOCORRELATION_BATCHES);
        let end = ((batch + 1) * n).div_ceil(AUTOCORRELATION_BATCHES);
        for &i in &rows[first..end] {
            let t_s = input.t_s[i];
            let current = [current_at(input, rows, t_s - lag_s)];
            let regs =
                probes.regressors(&Context::body(t_s, f64::NAN, &current, input.field_ut[i]));
            for j in 0..3 {
                let mut entries = vec![(j, 1.0)];
                entries.extend(
                    (0..3)
                        .filter(|&k| regs[k][j] != 0.0)
                        .map(|k| (BASE.len() + k, regs[k][j])),
                );
                active += usize::from(entries.len() > 1);
                let y = input.field_ut[i][j];
                blocks[block].add_row(&entries, y);
                batch_stats[batch].add_row(&entries, y);
                by_kind[j].add_row(&entries, y);
                batches.add_row(batch, j, &entries, y);
                by_kind[j].samples += 1;
            }
            blocks[block].samples += 1;
            batch_stats[batch].samples += 1;
        }
    }
    cand.active_rows = active;
    let clean = blocks.clone();
    Problem::new(
        blocks,
        clean,
        batches,
        batch_stats,
        by_kind,
        nalgebra::DVector::zeros(COLUMNS),
    )
}

/// The lag, scanned over whole sample intervals up to `max_lag_s` either way, when its profile interval lies inside
/// that grid; `None` otherwise (the lag is then taken as zero). Between two of the grid's points the current is
/// linear in the lag (interpolated between its samples), so the residual is a parabola there: the one through each
/// interval next to the best whole lag (its ends and its middle) gives the least residual, and the interval where the
/// residual stays within one autocorrelation-scaled residual variance of it. (One parabola through three whole lags
/// would misplace both: with a quick step of the current, rising in a few tens of milliseconds, the residual is far
/// from one parabola over two sample intervals, and its slope changes at every whole lag.)
fn scan_lag(input: &MotorInput<'_>, rows: &[usize], cand: &mut Candidate) -> Option<Lag> {
    let t = input.t_s;
    let (first, last) = (t[rows[0]], t[rows[rows.len() - 1]]);
    let dt = (last - first) / (rows.len() - 1) as f64;
    // NaN is no positive number either.
    if dt.is_nan() || dt <= 0.0 || input.max_lag_s.is_nan() || input.max_lag_s <= 0.0 {
        return None;
    }
    let steps = ((input.max_lag_s / dt).round() as usize).min(MAX_LAG_STEPS);
    if steps == 0 {
        return None;
    }
    let all: Vec<usize> = (0..COLUMNS).collect();
    let mut fit_at = |lag: f64| {
        let p = problem_at(input, rows, lag, cand);
        let sol = p.solve(&all, None, false);
        let tau = sol.as_ref().map_or(1.0, |s| p.autocorrelation(s));
        (sol.map_or(f64::INFINITY, |s| s.rss), tau)
    };
    let lags: Vec<f64> = (0..=2 * steps)
        .map(|m| (m as f64 - steps as f64) * dt)
        .collect();
    let fits: Vec<(f64, f64)> = lags.iter().map(|&lag| fit_at(lag)).collect();
    let best = (0..fits.len()).min_by(|&a, &b| fits[a].0.total_cmp(&fits[b].0))?;
    if best == 0 || best == fits.len() - 1 {
        return None;
    }
    let (rss, tau) = fits[best];
    let dof = (3 * rows.len() - COLUMNS) as f64;
    let within = tau * rss / dof;
    let lo = (0..=best)
        .rev()
        .take_while(|&m| fits[m].0 <= rss + within)
        .last()?;
    let hi = (best..fits.len())
        .take_while(|&m| fits[m].0 <= rss + within)
        .last()?;
    if lo == 0 || hi == fits.len() - 1 {
        return None;
    }
    // Between two samples the current is linear in the lag, so the residual is a quadratic: one through each
    // neighbouring interval's ends and middle.
    let left = Quadratic::through(fits[best - 1].0, fit_at(lags[best] - dt / 2.0).0, rss);
    let right = Quadratic::through(rss, fit_at(lags[best] + dt / 2.0).0, fits[best + 1].0);
    // The least residual, at u in [0, 1] of either interval (from its earlier end).
    let (l_u, l_r) = left.least();
    let (r_u, r_r) = right.least();
    let (least_s, least) = if l_r < r_r {
        (lags[best - 1] + l_u * dt, l_r)
    } else {
        (lags[best] + r_u * dt, r_r)
    };
    let target = least + within;
    // Where the residual rises past one variance above its least: on the left interval's parabola unless it stays
    // above that throughout, then on the right's; and the other way round.
    let below = |q: &Quadratic| q.roots(target).filter(|&(lo, hi)| hi >= 0.0 && lo <= 1.0);
    let lo_s = match below(&left) {
        Some((lo, _)) => lags[best - 1] + lo * dt,
        None => lags[best] + below(&right)?.0 * dt,
    };
    let hi_s = match below(&right) {
        Some((_, hi)) => lags[best] + hi * dt,
        None => lags[best - 1] + below(&left)?.1 * dt,
    };
    Some(Lag {
        lag_s: least_s,
        interval_s: (lo_s, hi_s),
        sample_interval_s: dt,
        current_update_s: current_update_s(input, rows),
    })
}

/// `r(u) = a + b·u + c·u²`: the residual over one sample interval of the lag (`u` from 0 to 1).
#[derive(Clone, Copy, Debug)]
struct Quadratic {
    a: f64,
    b: f64,
    c: f64,
}

impl Quadratic {
    /// Through the values at `u` = 0, ½ and 1.
    fn through(at0: f64, half: f64, at1: f64) -> Quadratic {
        let c = 2.0 * (at0 + at1 - 2.0 * half);
        Quadratic {
            a: at0,
            b: at1 - at0 - c,
            c,
        }
    }

    fn at(&self, u: f64) -> f64 {
        self.a + u * (self.b + u * self.c)
    }

    /// The least value on [0, 1] and where it is.
    fn least(&self) -> (f64, f64) {
        let vertex = if self.c > 0.0 {
            (-self.b / (2.0 * self.c)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        [vertex, 0.0, 1.0]
            .into_iter()
            .map(|u| (u, self.at(u)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .expect("three points")
    }

    /// Where it equals `level`, the lower root first (the parabola extended beyond [0, 1]); `None` when it stays
    /// above `level` or does not open upwards.
    fn roots(&self, level: f64) -> Option<(f64, f64)> {
        if self.c.is_nan() || self.c <= 0.0 {
            return None;
        }
        let vertex = -self.b / (2.0 * self.c);
        let depth = level - self.at(vertex);
        (depth >= 0.0).then(|| {
            let half = (depth / self.c).sqrt();
            (vertex - half, vertex + half)
        })
    }
}

/// The median time between changes of the recorded current over `rows`, s (infinite when it changes less than
/// twice).
fn current_update_s(input: &MotorInput<'_>, rows: &[usize]) -> f64 {
    let changes: Vec<f64> = rows
        .windows(2)
        .filter(|w| input.current_a[w[1]] != input.current_a[w[0]])
        .map(|w| input.t_s[w[1]])
        .collect();
    let mut gaps: Vec<f64> = changes.windows(2).map(|w| w[1] - w[0]).collect();
    if gaps.is_empty() {
        return f64::INFINITY;
    }
    gaps.sort_by(f64::total_cmp);
    gaps[gaps.len() / 2]
}

/// The heading error, degrees, that the current term `effect` makes at `current_a` with the sensor held at
/// `sensor_to_ned` in the world field `field_ned_ut`: the angle between the field's horizontal part and that part
/// with the term's field added (what a compensation of it removes). NaN when the field has no horizontal part.
pub fn heading_error_deg(
    effect: &Effect,
    current_a: f64,
    sensor_to_ned: &Mat3,
    field_ned_ut: [f64; 3],
) -> f64 {
    let current = [current_a];
    let delta_ned = frames::mat_vec(
        sensor_to_ned,
        effect.perturbation_ut(&Context::body(0.0, f64::NAN, &current, [0.0; 3])),
    );
    let (n, e) = (field_ned_ut[0], field_ned_ut[1]);
    if n.hypot(e) == 0.0 {
        return f64::NAN;
    }
    let (n2, e2) = (n + delta_ned[0], e + delta_ned[1]);
    (n * e2 - e * n2).atan2(n * n2 + e * e2).abs().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A still recording: a current ramping up and down, a constant field plus `coef·I`, white noise from a
    /// fixed-seed generator.
    fn recording(coef: [f64; 3], lag_s: f64, noise_ut: f64) -> (Vec<f64>, Vec<[f64; 3]>, Vec<f64>) {
        recording_seeded(coef, lag_s, noise_ut, 0.0, 0)
    }

    /// Standard normal draws: Box–Muller from a xorshift stream seeded with `seed`.
    struct Gauss(u64);

    impl Gauss {
        fn new(seed: u64) -> Gauss {
            Gauss(0x2545_f491_4f6c_dd1du64 ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15))
        }

        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }

        fn draw(&mut self) -> f64 {
            let (a, b) = (self.uniform().max(1e-300), self.uniform());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        }
    }

    /// [`recording`] with AR(1) noise of coefficient `rho` (its variance `noise_ut²` whatever `rho`), from `seed`.
    fn recording_seeded(
        coef: [f64; 3],
        lag_s: f64,
        noise_ut: f64,
        rho: f64,
        seed: u64,
    ) -> (Vec<f64>, Vec<[f64; 3]>, Vec<f64>) {
        let n = 3000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.02).collect();
        let current = |t: f64| 2.0 + 14.0 * (1.0 - (std::f64::consts::TAU * t / 7.0).cos());
        let mut gauss = Gauss::new(seed);
        let b0 = [20.0, -5.0, 40.0];
        let mut e = [0.0; 3];
        let innovation = (1.0 - rho * rho).sqrt();
        let field = t
            .iter()
            .map(|&t| {
                std::array::from_fn(|j| {
                    e[j] = rho * e[j] + innovation * noise_ut * gauss.draw();
                    b0[j] + coef[j] * current(t - lag_s) + e[j]
                })
            })
            .collect();
        let i = t.iter().map(|&t| current(t)).collect();
        (t, field, i)
    }

    /// The motors routine's current at `t_s`: two slow ramps from 2 to 30 A and back over 7 s each, then `blips`
    /// steps to 30 A and back (1 s at idle, 0.5 s high), the current following each step of the throttle with a
    /// time constant of 40 ms.
    fn routine_current(t_s: f64, blips: u32) -> f64 {
        if t_s < 14.0 || blips == 0 {
            return 2.0 + 14.0 * (1.0 - (std::f64::consts::TAU * t_s.max(0.0) / 7.0).cos());
        }
        let step = |since_s: f64| {
            if since_s > 0.0 {
                1.0 - (-since_s / 0.04).exp()
            } else {
                0.0
            }
        };
        let u = t_s - 14.0;
        let share: f64 = (0..blips)
            .map(|n| {
                let up = 1.5 * f64::from(n) + 1.0;
                step(u - up) - step(u - up - 0.5)
            })
            .sum();
        2.0 + 28.0 * share
    }

    /// A 50 Hz still recording of the motors routine ([`routine_current`]) until 1 s after the last blip, the field
    /// `coef·I(t − lag_s)` plus white noise of `noise_ut`; the current recorded as a battery monitor measuring it
    /// `battery_hz` times a second gives it (the last measurement at each row; 0: the current at the row).
    fn routine_recording(
        coef: [f64; 3],
        lag_s: f64,
        noise_ut: f64,
        blips: u32,
        battery_hz: f64,
        seed: u64,
    ) -> (Vec<f64>, Vec<[f64; 3]>, Vec<f64>) {
        let duration_s = 14.0 + 1.5 * f64::from(blips) + 1.0;
        let t: Vec<f64> = (0..(duration_s * 50.0) as usize)
            .map(|i| i as f64 * 0.02)
            .collect();
        let mut gauss = Gauss::new(seed);
        let field = t
            .iter()
            .map(|&t| {
                std::array::from_fn(|j| {
                    20.0 + coef[j] * routine_current(t - lag_s, blips) + noise_ut * gauss.draw()
                })
            })
            .collect();
        let measured = |t: f64| {
            if battery_hz > 0.0 {
                (t * battery_hz + 1e-9).floor() / battery_hz
            } else {
                t
            }
        };
        let i = t
            .iter()
            .map(|&t| routine_current(measured(t), blips))
            .collect();
        (t, field, i)
    }

    fn fit(coef: [f64; 3], lag_s: f64) -> MotorFit {
        let (t, field, i) = recording(coef, lag_s, 0.1);
        fit_on(&t, &field, &i, 0.1)
    }

    /// The fit of a recording with a noise floor of `floor_ut` on each axis, lags scanned up to 0.5 s.
    fn fit_on(t: &[f64], field: &[[f64; 3]], current: &[f64], floor_ut: f64) -> MotorFit {
        fit_motors(&MotorInput {
            t_s: t,
            field_ut: field,
            current_a: current,
            noise_floor_ut: [floor_ut; 3],
            max_lag_s: 0.5,
        })
        .unwrap()
    }

    #[test]
    fn the_coefficients_and_a_lag_are_recovered_within_their_errors() {
        let coef = [0.05, -1.0, 0.3];
        let f = fit(coef, 0.1);
        let term = f.current.expect("a current term");
        let (got, se) = (term.coef_ut_per_a(), term.coef_se_ut_per_a);
        for k in 0..3 {
            assert!((got[k] - coef[k]).abs() <= 3.0 * se[k], "{got:?} ± {se:?}");
        }
        let lag = term.lag.expect("the lag is identified");
        assert!(
            lag.interval_s.0 < 0.1
                && lag.interval_s.1 > 0.1
                && lag.interval_s.1 - lag.interval_s.0 < 0.02,
            "{lag:?}"
        );
        assert!(
            (f.residual_rms_ut - 0.1).abs() < 0.01,
            "{}",
            f.residual_rms_ut
        );
        for j in 0..3 {
            assert!((f.offset_ut[j] - [20.0, -5.0, 40.0][j]).abs() < 0.05);
        }
    }

    /// 0.05 µT/A on each axis (the bottom of acceptance 2's range) under 0.34 µT of noise, a 20 ms lag: the slow ramps
    /// alone leave the lag's interval about ±15 ms, not determined; ten blips after them determine it within 5 ms.
    #[test]
    fn a_small_coefficient_needs_the_blips_for_its_lag() {
        let coef = [0.05, -0.05, 0.05];
        let lag_of = |blips| {
            let (t, field, i) = routine_recording(coef, 0.02, 0.34, blips, 0.0, 7);
            let f = fit_on(&t, &field, &i, 0.34);
            f.current.expect("a current term").lag.expect("a lag")
        };
        let ramps = lag_of(0);
        assert!(
            !ramps.determined() && ramps.half_width_s() > 0.008,
            "{ramps:?}"
        );
        let blips = lag_of(10);
        assert!(blips.determined(), "{blips:?}");
        assert!((blips.lag_s - 0.02).abs() <= 0.005, "{blips:?}");
    }

    /// The lag's error and interval over 50 simulated routines (two ramps, ten blips; lags of 5 to 50 ms) per size of
    /// coefficient (on each axis) and per rate at which the battery monitor measures the current (the field at 50 Hz):
    /// how a 10–50 Hz current limits the lag. Asserted: with the current measured at each row every lag is within
    /// 5 ms and determined from 0.05 µT/A up; measured at 25 or 10 Hz, none is said determined.
    #[test]
    #[ignore = "a study: cargo test --release -- --ignored"]
    fn the_lag_over_coefficients_and_current_rates() {
        let mut failed = Vec::new();
        for battery_hz in [0.0, 25.0, 10.0] {
            for size in [0.05, 0.1, 0.3, 1.0] {
                let coef = [size, -size, size];
                let (mut errors, mut halves, mut determined) = (Vec::new(), Vec::new(), 0);
                let mut coef_error = 0.0f64;
                for seed in 0..50u64 {
                    let lag_s = 0.005 + 0.045 * seed as f64 / 49.0;
                    let (t, field, i) =
                        routine_recording(coef, lag_s, 0.34, 10, battery_hz, 500 + seed);
                    let f = fit_on(&t, &field, &i, 0.34);
                    let term = f.current.expect("a current term");
                    for k in 0..3 {
                        coef_error =
                            coef_error.max((term.coef_ut_per_a()[k] / coef[k] - 1.0).abs());
                    }
                    let lag = term.lag;
                    let Some(lag) = lag else {
                        errors.push(f64::NAN);
                        continue;
                    };
                    errors.push(lag.lag_s - lag_s);
                    halves.push(lag.half_width_s());
                    determined += usize::from(lag.determined());
                }
                let n = errors.len() as f64;
                let mean = errors.iter().sum::<f64>() / n;
                let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
                let worst = errors.iter().fold(0.0f64, |w, e| w.max(e.abs()));
                let half = halves.iter().sum::<f64>() / halves.len().max(1) as f64;
                let within = errors.iter().filter(|e| e.abs() <= 0.005).count();
                println!(
                    "current at {}: {size} µT/A: lag error mean {:+.1} ms, RMS {:.1} ms, worst {:.1} ms, within \
                     5 ms {within}/50; interval ±{:.1} ms; determined {determined}/50; coefficients within \
                     {:.1} %",
                    if battery_hz > 0.0 {
                        format!("{battery_hz} Hz")
                    } else {
                        "each row (50 Hz)".to_owned()
                    },
                    1e3 * mean,
                    1e3 * rms,
                    1e3 * worst,
                    1e3 * half,
                    100.0 * coef_error
                );
                let held = battery_hz > 0.0;
                if (!held && (within < 50 || determined < 50)) || (held && determined > 0) {
                    failed.push((battery_hz, size));
                }
            }
        }
        assert!(failed.is_empty(), "(current rate, µT/A): {failed:?}");
    }

    /// How often the true coefficient lies within two standard errors, over 200 simulated tests with a lag, with
    /// white noise and with noise whose neighbouring samples are alike (AR(1), 0.95 from one sample to the next):
    /// about 95 % if the errors are honest. Measured: 95.7 % and 92.7 % (the cluster-robust errors a little short when
    /// the noise's correlation time nears the batches' length).
    #[test]
    #[ignore = "a study: cargo test --release -- --ignored"]
    fn two_standard_errors_hold_the_truth_95_times_in_100() {
        for rho in [0.0, 0.95] {
            let share = coverage_of_two_standard_errors(rho);
            assert!(share > 0.9, "AR(1) {rho}: {share}");
        }
    }

    fn coverage_of_two_standard_errors(rho: f64) -> f64 {
        let coef = [0.05, -1.0, 0.3];
        let (mut within, mut all) = (0, 0);
        for seed in 1..=200 {
            let (t, field, i) = recording_seeded(coef, 0.013, 0.3, rho, seed);
            let f = fit_on(&t, &field, &i, 0.3);
            let term = f.current.unwrap();
            for k in 0..3 {
                all += 1;
                within += usize::from(
                    (term.coef_ut_per_a()[k] - coef[k]).abs() <= 2.0 * term.coef_se_ut_per_a[k],
                );
            }
        }
        let share = within as f64 / all as f64;
        println!(
            "AR(1) {rho}: within two standard errors: {within} of {all} ({:.1} %)",
            100.0 * share
        );
        share
    }

    /// How often a current term is reported when there is none, over 200 simulated tests with white noise and 200
    /// with AR(1) noise (0.95 from one sample to the next). Measured: 0 and 8 of 200. The second is the selection's
    /// own limit: its autocorrelation factor comes from the means of 100 batches, here 30 samples each, which
    /// a correlation time of 20 samples outlasts, so the factor is underestimated and the Wald test is liberal.
    #[test]
    #[ignore = "a study: cargo test --release -- --ignored"]
    fn no_current_term_is_found_in_200_null_tests() {
        for rho in [0.0, 0.95] {
            let found = (1..=200u64)
                .filter(|&seed| {
                    let (t, field, i) = recording_seeded([0.0; 3], 0.0, 0.3, rho, 1000 + seed);
                    fit_on(&t, &field, &i, 0.3).current.is_some()
                })
                .count();
            println!("AR(1) {rho}: a current term found in {found} of 200 null tests");
            assert!(
                found <= if rho > 0.0 { 12 } else { 2 },
                "AR(1) {rho}: {found}"
            );
        }
    }

    #[test]
    fn no_current_term_without_one_and_none_testable_without_a_varying_current() {
        let f = fit([0.0; 3], 0.0);
        assert!(f.current.is_none() && f.untestable.is_none(), "{f:?}");
        let (t, field, _) = recording([0.0; 3], 0.0, 0.1);
        let steady = vec![3.0; t.len()];
        let f = fit_on(&t, &field, &steady, 0.1);
        assert!(f.current.is_none() && f.untestable.is_some(), "{f:?}");
    }

    /// A field of 3 µT east at 10 A in a level sensor facing north, under 20 µT of horizontal field: atan(3/20).
    #[test]
    fn the_heading_error_is_the_turn_of_the_horizontal_field() {
        let effect = Effect::CurrentBias {
            channel: 0,
            coef_ut_per_a: [0.0, 0.3, 5.0],
        };
        let level = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let got = heading_error_deg(&effect, 10.0, &level, [20.0, 0.0, 45.0]);
        assert!(
            (got - (3.0f64 / 20.0).atan().to_degrees()).abs() < 1e-12,
            "{got}"
        );
        assert!(heading_error_deg(&effect, 10.0, &level, [0.0, 0.0, 45.0]).is_nan());
    }
}
