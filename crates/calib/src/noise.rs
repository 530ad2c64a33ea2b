//! The sensor's noise floor, measured from the recording itself.
//!
//! Three sources, best first:
//! - **poses**: when the reference stays exactly the same over runs of samples (a jig's poses, one attitude per
//!   pose), the readings' spread inside each run is the noise, pooled over the runs;
//! - **a still segment** of the readings (windows whose spread is no more than the differences allow);
//! - **k-th differences**: white noise of standard deviation σ gives k-th order differences of variance
//!   `C(2k, k)·σ²`, while a smooth signal contributes less the higher the order. The scale is taken robustly (the
//!   median absolute difference, then the RMS of the differences within four of it), so the jumps between poses or a
//!   shuffled file cannot pass for noise as long as fewer than half the differences are jumps; the smallest figure
//!   over orders 1–4 is kept. Noise that is alike in neighbouring samples (a chip's or a logger's filter: the BROAD
//!   IMU's readings correlate 0.3–0.6 with the next one, and not beyond the third) makes differences of neighbours
//!   small; fourth differences whose taps are `L` samples apart see the noise of each sample as white once `L`
//!   passes the correlation, while a rotation's part stays negligible (`(ω·L·dt)⁴` of the field), so their figure
//!   rises with `L` up to the per-sample noise and stays there ([`correlated_noise`]).
//!
//! A recording whose every row changes pose (one row per orientation, or rows in random order) has no measurable
//! sample-to-sample noise: the difference figure is then an upper bound at best, and the fits bound it by what their
//! residual allows (see [`crate::vector`]). Readings on a grid (the chip's LSB) are detected, and when the noise is
//! below the LSB the quantisation floor `LSB/√12` is added.

use crate::{chunks, robust};

/// How the noise floor was obtained.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NoiseSource {
    /// From the spread inside runs of samples that share one reference (a jig's poses).
    Poses {
        /// Runs of at least two samples.
        runs: usize,
        /// Degrees of freedom pooled over them (samples less one per run).
        dof: usize,
    },
    /// From a still segment of the recording (sample indices `[start, end)`).
    Still {
        /// First sample of the segment.
        start: usize,
        /// One past its last sample.
        end: usize,
    },
    /// From k-th order differences over the recording (the order that was least contaminated by signal).
    Differences {
        /// Order of the differences.
        order: usize,
        /// Samples between their taps: 1, or more when the noise is alike in neighbouring samples
        /// ([`correlated_noise`]).
        spacing: usize,
    },
}

/// The measured noise of the raw readings, per sensor axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseFloor {
    /// Standard deviation of the random noise, µT.
    pub sigma_ut: [f64; 3],
    /// The readings' grid step (LSB), µT, when they lie on one.
    pub lsb_ut: Option<[f64; 3]>,
    /// The floor a residual cannot go below: `sigma`, plus `LSB/√12` in quadrature where σ is below the LSB
    /// (above it, quantisation is already part of what the differences measure), µT.
    pub floor_ut: [f64; 3],
    /// Where the figure comes from.
    pub source: NoiseSource,
}

impl NoiseFloor {
    /// The floor in calibrated axes for the matrix `A` of `B = A·B̂ + b`: `sqrt(Σ_k A_jk² floor_k²)` per axis.
    pub fn calibrated_ut(&self, a: &crate::frames::Mat3) -> [f64; 3] {
        let f = self.floor_ut;
        std::array::from_fn(|j| (0..3).map(|k| (a[j][k] * f[k]).powi(2)).sum::<f64>().sqrt())
    }

    /// Mean over the axes of the squared calibrated floor, square-rooted: the per-axis figure to compare a residual
    /// RMS with.
    pub fn calibrated_rms_ut(&self, a: &crate::frames::Mat3) -> f64 {
        rms3(self.calibrated_ut(a))
    }

    /// The floor scaled by `factor` (a bound the fit's residual sets on it).
    pub fn scaled(&self, factor: f64) -> NoiseFloor {
        NoiseFloor {
            sigma_ut: self.sigma_ut.map(|s| s * factor),
            floor_ut: self.floor_ut.map(|s| s * factor),
            ..*self
        }
    }
}

/// The per-axis RMS of three per-axis figures.
pub fn rms3(v: [f64; 3]) -> f64 {
    ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) / 3.0).sqrt()
}

