//! Scans for the effects with a time hyperparameter: where a bias step happened, and when a transient disturbance
//! started and ended. Each scan maximises a likelihood-ratio statistic (in units of the noise variance, so a
//! difference of 1 is one σ of evidence) over every split, from prefix sums in O(N), and reports the profile interval
//! (the times whose statistic is within 1 of the best) as the hyperparameter's uncertainty.

use nalgebra::{Matrix3, Vector3};

use crate::{chunks, frames};

/// A scanned hyperparameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Scan {
    /// Sample index where the step starts (or the window starts).
    pub start: usize,
    /// One past the window's last sample (the step: the end of the recording).
    pub end: usize,
    /// The best statistic, σ² units.
    pub stat: f64,
    /// Profile interval of the start, sample indices.
    pub start_interval: (usize, usize),
    /// Profile interval of the end, sample indices.
    pub end_interval: (usize, usize),
}

impl Scan {
    /// The scan of a subset of samples (`index`: each of its samples' index among all `n`) in the indices of all
    /// of them; the subset's end is `n`.
    pub(crate) fn through(self, index: &[usize], n: usize) -> Scan {
        let back = |k: usize| index.get(k).copied().unwrap_or(n);
        Scan {
            start: back(self.start),
            end: back(self.end),
            stat: self.stat,
            start_interval: (back(self.start_interval.0), back(self.start_interval.1)),
            end_interval: (back(self.end_interval.0), back(self.end_interval.1)),
        }
    }
}

/// Fewest samples on either side of a split.
const MIN_SIDE: usize = 10;

/// The most likely bias step in a vector residual `e` (body axes). A step `s` at `k` makes the residual's mean
/// differ by `s` after `k`; with the offset `b` absorbing the overall mean, the statistic is
/// `k(N−k)/N·|mean_after − mean_before|² / σ²`.
pub(crate) fn step_vector(e: &[[f64; 3]], sigma2: f64) -> Option<Scan> {
    let n = e.len();
    if n < 2 * MIN_SIDE {
        return None;
    }
    let total = e.iter().fold([0.0; 3], |s, v| frames::add(s, *v));
    let mut prefix = [0.0; 3];
    let mut stats = vec![f64::NEG_INFINITY; n];
    for k in 1..n {
        prefix = frames::add(prefix, e[k - 1]);
        if k < MIN_SIDE || n - k < MIN_SIDE {
            continue;
        }
        let (kf, nf) = (k as f64, n as f64);
        let before = frames::scale(prefix, 1.0 / kf);
        let after = frames::scale(frames::sub(total, prefix), 1.0 / (nf - kf));
        let d = frames::sub(after, before);
        stats[k] = kf * (nf - kf) / nf * frames::dot(d, d) / sigma2;
    }
    best_split(&stats, n)
}

/// The most likely bias step in a scalar (magnitude) residual `rho` with field directions `u`: the step shows as
/// `u·s`, and the offset `b` absorbs `u·b'` throughout.
pub(crate) fn step_scalar(rho: &[f64], u: &[[f64; 3]], sigma2: f64) -> Option<Scan> {
    let n = rho.len();
    if n < 2 * MIN_SIDE {
        return None;
    }
    let (mut m_all, mut v_all) = (Matrix3::zeros(), Vector3::zeros());
    for (r, d) in rho.iter().zip(u) {
        let d = Vector3::from(*d);
        m_all += d * d.transpose();
        v_all += d * *r;
    }
    let m_inv = m_all.try_inverse()?;
    let (mut m_tail, mut v_tail) = (m_all, v_all);
    let mut stats = vec![f64::NEG_INFINITY; n];
    for k in 1..n {
        let d = Vector3::from(u[k - 1]);
        m_tail -= d * d.transpose();
        v_tail -= d * rho[k - 1];
        if k < MIN_SIDE || n - k < MIN_SIDE {
            continue;
        }
        // Partitioned regression: the step's part after removing what the offset explains.
        let s = m_tail - m_tail * m_inv * m_tail;
        let r = v_tail - m_tail * m_inv * v_all;
        if let Some(s_inv) = s.try_inverse() {
            stats[k] = r.dot(&(s_inv * r)) / sigma2;
        }
    }
    best_split(&stats, n)
}

fn best_split(stats: &[f64], n: usize) -> Option<Scan> {
    let (k, &stat) = stats.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    if !stat.is_finite() {
        return None;
    }
    let interval = profile(|i| stats[i], stats.len(), k, stat);
    Some(Scan {
        start: k,
        end: n,
        stat,
        start_interval: interval,
        end_interval: (n, n),
    })
}