/// Samples used to find the LSB grid (the start of the recording is enough and keeps this O(1)).
const LSB_PROBE: usize = 20_000;
/// Differences used for the median that sets the robust scale (evenly strided over the recording).
const MEDIAN_PROBE: usize = 65_536;
/// Differences summed per order and axis, at most (in blocks spread evenly over the recording): σ to 0.2 %.
const DIFFERENCES_MOST: usize = 1 << 18;
/// Length of the windows searched for a still segment, samples.
const STILL_WINDOW: usize = 50;
/// A still segment must be at least this many windows long.
const STILL_MIN_WINDOWS: usize = 4;
/// A still window's spread is at most this fraction of the recording's largest spread.
const STILL_OF_ROTATION: f64 = 0.1;
/// Poses give the noise when their pooled degrees of freedom reach this…
const POSES_MIN_DOF: usize = 20;
/// …and their runs hold at least this share of the samples: a recording of poses is made of them, not of a few runs
/// that happen to share a reference.
const POSES_MIN_SHARE: f64 = 0.5;

/// Estimates the noise floor of raw readings (µT). `reference`, when given, is the expected field (or any
/// per-sample reference) in sample order: runs of identical references are poses, and their spread is the noise.
pub fn estimate(raw_ut: &[[f64; 3]], reference: Option<&[[f64; 3]]>) -> NoiseFloor {
    let mut best = (f64::INFINITY, 1, [f64::NAN; 3]);
    for (o, s) in difference_sigmas(raw_ut).into_iter().enumerate() {
        let total = s.iter().map(|x| x * x).sum::<f64>();
        if total < best.0 {
            best = (total, o + 1, s);
        }
    }
    let (_, order, diff_sigma) = best;
    let (order, spacing, diff_sigma) = match correlated_noise(raw_ut) {
        Some((spacing, sigma)) => (SPACED_ORDER, spacing, sigma),
        None => (order, 1, diff_sigma),
    };
    let poses = reference.and_then(|r| pose_sigma(raw_ut, r));
    let (sigma_ut, source) = match poses {
        Some((sigma, runs, dof)) => (sigma, NoiseSource::Poses { runs, dof }),
        None => match still_segment(raw_ut, diff_sigma) {
            Some((start, end, s)) => (s, NoiseSource::Still { start, end }),
            None => (diff_sigma, NoiseSource::Differences { order, spacing }),
        },
    };
    let probe = &raw_ut[..raw_ut.len().min(LSB_PROBE)];
    let lsb: [Option<f64>; 3] =
        std::array::from_fn(|k| grid_step(&probe.iter().map(|m| m[k]).collect::<Vec<f64>>()));
    let lsb_ut = if lsb.iter().all(Option::is_some) {
        Some(lsb.map(|x| x.unwrap_or_default()))
    } else {
        None
    };
    let floor_ut = std::array::from_fn(|k| match lsb[k] {
        Some(q) if sigma_ut[k] < q => (sigma_ut[k].powi(2) + q * q / 12.0).sqrt(),
        _ => sigma_ut[k],
    });
    NoiseFloor {
        sigma_ut,
        lsb_ut,
        floor_ut,
        source,
    }
}

/// The order of the differences whose taps are spread ([`correlated_noise`]).
const SPACED_ORDER: usize = 4;
/// Widest spacing of their taps tried, samples.
const SPACINGS: usize = 6;
/// For white noise, the standard error of the ratio of two neighbouring spacings' figures (the root of the
/// variances summed over the axes) times `√n`, `n` the differences: measured over 60 seeds of 2000 Gaussian samples
/// per axis (0.036 per axis at n = 2000, so `0.036·√2000/√3`).
const SPACING_RATIO_SE: f64 = 0.94;
/// The figure at spacing 2 is another than at spacing 1 beyond this many of those standard errors: white noise's
/// figures differ so in about one recording in 30 000.
const SPACING_SE: f64 = 4.0;
/// The figure has reached its plateau at a spacing when each of the next two adds less than this share of what the
/// first step (spacing 1 to 2) added. The noise's correlation makes the figure rise and then stop; a signal's part
/// grows as the spacing's fourth power, so its steps grow and no plateau holds for two of them (a fast hand-held
/// dance at 50 Hz rises from spacing 1 to 2, stays to 3 and rises again to 4).
const PLATEAU_SHARE: f64 = 0.1;

/// The per-sample noise σ per axis when it is alike in neighbouring samples, and the spacing of the fourth
/// differences that measured it: the figures of fourth differences whose taps are 1, 2, …, [`SPACINGS`] samples apart
/// rise with the spacing while it is within the noise's correlation and then stay (a plateau); the first spacing
/// after which the figure rises twice by less than [`PLATEAU_SHARE`] of its first rise gives it. `None` when the first
/// step stays within [`SPACING_SE`] standard errors of white noise (the differences of neighbours stand) or no
/// spacing tried reaches a plateau (a signal that grows with the spacing, not noise).
fn correlated_noise(raw_ut: &[[f64; 3]]) -> Option<(usize, [f64; 3])> {
    let n = raw_ut.len();
    if n <= 4 * SPACINGS * 4 {
        return None;
    }
    let sigmas: Vec<[f64; 3]> = (1..=SPACINGS).map(|l| spaced_sigma(raw_ut, l)).collect();
    let total = |s: &[f64; 3]| s.iter().map(|x| x * x).sum::<f64>().sqrt();
    let used = n.min(DIFFERENCES_MOST) as f64;
    let tolerance = 1.0 + SPACING_SE * SPACING_RATIO_SE / used.sqrt();
    let rise = |l: usize| total(&sigmas[l + 1]) - total(&sigmas[l]);
    let first = total(&sigmas[0]);
    if !first.is_finite() || first <= 0.0 || total(&sigmas[1]) <= tolerance * first {
        return None;
    }
    (1..SPACINGS - 2)
        .find(|&l| (l..l + 2).all(|m| rise(m) <= PLATEAU_SHARE * rise(0)))
        .map(|l| (l + 1, sigmas[l]))
}

/// The noise σ per axis from fourth differences whose taps are `spacing` samples apart, robust to jumps as
/// [`difference_sigmas`] is (the median absolute difference sets a scale, the RMS within four of it is the figure),
/// over the readings or blocks spread evenly over them ([`DIFFERENCES_MOST`]).
fn spaced_sigma(raw_ut: &[[f64; 3]], spacing: usize) -> [f64; 3] {
    let count = raw_ut.len().saturating_sub(SPACED_ORDER * spacing);
    let at = |i: usize| {
        difference(
            SPACED_ORDER - 1,
            &std::array::from_fn(|j| raw_ut[i + j * spacing]),
        )
    };
    let stride = count.div_ceil(MEDIAN_PROBE).max(1);
    let limit: [f64; 3] = std::array::from_fn(|k| {
        let abs: Vec<f64> = (0..count).step_by(stride).map(|i| at(i)[k].abs()).collect();
        four_sigma_limit(robust::median(&abs))
    });
    let sums = chunks::fold_spread(
        count,
        DIFFERENCES_MOST,
        |range| {
            let mut sums = WithinSums::default();
            for i in range {
                sums.add(&at(i), &limit);
            }
            sums
        },
        WithinSums::merge,
    )
    .unwrap_or_default();
    let norm = binomial(2 * SPACED_ORDER, SPACED_ORDER).sqrt();
    sums.rms().map(|r| r / KEPT_AT_4_SIGMA.sqrt() / norm)
}

fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// Orders of the differences tried.
const ORDERS: usize = 4;
/// Truncating a Gaussian at ±4σ keeps 99.893 % of its variance.
const KEPT_AT_4_SIGMA: f64 = 0.998_93;