/// The contiguous run of indices (of `0..len`) around `best` whose statistic is within 1 of the maximum.
fn profile(stats: impl Fn(usize) -> f64, len: usize, best: usize, max: f64) -> (usize, usize) {
    let within = |i: usize| stats(i) >= max - 1.0;
    let mut lo = best;
    while lo > 0 && within(lo - 1) {
        lo -= 1;
    }
    let mut hi = best;
    while hi + 1 < len && within(hi + 1) {
        hi += 1;
    }
    (lo, hi)
}

/// Candidate boundaries on the coarse grid of the window scan.
const WINDOW_GRID: usize = 400;
/// A disturbance covers at most this fraction of the recording (a longer one is a field error, not a transient).
const WINDOW_MAX_FRACTION: f64 = 0.8;

/// The most likely window of a world-fixed disturbance in a vector residual seen through the attitude, `world`
/// (`R·e` per sample, NED): the disturbance is a constant `d` there inside the window, so the statistic is
/// `|Σ_window R·e|² / (L·σ²)`. Coarse grid first, then each boundary refined at sample resolution
/// ([`best_window`]).
pub(crate) fn window(world: &[[f64; 3]], sigma2: f64) -> Option<Scan> {
    let n = world.len();
    if n < 4 * MIN_SIDE {
        return None;
    }
    let mut prefix = vec![[0.0; 3]; n + 1];
    for i in 0..n {
        prefix[i + 1] = frames::add(prefix[i], world[i]);
    }
    let max_len = (WINDOW_MAX_FRACTION * n as f64) as usize;
    best_window(n, |a, b| {
        if b <= a + MIN_SIDE || b - a > max_len {
            return f64::NEG_INFINITY;
        }
        let sum = frames::sub(prefix[b], prefix[a]);
        frames::dot(sum, sum) / ((b - a) as f64 * sigma2)
    })
}

/// Regressors of the scan of a window of a field fixed to the sensor in a magnitude: a constant and the field
/// direction's three components.
const TERMS: usize = 4;
type Terms = nalgebra::SMatrix<f64, TERMS, TERMS>;
type TermVec = nalgebra::SVector<f64, TERMS>;

/// Sums of `xxᵀ` and `x·rho` over samples, `x = [1, u]`; `xxᵀ[(0, 0)]` counts the samples.
#[derive(Clone, Copy)]
struct TermSums {
    xx: Terms,
    xr: TermVec,
}

impl TermSums {
    fn zero() -> Self {
        Self {
            xx: Terms::zeros(),
            xr: TermVec::zeros(),
        }
    }

    fn sub(self, other: Self) -> Self {
        Self {
            xx: self.xx - other.xx,
            xr: self.xr - other.xr,
        }
    }
}

/// The samples a directions scan sees: the residual `rho` and the field direction `u` where `free`; the others
/// count as absent.
struct Directional<'a> {
    rho: &'a [f64],
    u: &'a [[f64; 3]],
    free: &'a [bool],
}

impl Directional<'_> {
    /// The sums over `[a, b)` added to `from`.
    fn add(&self, mut from: TermSums, a: usize, b: usize) -> TermSums {
        for i in (a..b).filter(|&i| self.free[i]) {
            let [x, y, z] = self.u[i];
            let x = TermVec::new(1.0, x, y, z);
            from.xx += x * x.transpose();
            from.xr += x * self.rho[i];
        }
        from
    }

    /// The prefix sums at `lo..=hi`, from the prefix sum `at_lo` at `lo`.
    fn prefix(&self, at_lo: TermSums, lo: usize, hi: usize) -> Vec<TermSums> {
        let mut out = Vec::with_capacity(hi - lo + 1);
        out.push(at_lo);
        for i in lo..hi {
            let last = *out.last().expect("one pushed");
            out.push(self.add(last, i, i + 1));
        }
        out
    }
}

/// A window the directions scan found, with the RMS over it of the terms it fits there (`rho`'s units).
pub(crate) struct DirectionsWindow {
    pub scan: Scan,
    pub terms_rms: f64,
}