/// The noise σ per axis from the 1st to 4th differences, robust to jumps: per order, the median absolute
/// difference sets a scale, and the RMS of the differences within four of that scale (a Gaussian loses 0.1 % of its
/// variance there, corrected) is the estimate. Where most differences are exactly zero (readings on a coarse grid)
/// the scale falls back to five times the plain RMS. One pass for every order and axis at once (two on a coarse grid),
/// on all threads, over the readings or, in a long recording, over blocks spread evenly over them
/// ([`DIFFERENCES_MOST`] samples); NaN for an order the readings are too few for.
fn difference_sigmas(raw_ut: &[[f64; 3]]) -> [[f64; 3]; ORDERS] {
    let n = raw_ut.len();
    let mad = median_abs_differences(raw_ut);
    let within = rms_within(raw_ut, &four_sigma_limits(&mad));
    let coarse = if (0..ORDERS)
        .filter(|&o| order_usable(n, o))
        .any(|o| mad[o].iter().any(|m| m.is_nan() || *m <= 0.0))
    {
        rms_within(raw_ut, &within.map(|w| w.map(|r| 5.0 * r)))
    } else {
        [[0.0; 3]; ORDERS]
    };
    std::array::from_fn(|o| {
        if !order_usable(n, o) {
            return [f64::NAN; 3];
        }
        let norm = binomial(2 * (o + 1), o + 1).sqrt();
        std::array::from_fn(|k| {
            if mad[o][k] > 0.0 {
                within[o][k] / KEPT_AT_4_SIGMA.sqrt() / norm
            } else {
                coarse[o][k] / norm
            }
        })
    })
}

/// Whether `n` readings are enough for order `o + 1`'s figure.
fn order_usable(n: usize, o: usize) -> bool {
    n > o + 3
}

/// The number of order `o + 1`'s differences of `n` readings.
fn difference_count(n: usize, o: usize) -> usize {
    n.saturating_sub(o + 1)
}

/// The taps `c` applied to the first readings of `w`, per axis.
#[inline]
fn taps<const T: usize>(c: [f64; T], w: &[[f64; 3]; 5]) -> [f64; 3] {
    std::array::from_fn(|k| c.iter().zip(w).map(|(c, v)| c * v[k]).sum())
}

/// Order `o + 1`'s difference at the first of the five readings `w`: `Σ_j (−1)^j·C(o + 1, j)·w[j]`, `j = 0..=o + 1`.
#[inline]
fn difference(o: usize, w: &[[f64; 3]; 5]) -> [f64; 3] {
    match o {
        0 => taps([1.0, -1.0], w),
        1 => taps([1.0, -2.0, 1.0], w),
        2 => taps([1.0, -3.0, 3.0, -1.0], w),
        _ => taps([1.0, -4.0, 6.0, -4.0, 1.0], w),
    }
}

/// Every order's difference at the first of the five readings `w`.
#[inline]
fn differences(w: &[[f64; 3]; 5]) -> [[f64; 3]; ORDERS] {
    std::array::from_fn(|o| difference(o, w))
}

/// The five readings from sample `i` on, NaN past the end.
#[inline]
fn window(raw_ut: &[[f64; 3]], i: usize) -> [[f64; 3]; 5] {
    std::array::from_fn(|j| raw_ut.get(i + j).copied().unwrap_or([f64::NAN; 3]))
}

/// Per order and axis, the median absolute difference, from at most [`MEDIAN_PROBE`] differences strided evenly
/// over the readings (NaN for an order the readings are too few for); the orders on all threads.
fn median_abs_differences(raw_ut: &[[f64; 3]]) -> [[f64; 3]; ORDERS] {
    let n = raw_ut.len();
    let mad = chunks::parts(ORDERS, |o| {
        if !order_usable(n, o) {
            return [f64::NAN; 3];
        }
        // One axis at a time, so that the probe is one column of values.
        let count = difference_count(n, o);
        let stride = count.div_ceil(MEDIAN_PROBE).max(1);
        std::array::from_fn(|k| {
            let abs: Vec<f64> = (0..count)
                .step_by(stride)
                .map(|i| difference(o, &window(raw_ut, i))[k].abs())
                .collect();
            robust::median(&abs)
        })
    });
    std::array::from_fn(|o| mad[o])
}

/// The limits within which differences count: four standard deviations of a Gaussian whose median absolute value
/// is `mad`, or none where `mad` is not positive.
fn four_sigma_limits(mad: &[[f64; 3]; ORDERS]) -> [[f64; 3]; ORDERS] {
    mad.map(|m| m.map(four_sigma_limit))
}

/// Four standard deviations of a Gaussian whose median absolute value is `mad`; none (infinite) where `mad` is not
/// positive.
fn four_sigma_limit(mad: f64) -> f64 {
    if mad > 0.0 {
        4.0 * mad / 0.674_489_75
    } else {
        f64::INFINITY
    }
}

/// Per axis, the sum of the squares of one order's differences within their limit, and how many there are.
#[derive(Clone, Copy, Debug, Default)]
struct WithinSums {
    /// Sum of the squared differences within the limit, µT².
    sum_sq: [f64; 3],
    /// Differences within the limit.
    count: [usize; 3],
}

impl WithinSums {
    /// Adds the difference `d` where it lies within `limit`, per axis.
    #[inline]
    fn add(&mut self, d: &[f64; 3], limit: &[f64; 3]) {
        for k in 0..3 {
            let within = d[k].abs() <= limit[k];
            self.sum_sq[k] += if within { d[k] * d[k] } else { 0.0 };
            self.count[k] += usize::from(within);
        }
    }

    /// The sums of two runs of samples, `self`'s first.
    fn merge(self, o: WithinSums) -> WithinSums {
        WithinSums {
            sum_sq: std::array::from_fn(|k| self.sum_sq[k] + o.sum_sq[k]),
            count: std::array::from_fn(|k| self.count[k] + o.count[k]),
        }
    }

    /// The RMS of the differences within the limit per axis, µT (zero where none is).
    fn rms(&self) -> [f64; 3] {
        std::array::from_fn(|k| {
            if self.count[k] == 0 {
                0.0
            } else {
                (self.sum_sq[k] / self.count[k] as f64).sqrt()
            }
        })
    }
}

/// Per order and axis, the RMS of the differences within `limit`, from one pass for every order at once on all
/// threads, over the readings or blocks spread evenly over them ([`DIFFERENCES_MOST`] samples).
fn rms_within(raw_ut: &[[f64; 3]], limit: &[[f64; 3]; ORDERS]) -> [[f64; 3]; ORDERS] {
    chunks::fold_spread(
        difference_count(raw_ut.len(), 0),
        DIFFERENCES_MOST,
        |range| sums_within(raw_ut, range, limit),
        |a, b| std::array::from_fn(|o| a[o].merge(b[o])),
    )
    .unwrap_or([WithinSums::default(); ORDERS])
    .map(|sums| sums.rms())
}

/// Per order, the sums of the differences within `limit` at the samples of `range`: the differences of the orders
/// that exist at a sample, added in sample order.
fn sums_within(
    raw_ut: &[[f64; 3]],
    range: std::ops::Range<usize>,
    limit: &[[f64; 3]; ORDERS],
) -> [WithinSums; ORDERS] {
    let n = raw_ut.len();
    let mut sums = [WithinSums::default(); ORDERS];
    let mut add = |all: [[f64; 3]; ORDERS], orders: usize| {
        for (sum, (d, limit)) in sums.iter_mut().zip(all.iter().zip(limit)).take(orders) {
            sum.add(d, limit);
        }
    };
    // Where all five readings exist, straight from the slice; the last few samples the long way.
    let inner = range.start..range.end.min(n.saturating_sub(ORDERS)).max(range.start);
    if !inner.is_empty() {
        for w in raw_ut[inner.start..inner.end + ORDERS].windows(ORDERS + 1) {
            add(differences(w.try_into().expect("five readings")), ORDERS);
        }
    }
    for i in inner.end..range.end {
        add(
            differences(&window(raw_ut, i)),
            (0..ORDERS).filter(|&o| i < difference_count(n, o)).count(),
        );
    }
    sums
}

/// The pooled spread inside runs of consecutive samples whose reference is identical, if they give enough degrees of
/// freedom and hold enough of the samples ([`POSES_MIN_SHARE`]): σ per axis, the runs of two or more, and the pooled
/// degrees of freedom.
fn pose_sigma(raw_ut: &[[f64; 3]], reference: &[[f64; 3]]) -> Option<([f64; 3], usize, usize)> {
    let (mut ss, mut dof, mut runs) = ([0.0; 3], 0usize, 0usize);
    let mut start = 0;
    let known = |r: &[f64; 3]| r.iter().all(|v| v.is_finite());
    for end in 1..=raw_ut.len() {
        if end < raw_ut.len() && known(&reference[start]) && reference[end] == reference[start] {
            continue;
        }
        let run = &raw_ut[start..end];
        // Rows written twice (reading and reference alike) are no pose: a run of one reading says nothing of noise.
        let one_reading = run.iter().all(|m| m == &run[0]);
        if run.len() >= 2 && known(&reference[start]) && !one_reading {
            let mean: [f64; 3] =
                std::array::from_fn(|k| run.iter().map(|m| m[k]).sum::<f64>() / run.len() as f64);
            for m in run {
                for k in 0..3 {
                    ss[k] += (m[k] - mean[k]).powi(2);
                }
            }
            dof += run.len() - 1;
            runs += 1;
        }
        start = end;
    }
    let finite = ss.iter().all(|s| s.is_finite());
    let most = (dof + runs) as f64 >= POSES_MIN_SHARE * raw_ut.len() as f64;
    (dof >= POSES_MIN_DOF && finite && most)
        .then(|| (ss.map(|s| (s / dof as f64).sqrt()), runs, dof))
}