/// The most likely window of a field fixed to the sensor (or to the room) in a scalar (magnitude) residual `rho`
/// with field directions `u`, among the samples `free` (a window's length counts those): inside it the residual
/// moves by `c + d·u` (a field `d` fixed to the sensor shows in |B| along the field's direction; `c` is what a field
/// fixed in the room leaves there), against the same terms fitted to all samples (partitioned regression). The
/// statistic is the window terms' explained sum of squares in units of `sigma2` (χ² with four degrees of freedom
/// under noise alone). Grid and refinement as [`window`], from prefix sums kept only at the grid's boundaries and
/// near the two being refined: a few hundred sums, whatever the recording's length.
pub(crate) fn window_with_directions(
    rho: &[f64],
    u: &[[f64; 3]],
    free: &[bool],
    sigma2: f64,
) -> Option<DirectionsWindow> {
    let n = rho.len();
    let d = Directional { rho, u, free };
    let g = WINDOW_GRID.min(n);
    let grid: Vec<usize> = (0..=g).map(|i| i * n / g).collect();
    let mut at_grid = vec![TermSums::zero()];
    for w in grid.windows(2) {
        let last = *at_grid.last().expect("one pushed");
        at_grid.push(d.add(last, w[0], w[1]));
    }
    let all = at_grid[g];
    let count = all.xx[(0, 0)] as usize;
    if count < 4 * MIN_SIDE {
        return None;
    }
    let m_inv = all.xx.try_inverse()?;
    let fitted_all = m_inv * all.xr;
    let max_len = WINDOW_MAX_FRACTION * count as f64;
    let stat = |lo: TermSums, hi: TermSums| {
        let w = hi.sub(lo);
        let len = w.xx[(0, 0)];
        if len <= MIN_SIDE as f64 || len > max_len {
            return f64::NEG_INFINITY;
        }
        window_terms(&w, &m_inv, &fitted_all).map_or(f64::NEG_INFINITY, |(_, ess)| ess / sigma2)
    };
    let (ga, gb) = coarse(&grid, |a, b| stat(at_grid[a], at_grid[b]))?;
    // Prefix sums at every sample within two grid steps of the two boundaries found (the refinement looks one step
    // either way); elsewhere (a profile interval reaching further) summed from the grid boundary below.
    let near = |k: usize| {
        (
            grid[k.saturating_sub(2)],
            grid[(k + 2).min(g)],
            k.saturating_sub(2),
        )
    };
    let tables: Vec<(usize, Vec<TermSums>)> = [ga, gb]
        .iter()
        .map(|&k| {
            let (lo, hi, below) = near(k);
            (lo, d.prefix(at_grid[below], lo, hi))
        })
        .collect();
    let prefix = |x: usize| {
        for (lo, t) in &tables {
            if let Some(p) = x.checked_sub(*lo).and_then(|k| t.get(k)) {
                return *p;
            }
        }
        let k = grid.partition_point(|&b| b <= x) - 1;
        d.add(at_grid[k], grid[k], x)
    };
    let scan = refine(n, g, (grid[ga], grid[gb]), |a, b| {
        stat(prefix(a), prefix(b))
    });
    let w = prefix(scan.end).sub(prefix(scan.start));
    let terms_rms = window_terms(&w, &m_inv, &fitted_all).map_or(0.0, |(beta, _)| {
        (beta.dot(&(w.xx * beta)) / w.xx[(0, 0)].max(1.0)).sqrt()
    });
    Some(DirectionsWindow { scan, terms_rms })
}

/// The window terms (the window's sums) against the same terms on all samples (`m_inv`, the inverse of all
/// samples' `xxᵀ`, and `fitted_all`, their coefficients): the window terms' coefficients and the sum of squares
/// they explain. A window where the direction hardly turns leaves `c` and `d·u` confounded: a small ridge keeps the
/// statistic that of their sum.
fn window_terms(w: &TermSums, m_inv: &Terms, fitted_all: &TermVec) -> Option<(TermVec, f64)> {
    let mut s = w.xx - w.xx * m_inv * w.xx;
    let r = w.xr - w.xx * fitted_all;
    let ridge = 1e-6 * s.trace() / TERMS as f64;
    for k in 0..TERMS {
        s[(k, k)] += ridge;
    }
    let beta = s.try_inverse()? * r;
    Some((beta, r.dot(&beta)))
}

/// The window `[a, b)` of `0..=n` with the largest `stat(a, b)`: on a coarse grid of [`WINDOW_GRID`] boundaries
/// first ([`coarse`]), then refined ([`refine`]).
fn best_window(n: usize, stat: impl Fn(usize, usize) -> f64 + Sync) -> Option<Scan> {
    let g = WINDOW_GRID.min(n);
    let grid: Vec<usize> = (0..=g).map(|i| i * n / g).collect();
    let (a, b) = coarse(&grid, |a, b| stat(grid[a], grid[b]))?;
    Some(refine(n, g, (grid[a], grid[b]), stat))
}

/// The pair of `grid` boundaries (their indices) with the largest `stat`, if any is finite.
/// The starts are searched on all threads; the first pair in `(a, b)` order wins a tie, as in one loop.
fn coarse(grid: &[usize], stat: impl Fn(usize, usize) -> f64 + Sync) -> Option<(usize, usize)> {
    let row = |a: usize| {
        let mut best = (a, a, f64::NEG_INFINITY);
        for b in a + 1..grid.len() {
            let s = stat(a, b);
            if s > best.2 {
                best = (a, b, s);
            }
        }
        best
    };
    let best =
        chunks::parts(grid.len(), row)
            .into_iter()
            .fold((0, 0, f64::NEG_INFINITY), |best, r| {
                if r.2 > best.2 { r } else { best }
            });
    best.2.is_finite().then_some((best.0, best.1))
}