/// The longest run of windows whose spread (no motion removed) is no more than the difference-based noise allows,
/// if long enough.
fn still_segment(raw_ut: &[[f64; 3]], diff_sigma: [f64; 3]) -> Option<(usize, usize, [f64; 3])> {
    let n = raw_ut.len();
    let windows = n / STILL_WINDOW;
    // Still means small against the rotation too: rows in random order also have windows whose spread matches their
    // differences, and they are not still.
    let rotation = plain_sigma(raw_ut).into_iter().fold(0.0, f64::max);
    let window = |w: usize| plain_sigma(&raw_ut[w * STILL_WINDOW..(w + 1) * STILL_WINDOW]);
    let still = |w: usize| {
        let spread = window(w);
        (0..3).all(|k| {
            spread[k] <= 1.3 * diff_sigma[k].max(1e-9) && spread[k] <= STILL_OF_ROTATION * rotation
        })
    };
    let still = chunks::map(windows, still);
    let (mut best, mut run_start) = ((0, 0), None);
    for w in 0..=windows {
        match (w < windows && still[w], run_start) {
            (true, None) => run_start = Some(w),
            (false, Some(s)) => {
                if w - s > best.1 - best.0 {
                    best = (s, w);
                }
                run_start = None;
            }
            _ => {}
        }
    }
    if best.1 - best.0 < STILL_MIN_WINDOWS {
        return None;
    }
    let var = (best.0..best.1).map(window).fold([0.0; 3], |acc, s| {
        std::array::from_fn(|k| acc[k] + s[k].powi(2))
    });
    let sigma = var.map(|v| (v / (best.1 - best.0) as f64).sqrt());
    Some((best.0 * STILL_WINDOW, best.1 * STILL_WINDOW, sigma))
}

/// Sample standard deviation per axis, on all threads.
fn plain_sigma(x: &[[f64; 3]]) -> [f64; 3] {
    fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| a[k] + b[k])
    }
    // Generic rather than `dyn`: called once per still window too, where a call per sample would dominate.
    fn sum(x: &[[f64; 3]], f: impl Fn(&[f64; 3]) -> [f64; 3] + Sync) -> [f64; 3] {
        chunks::fold(x.len(), |r| x[r].iter().map(&f).fold([0.0; 3], add), add).unwrap_or_default()
    }
    let n = x.len() as f64;
    let mean = sum(x, |v| *v).map(|s| s / n);
    let ss = sum(x, |v| std::array::from_fn(|k| (v[k] - mean[k]).powi(2)));
    ss.map(|s| (s / (n - 1.0)).sqrt())
}