/// The window `coarse` (sample indices, from a grid of `g` steps over `0..=n`) refined: the start with the end
/// fixed, then the end with the start fixed, each within a grid step; with the profile intervals of both.
fn refine(n: usize, g: usize, coarse: (usize, usize), stat: impl Fn(usize, usize) -> f64) -> Scan {
    let step = n.div_ceil(g);
    let near = |x: usize, last: usize| x.saturating_sub(step)..=(x + step).min(last);
    let a = argmax_of(near(coarse.0, n - 1), |x| stat(x, coarse.1));
    let b = argmax_of(near(coarse.1, n), |x| stat(a, x));
    let best_stat = stat(a, b);
    Scan {
        start: a,
        end: b,
        stat: best_stat,
        start_interval: profile(|x| stat(x, b), n, a, best_stat),
        end_interval: profile(|x| stat(a, x), n + 1, b, best_stat),
    }
}

/// The `x` of `range` with the largest `f(x)` (the last of equals).
fn argmax_of(range: std::ops::RangeInclusive<usize>, f: impl Fn(usize) -> f64) -> usize {
    let start = *range.start();
    range
        .map(|x| (x, f(x)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(start, |(x, _)| x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    use crate::frames::Mat3;

    /// `n` triples of Gaussian noise of standard deviation 0.1.
    fn noise(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut g = move || -> f64 { StandardNormal.sample(&mut rng) };
        (0..n).map(|_| [0.1 * g(), 0.1 * g(), 0.1 * g()]).collect()
    }

    #[test]
    fn finds_a_step_in_a_vector_residual() {
        let mut e = noise(2000, 1);
        for v in &mut e[1234..] {
            v[0] += 0.05;
        }
        let s = step_vector(&e, 0.01).unwrap();
        assert!((s.start as i64 - 1234).abs() < 60, "{s:?}");
        assert!(s.start_interval.0 <= s.start && s.start <= s.start_interval.1);
    }

    #[test]
    fn finds_a_world_fixed_window_through_a_rotating_attitude() {
        let n = 3000;
        let rot: Vec<Mat3> = (0..n)
            .map(|i| {
                let a = i as f64 * 0.01;
                [
                    [a.cos(), -a.sin(), 0.0],
                    [a.sin(), a.cos(), 0.0],
                    [0.0, 0.0, 1.0],
                ]
            })
            .collect();
        let mut e = noise(n, 2);
        for i in 1000..1600 {
            e[i] = frames::add(e[i], frames::mat_t_vec(&rot[i], [0.08, 0.0, 0.0]));
        }
        let world: Vec<[f64; 3]> = (0..n).map(|i| frames::mat_vec(&rot[i], e[i])).collect();
        let s = window(&world, 0.01).unwrap();
        assert!(
            (s.start as i64 - 1000).abs() < 40 && (s.end as i64 - 1600).abs() < 40,
            "{s:?}"
        );
    }

    #[test]
    fn the_directions_scan_finds_a_sensor_fixed_window_and_its_statistic_is_that_of_its_samples() {
        let n = 5000;
        let u: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let (s, c) = (i as f64 * 0.03).sin_cos();
                [0.8 * c, 0.8 * s, 0.6]
            })
            .collect();
        let mut rho: Vec<f64> = noise(n, 3).iter().map(|v| v[0]).collect();
        for i in 3000..3500 {
            rho[i] += 0.1 * u[i][0] + 0.05 * u[i][1];
        }
        // Samples left out elsewhere do not count.
        let mut free = vec![true; n];
        free[500..900].fill(false);
        let found = window_with_directions(&rho, &u, &free, 0.01).unwrap();
        let s = found.scan;
        assert!(
            s.start.abs_diff(3000) < 30 && s.end.abs_diff(3500) < 30,
            "{s:?}"
        );
        // The statistic from sums over the window's own samples, as the scan's sparse prefix sums give it.
        let d = Directional {
            rho: &rho,
            u: &u,
            free: &free,
        };
        let all = d.add(TermSums::zero(), 0, n);
        let w = d.add(TermSums::zero(), s.start, s.end);
        let m_inv = all.xx.try_inverse().unwrap();
        let (_, ess) = window_terms(&w, &m_inv, &(m_inv * all.xr)).unwrap();
        assert!(
            (ess / 0.01 - s.stat).abs() < 1e-6 * s.stat,
            "{} vs {}",
            ess / 0.01,
            s.stat
        );
        assert!(found.terms_rms > 0.05, "{}", found.terms_rms);
    }
}