/// The step of the grid the values lie on, if they lie on one.
fn grid_step(x: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    if v.len() < 8 {
        return None;
    }
    let gaps: Vec<f64> = v.windows(2).map(|w| w[1] - w[0]).collect();
    let step = gaps.iter().copied().fold(f64::INFINITY, f64::min);
    // A grid finer than this is indistinguishable from values written with six decimals.
    if step < 1e-4 {
        return None;
    }
    // Values written with ~6 decimals: allow that rounding when checking the gaps are multiples of the step.
    let tol = 2e-6_f64.max(0.02 * step);
    let on_grid = gaps
        .iter()
        .filter(|g| (*g / step - (*g / step).round()).abs() * step < tol)
        .count();
    if (on_grid as f64) < 0.99 * gaps.len() as f64 {
        return None;
    }
    // Refine: the mean of the single-step gaps.
    let singles: Vec<f64> = gaps
        .iter()
        .copied()
        .filter(|g| (g - step).abs() < tol)
        .collect();
    Some(singles.iter().sum::<f64>() / singles.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    fn rotating(n: usize, rate_hz: f64, sigma: f64, lsb: Option<f64>, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        (0..n)
            .map(|i| {
                let t = i as f64 / rate_hz;
                let clean = [
                    40.0 * (0.7 * t).cos(),
                    40.0 * (0.7 * t).sin() * (0.3 * t).cos(),
                    25.0 * (0.3 * t).sin() + 10.0,
                ];
                clean.map(|c| {
                    let v = c + noise.sample(&mut rng);
                    lsb.map_or(v, |q| (v / q).round() * q)
                })
            })
            .collect()
    }

    #[test]
    fn measures_white_noise_under_a_moving_signal() {
        for (rate, sigma) in [(20.0, 0.05), (100.0, 0.3), (50.0, 0.1)] {
            let f = estimate(&rotating(20_000, rate, sigma, None, 7), None);
            for s in f.sigma_ut {
                assert!(
                    (s / sigma - 1.0).abs() < 0.05,
                    "{rate} Hz, σ {sigma}: got {s}"
                );
            }
            assert!(f.lsb_ut.is_none());
        }
    }

    #[test]
    fn noise_alike_in_neighbouring_samples_is_measured_per_sample() {
        // Each reading's noise the mean of three consecutive white draws (a logger's filter: correlation 2/3 with the
        // next reading, 1/3 with the one after), σ 0.3 µT per reading, under a rotation at 100 Hz: differences of
        // neighbours see about a third of it; taps three apart see it all.
        let (n, sigma) = (20_000, 0.3);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let white = Normal::new(0.0, sigma * 3f64.sqrt()).unwrap();
        let draws: Vec<[f64; 3]> = (0..n + 2)
            .map(|_| std::array::from_fn(|_| white.sample(&mut rng)))
            .collect();
        let clean = rotating(n, 100.0, 0.0, None, 1);
        let data: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                std::array::from_fn(|k| {
                    clean[i][k] + (draws[i][k] + draws[i + 1][k] + draws[i + 2][k]) / 3.0
                })
            })
            .collect();
        let f = estimate(&data, None);
        assert!(
            matches!(
                f.source,
                NoiseSource::Differences {
                    order: 4,
                    spacing: 3
                }
            ),
            "{:?}",
            f.source
        );
        for s in f.sigma_ut {
            assert!((s / sigma - 1.0).abs() < 0.05, "got {s}");
        }
        // White noise of the same size keeps the differences of neighbours.
        let f = estimate(&rotating(n, 100.0, sigma, None, 7), None);
        assert!(
            matches!(f.source, NoiseSource::Differences { spacing: 1, .. }),
            "{:?}",
            f.source
        );
    }

    #[test]
    fn a_long_recording_is_measured_on_blocks_spread_over_it() {
        // σ 0.1 µT in the first half, 0.12 µT in the second: blocks from one end alone would give one of them.
        let n = 3 * DIFFERENCES_MOST;
        let mut data = rotating(n, 100.0, 0.1, None, 5);
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let extra = Normal::new(0.0, (0.12f64.powi(2) - 0.1f64.powi(2)).sqrt()).unwrap();
        for m in &mut data[n / 2..] {
            *m = m.map(|v| v + extra.sample(&mut rng));
        }
        let expected = ((0.1f64.powi(2) + 0.12f64.powi(2)) / 2.0).sqrt();
        for s in estimate(&data, None).sigma_ut {
            assert!((s / expected - 1.0).abs() < 0.02, "{s} against {expected}");
        }
    }

    #[test]
    fn finds_the_lsb_and_adds_the_quantisation_floor() {
        let lsb = 100.0 / 1090.0;
        let f = estimate(&rotating(20_000, 75.0, 0.02, Some(lsb), 3), None);
        let found = f.lsb_ut.expect("grid not found");
        for k in 0..3 {
            assert!((found[k] / lsb - 1.0).abs() < 1e-3, "{found:?}");
            assert!(f.floor_ut[k] >= lsb / 12f64.sqrt());
        }
    }

    #[test]
    fn prefers_a_still_segment() {
        let mut data = vec![[10.0, 20.0, 30.0]; 1000];
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let noise = Normal::new(0.0, 0.2).unwrap();
        for m in &mut data {
            *m = m.map(|v| v + noise.sample(&mut rng));
        }
        data.extend(rotating(5000, 50.0, 0.2, None, 2));
        let f = estimate(&data, None);
        assert!(matches!(f.source, NoiseSource::Still { start: 0, end } if end >= 900));
        for s in f.sigma_ut {
            assert!((s / 0.2 - 1.0).abs() < 0.1, "{s}");
        }
    }

    /// Poses: `per_pose` samples at each of 24 fixed readings (a jig), with white noise.
    fn poses(per_pose: usize, sigma: f64, seed: u64) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let (mut raw, mut reference) = (Vec::new(), Vec::new());
        for p in 0..24 {
            let a = p as f64 * 0.7;
            let clean = [
                45.0 * a.cos(),
                45.0 * a.sin() * (1.3 * a).cos(),
                30.0 * (1.3 * a).sin(),
            ];
            for _ in 0..per_pose {
                raw.push(clean.map(|c| c + noise.sample(&mut rng)));
                reference.push(clean);
            }
        }
        (raw, reference)
    }

    #[test]
    fn poses_give_the_noise_and_their_jumps_do_not() {
        for per_pose in [3, 10, 50] {
            let (raw, reference) = poses(per_pose, 0.05, per_pose as u64);
            let f = estimate(&raw, Some(&reference));
            assert!(
                matches!(f.source, NoiseSource::Poses { runs: 24, .. }),
                "{f:?}"
            );
            let tol = if per_pose == 3 { 0.25 } else { 0.15 };
            for s in f.sigma_ut {
                assert!((s / 0.05 - 1.0).abs() < tol, "{per_pose} per pose: {s}");
            }
            // Without the reference, the robust differences still see through the jumps between poses.
            if per_pose >= 10 {
                let d = estimate(&raw, None);
                for s in d.sigma_ut {
                    assert!(
                        (s / 0.05 - 1.0).abs() < 0.3,
                        "{per_pose} per pose, differences: {s}"
                    );
                }
            }
        }
    }

    #[test]
    fn rows_a_logger_wrote_twice_are_no_poses() {
        // A tumbling recording with its own reference per row, one row in a hundred (or every other row) written
        // twice: the twins are runs of one reference with no spread, and must not set the noise to zero.
        let raw = rotating(20_000, 100.0, 0.2, None, 8);
        for every in [100, 2] {
            let mut twice = Vec::new();
            let mut reference = Vec::new();
            for (i, m) in raw.iter().enumerate() {
                let r = m.map(|v| v + 0.5);
                for _ in 0..if i % every == 1 { 2 } else { 1 } {
                    twice.push(*m);
                    reference.push(r);
                }
            }
            let f = estimate(&twice, Some(&reference));
            assert!(!matches!(f.source, NoiseSource::Poses { .. }), "{f:?}");
            assert!(f.sigma_ut.iter().all(|s| *s > 0.1), "one in {every}: {f:?}");
        }
    }

    #[test]
    fn rows_of_independent_attitudes_are_no_still_segment() {
        // Issue 11's failure case: every row its own attitude. Windows of such rows spread as much as their
        // differences allow, but they are not still: their spread is the rotation's.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, 0.1).unwrap();
        let raw: Vec<[f64; 3]> = (0..20_000)
            .map(|_| {
                let d: [f64; 3] = rand_distr::UnitSphere.sample(&mut rng);
                d.map(|v| 50.0 * v + noise.sample(&mut rng))
            })
            .collect();
        let f = estimate(&raw, None);
        assert!(!matches!(f.source, NoiseSource::Still { .. }), "{f:?}");
        let reference: Vec<[f64; 3]> = raw.iter().map(|m| m.map(|v| v + 1.0)).collect();
        let f = estimate(&raw, Some(&reference));
        assert!(!matches!(f.source, NoiseSource::Still { .. }), "{f:?}");
    }

    #[test]
    fn a_few_jumps_among_many_samples_do_not_pass_for_noise() {
        let mut data = rotating(5000, 50.0, 0.1, None, 8);
        for (i, m) in data.iter_mut().enumerate() {
            if i % 7 == 0 {
                m[0] += 30.0;
            }
        }
        let f = estimate(&data, None);
        assert!((f.sigma_ut[1] / 0.1 - 1.0).abs() < 0.1, "{f:?}");
        assert!(f.sigma_ut[0] < 0.2, "x: {}", f.sigma_ut[0]);
    }
}
