//! The reference's heading: an attitude reference whose north is not true north (a cube jig's edge lined up with a
//! compass or a few degrees off, a capture volume's axes), found from the readings.
//!
//! The vector method fits `A·B̂ᵢ + b = Rᵢᵀ·F` with `Rᵢ` the attitude (sensor → NED) and `F` the world field. When
//! the reference's north points `ψ` east of true north, the sensor's true attitude is `Rz(ψ)·Rᵢ` and the relation
//! is `A·B̂ᵢ + b = Rᵢᵀ·Fψ` with `Fψ = Rz(ψ)ᵀ·F`: the world field in the reference's axes, its declination less `ψ`
//! — the same as a field given with its declination off by `−ψ`. Unmodelled, `A` absorbs what of the turn it can
//! (all of it when the sensor turned about the vertical only, so `ψ` is then not determined) and leaves the rest in
//! the residual; at 30° the robust fit takes the reference for one in another convention.
//!
//! With `Fψ = cos ψ·u + sin ψ·v + k` (`u = (F_N, F_E, 0)`, `v = (F_E, −F_N, 0)`, `k = (0, 0, F_D)`) the expected
//! field is linear in `(cos ψ, sin ψ)`, so the least-squares residual with `A` and `b` profiled out is a quadratic
//! form in `(cos ψ, sin ψ, 1)` built from one pass of sums: its minimum on the circle is found by a grid and Newton
//! steps, its curvature gives `ψ`'s standard error, and the sums of blocks of time give a block jackknife, which sees
//! errors alike for a while (a jig pose's own error) that the curvature takes as independent.

use nalgebra::{Matrix3, Matrix4, Vector4};

use crate::chunks;
use crate::frames::{self, Mat3};
use crate::robust::median;
use crate::vector::VectorFit;

/// A heading below this is not fitted, degrees: it is left to the diagnosis' `field_direction_error`, which models a
/// small turn of the field exactly (its linearisation is off by `ψ²/2`, 0.002° at this size). Half the 1° of
/// heading error a good calibration may leave, so a heading left so cannot turn a verdict on its own; and about as
/// well as a jig's edge is lined up by eye.
pub const MIN_HEADING_DEG: f64 = 0.5;
/// A heading is fitted only when it is this many standard errors from zero (0.3 % of aligned references by chance).
pub const SIGNIFICANT_SE: f64 = 3.0;
/// A heading with a standard error above this, degrees, is not determined by the recording: the sensor turned
/// (almost) about the vertical only, and `A` absorbs the turn.
pub const MAX_SE_DEG: f64 = 2.0;
/// A heading is the reference's only when it explains at least this share of the misfit above the noise (the mean
/// square of the residual against the field as given, less the noise's): then it is the story of the misfit. A jig
/// turned from true north leaves nothing else (all of it); on the physical motion-capture recordings the best turn
/// about the vertical explains 10–20 % of a misfit that is mostly the reference's own error and a field that varies
/// along the path, and its angle changes from one stretch of a recording to the next and between trials in one lab
/// (BROAD 29 +1.2° ± 0.8°, BROAD 33 −2.7° ± 0.5°): no property of the reference, and the diagnosis' field direction
/// models it.
pub const EXPLAINED_SHARE: f64 = 0.5;
/// Samples the heading is found from, at most: whole chunks spread over the recording (at 10⁶ samples a fifth of
/// them, 9 ms of CPU instead of 43; the heading's standard error is of the samples used).
pub const MOST_SAMPLES: usize = 200_000;
/// Blocks of time of the jackknife.
pub const JACKKNIFE_BLOCKS: usize = 20;
/// The jackknife is made when every block holds at least this many samples.
const MIN_BLOCK_SAMPLES: usize = 10;
/// Grid points of the search over the circle (every 1°), before Newton steps.
const GRID: usize = 360;
/// Newton steps from the best grid point.
const NEWTON_STEPS: usize = 20;
/// Passes of the trimmed search ([`estimate_trimmed`]) after the first.
pub const TRIM_PASSES: usize = 3;
/// Each trimmed pass keeps the samples within this many times the median residual of the pass before.
pub const TRIM_MEDIANS: f64 = 3.0;

/// The reference's heading found from a recording.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingEstimate {
    /// Where the reference's north points, degrees east of true north (negative: west), in (−180, 180].
    pub heading_deg: f64,
    /// Its standard error, degrees: the larger of the curvature's and the block jackknife's.
    pub se_deg: f64,
    /// Samples used.
    pub n: usize,
    /// RMS residual per axis of the least-squares fit against the field turned by the heading, µT.
    pub rms_ut: f64,
    /// The same against the field as given (no heading), µT.
    pub rms_unturned_ut: f64,
    /// `A` of the least-squares fit against the turned field.
    pub a: Mat3,
    /// `b` of it, µT.
    pub b_ut: [f64; 3],
    /// Per calibrated axis `j`, how `(a_j1, a_j2, a_j3, b_j)` of that fit move with the heading, per radian.
    pub sensitivity: [[f64; 4]; 3],
}

impl HeadingEstimate {
    /// Whether the recording determines the heading ([`MAX_SE_DEG`]).
    pub fn determined(&self) -> bool {
        self.se_deg <= MAX_SE_DEG
    }

    /// Whether the heading is worth fitting as the reference's, with a noise of `noise_ut` per axis in calibrated
    /// units: determined, at least [`MIN_HEADING_DEG`], [`SIGNIFICANT_SE`] standard errors from zero, and explaining
    /// [`EXPLAINED_SHARE`] of the misfit.
    pub fn material(&self, noise_ut: f64) -> bool {
        let size = self.heading_deg.abs();
        self.determined()
            && size >= MIN_HEADING_DEG
            && size >= SIGNIFICANT_SE * self.se_deg
            && self.explained_share(noise_ut) >= EXPLAINED_SHARE
    }

    /// The share of the misfit above a noise of `noise_ut` (per axis) that turning the field by the heading removes
    /// (mean squares of the least-squares residuals); 1 when the noise leaves no more misfit than it removes.
    pub fn explained_share(&self, noise_ut: f64) -> f64 {
        let before = self.rms_unturned_ut.powi(2);
        let removed = before - self.rms_ut.powi(2);
        let excess = before - noise_ut.powi(2);
        if removed <= 0.0 {
            0.0
        } else {
            (removed / excess.max(removed)).min(1.0)
        }
    }

    /// The world field `field_ned_ut` in the reference's axes ([`turned`]).
    pub fn field_in_reference(&self, field_ned_ut: [f64; 3]) -> [f64; 3] {
        turned(field_ned_ut, self.heading_deg)
    }
}

/// The world field (NED, µT) in the axes of a reference whose north points `heading_deg` east of true north:
/// `Rz(ψ)ᵀ·F`, its declination less `heading_deg`.
pub fn turned(field_ned_ut: [f64; 3], heading_deg: f64) -> [f64; 3] {
    let (s, c) = heading_deg.to_radians().sin_cos();
    let [n, e, d] = field_ned_ut;
    [c * n + s * e, -s * n + c * e, d]
}

/// The attitude (sensor → NED, `[w, x, y, z]`) of a sensor whose attitude against a reference with its north
/// `heading_deg` east of true north is `q`: `Rz(ψ)·q`.
pub fn true_attitude(q: [f64; 4], heading_deg: f64) -> [f64; 4] {
    let (s, c) = (heading_deg.to_radians() / 2.0).sin_cos();
    // (c, 0, 0, s) ⊗ (w, x, y, z)
    let [w, x, y, z] = q;
    [c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w]
}

/// The sums of one pass: the design `xᵢ = (B̂ᵢ, 1)` against the targets `Rᵢᵀu`, `Rᵢᵀv`, `Rᵢᵀk` per axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sums {
    n: usize,
    /// `Σ xxᵀ`.
    xx: [[f64; 4]; 4],
    /// Per axis `j`, `Σ x·tⱼᵀ` with `tⱼ = ((Rᵀu)ⱼ, (Rᵀv)ⱼ, (Rᵀk)ⱼ)`.
    xt: [[[f64; 3]; 4]; 3],
    /// Per axis `j`, `Σ tⱼ·tⱼᵀ`.
    tt: [[[f64; 3]; 3]; 3],
}

impl Sums {
    fn add(&mut self, raw: [f64; 3], r: &Mat3, [u, v, k]: &[[f64; 3]; 3]) {
        let x = [raw[0], raw[1], raw[2], 1.0];
        let targets = [
            frames::mat_t_vec(r, *u),
            frames::mat_t_vec(r, *v),
            frames::mat_t_vec(r, *k),
        ];
        self.n += 1;
        for p in 0..4 {
            for q in 0..4 {
                self.xx[p][q] += x[p] * x[q];
            }
        }
        for j in 0..3 {
            let t = [targets[0][j], targets[1][j], targets[2][j]];
            for p in 0..4 {
                for a in 0..3 {
                    self.xt[j][p][a] += x[p] * t[a];
                }
            }
            for a in 0..3 {
                for b in 0..3 {
                    self.tt[j][a][b] += t[a] * t[b];
                }
            }
        }
    }

    fn combine(mut self, o: &Sums, sign: f64) -> Sums {
        self.n = if sign > 0.0 {
            self.n + o.n
        } else {
            self.n.saturating_sub(o.n)
        };
        for p in 0..4 {
            for q in 0..4 {
                self.xx[p][q] += sign * o.xx[p][q];
            }
        }
        for j in 0..3 {
            for p in 0..4 {
                for a in 0..3 {
                    self.xt[j][p][a] += sign * o.xt[j][p][a];
                }
            }
            for a in 0..3 {
                for b in 0..3 {
                    self.tt[j][a][b] += sign * o.tt[j][a][b];
                }
            }
        }
        self
    }

    /// The inverse of `Σ xxᵀ` and the residual quadratic form `G` (over `(cos ψ, sin ψ, 1)`, summed over axes).
    fn profile(&self) -> Option<(Matrix4<f64>, Matrix3<f64>)> {
        let xx = Matrix4::from_fn(|p, q| self.xx[p][q]);
        let inv = xx.try_inverse()?;
        let mut g = Matrix3::zeros();
        for j in 0..3 {
            let xt = nalgebra::Matrix4x3::from_fn(|p, a| self.xt[j][p][a]);
            let tt = Matrix3::from_fn(|a, b| self.tt[j][a][b]);
            g += tt - xt.transpose() * inv * xt;
        }
        Some((inv, g))
    }
}

/// The residual sum of squares at `psi` (rad) of the quadratic form `g`, and its first two derivatives.
fn ss(g: &Matrix3<f64>, psi: f64) -> (f64, f64, f64) {
    let (s, c) = psi.sin_cos();
    let w = nalgebra::Vector3::new(c, s, 1.0);
    let dw = nalgebra::Vector3::new(-s, c, 0.0);
    let ddw = nalgebra::Vector3::new(-c, -s, 0.0);
    let value = (w.transpose() * g * w)[0];
    let d1 = 2.0 * (dw.transpose() * g * w)[0];
    let d2 = 2.0 * ((ddw.transpose() * g * w)[0] + (dw.transpose() * g * dw)[0]);
    (value, d1, d2)
}

/// The heading (rad) at which `g` is least: from `start` when given (Newton steps), else from the best point of a
/// grid over the circle.
fn minimum(g: &Matrix3<f64>, start: Option<f64>) -> f64 {
    let mut psi = start.unwrap_or_else(|| {
        (0..GRID)
            .map(|k| k as f64 * std::f64::consts::TAU / GRID as f64)
            .min_by(|a, b| ss(g, *a).0.total_cmp(&ss(g, *b).0))
            .unwrap_or(0.0)
    });
    for _ in 0..NEWTON_STEPS {
        let (_, d1, d2) = ss(g, psi);
        if d2 <= 0.0 {
            break;
        }
        let step = (d1 / d2).clamp(-0.05, 0.05);
        psi -= step;
        if step.abs() < 1e-12 {
            break;
        }
    }
    wrap(psi)
}

/// An angle (rad) in (−π, π].
fn wrap(a: f64) -> f64 {
    let t = a.rem_euclid(std::f64::consts::TAU);
    if t > std::f64::consts::PI {
        t - std::f64::consts::TAU
    } else {
        t
    }
}

/// The heading of the reference against which the readings `raw_ut` fit best, with the attitude `quat` (sensor →
/// NED) and the world field `field_ned_ut`, on the samples `kept` (all when `None`; samples with a non-finite
/// reading or attitude are left out; at most about [`MOST_SAMPLES`] of them, in whole chunks spread over the
/// recording). `None` when fewer samples than parameters remain or the readings span no volume.
pub fn estimate(
    raw_ut: &[[f64; 3]],
    quat: &[[f64; 4]],
    field_ned_ut: [f64; 3],
    kept: Option<&[bool]>,
) -> Option<HeadingEstimate> {
    let n = raw_ut.len().min(quat.len());
    let [f_n, f_e, f_d] = field_ned_ut;
    let basis = [[f_n, f_e, 0.0], [f_e, -f_n, 0.0], [0.0, 0.0, f_d]];
    let stride = n.div_ceil(MOST_SAMPLES).max(1);
    let usable = |i: usize| {
        (i / chunks::CHUNK).is_multiple_of(stride)
            && kept.is_none_or(|kept| kept[i])
            && raw_ut[i].iter().chain(&quat[i]).all(|v| v.is_finite())
    };
    let bounds = block_bounds(n, usable);
    let block_sums: Vec<Sums> = chunks::parts(bounds.len() - 1, |k| {
        let mut s = Sums::default();
        for i in (bounds[k]..bounds[k + 1]).filter(|&i| usable(i)) {
            s.add(raw_ut[i], &frames::quat_to_matrix(quat[i]), &basis);
        }
        s
    });
    let total = block_sums
        .iter()
        .fold(Sums::default(), |acc, s| acc.combine(s, 1.0));
    let (inv, g) = total.profile()?;
    // Twelve parameters of A and b, and the heading.
    let dof = (3 * total.n).checked_sub(13).filter(|d| *d > 0)? as f64;
    let psi = minimum(&g, None);
    let (ss_min, _, curvature) = ss(&g, psi);
    let sigma2 = ss_min.max(0.0) / dof;
    let white_var = if curvature > 0.0 {
        2.0 * sigma2 / curvature
    } else {
        f64::INFINITY
    };
    let jackknife_var = jackknife(&total, &block_sums, psi);
    let se_deg = white_var.max(jackknife_var).sqrt().to_degrees();
    let (s, c) = psi.sin_cos();
    let coefficients = |w: [f64; 3]| -> [[f64; 4]; 3] {
        std::array::from_fn(|j| {
            let xt = nalgebra::Matrix4x3::from_fn(|p, a| total.xt[j][p][a]);
            let beta: Vector4<f64> = inv * xt * nalgebra::Vector3::from(w);
            [beta[0], beta[1], beta[2], beta[3]]
        })
    };
    let beta = coefficients([c, s, 1.0]);
    let per_axis = |v: f64| (v.max(0.0) / total.n as f64 / 3.0).sqrt();
    Some(HeadingEstimate {
        heading_deg: psi.to_degrees(),
        se_deg,
        n: total.n,
        rms_ut: per_axis(ss_min),
        rms_unturned_ut: per_axis(ss(&g, 0.0).0),
        a: std::array::from_fn(|j| [beta[j][0], beta[j][1], beta[j][2]]),
        b_ut: std::array::from_fn(|j| beta[j][3]),
        sensitivity: coefficients([-s, c, 0.0]),
    })
}

/// The starts of [`JACKKNIFE_BLOCKS`] blocks of time over rows `0..n` holding about as many `usable` rows each (the
/// rows the robust fit kept may leave a third of the recording out), and `n`.
fn block_bounds(n: usize, usable: impl Fn(usize) -> bool) -> Vec<usize> {
    let total = (0..n).filter(|&i| usable(i)).count();
    let blocks = JACKKNIFE_BLOCKS.min(total.max(1));
    let mut bounds = vec![0];
    let mut seen = 0;
    for i in 0..n {
        if usable(i) {
            if seen * blocks >= bounds.len() * total && bounds.len() < blocks {
                bounds.push(i);
            }
            seen += 1;
        }
    }
    bounds.push(n);
    bounds
}

/// The block jackknife's variance of the heading (rad²) found at `psi` from `total`, each of `blocks` left out in
/// turn; zero when a block holds too few samples to leave out.
fn jackknife(total: &Sums, blocks: &[Sums], psi: f64) -> f64 {
    let k = blocks.len();
    if k < 2 || blocks.iter().any(|b| b.n < MIN_BLOCK_SAMPLES) {
        return 0.0;
    }
    let deltas: Option<Vec<f64>> = blocks
        .iter()
        .map(|b| {
            let (_, g) = total.combine(b, -1.0).profile()?;
            Some(wrap(minimum(&g, Some(psi)) - psi))
        })
        .collect();
    let Some(deltas) = deltas else {
        return f64::INFINITY;
    };
    let mean = deltas.iter().sum::<f64>() / k as f64;
    (k - 1) as f64 / k as f64 * deltas.iter().map(|d| (d - mean).powi(2)).sum::<f64>()
}

/// [`estimate`] from the samples `start` keeps (all when `None`), refitted [`TRIM_PASSES`] times on the samples
/// within [`TRIM_MEDIANS`] times the median residual of the pass before: for a recording whose robust fit against the
/// reference as given failed, where a field on the board or in the room for part of it drags a plain fit.
pub fn estimate_trimmed(
    raw_ut: &[[f64; 3]],
    quat: &[[f64; 4]],
    field_ned_ut: [f64; 3],
    start: Option<&[bool]>,
) -> Option<HeadingEstimate> {
    let mut est = estimate(raw_ut, quat, field_ned_ut, start)?;
    for _ in 0..TRIM_PASSES {
        let field = est.field_in_reference(field_ned_ut);
        let residual: Vec<f64> = chunks::map(raw_ut.len().min(quat.len()), |i| {
            let calibrated = frames::add(frames::mat_vec(&est.a, raw_ut[i]), est.b_ut);
            frames::norm(frames::sub(
                calibrated,
                frames::expected_sensor_field(quat[i], field),
            ))
        });
        let finite: Vec<f64> = residual.iter().copied().filter(|r| r.is_finite()).collect();
        let limit = TRIM_MEDIANS * median(&finite);
        let kept: Vec<bool> = residual.iter().map(|r| *r <= limit).collect();
        est = estimate(raw_ut, quat, field_ned_ut, Some(&kept))?;
    }
    Some(est)
}

/// `fit`'s covariance (each axis' block) widened by the heading's uncertainty, which a fit against the field turned
/// by `est`'s heading takes as known: `+ se²·gⱼ·gⱼᵀ` with `gⱼ` the axis' [`HeadingEstimate::sensitivity`]; its
/// standard errors follow.
pub fn widen(fit: &mut VectorFit, est: &HeadingEstimate) {
    let var = est.se_deg.to_radians().powi(2);
    for (j, g) in est.sensitivity.iter().enumerate() {
        for p in 0..4 {
            for q in 0..4 {
                fit.covariance[j][p][q] += var * g[p] * g[q];
            }
        }
        for k in 0..3 {
            fit.a_se[j][k] = fit.covariance[j][k][k].sqrt();
        }
        fit.b_se_ut[j] = fit.covariance[j][3][3].sqrt();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    const FIELD: [f64; 3] = [19.8, 1.2, 45.3];
    const A: Mat3 = [[1.05, 0.02, -0.01], [0.01, 0.97, 0.03], [-0.02, 0.01, 1.1]];
    const B: [f64; 3] = [20.0, -35.0, 12.0];

    /// Readings of a sensor (`A`, `B`, noise `sigma_ut`) at attitudes `quat` taken against a reference whose north
    /// is `heading_deg` east of true north.
    fn readings(quat: &[[f64; 4]], heading_deg: f64, sigma_ut: f64, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let a_inv = Matrix3::from_fn(|j, k| A[j][k]).try_inverse().unwrap();
        quat.iter()
            .map(|q| {
                let field = frames::expected_sensor_field(true_attitude(*q, heading_deg), FIELD);
                let m = a_inv * nalgebra::Vector3::from(frames::sub(field, B));
                std::array::from_fn(|k| {
                    let g: f64 = StandardNormal.sample(&mut rng);
                    m[k] + sigma_ut * g
                })
            })
            .collect()
    }

    /// Attitudes turning through every direction.
    fn tumble(n: usize) -> Vec<[f64; 4]> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.01;
                let axis = [(0.3 * t).sin(), (0.17 * t).cos(), (0.11 * t + 1.0).sin()];
                let angle = 1.3 * t;
                let len = frames::norm(axis);
                let (s, c) = (angle / 2.0).sin_cos();
                [c, s * axis[0] / len, s * axis[1] / len, s * axis[2] / len]
            })
            .collect()
    }

    #[test]
    fn the_turned_field_is_the_field_in_the_references_axes() {
        // A reference lined up with magnetic north sees no declination.
        let declination = frames::field_angles(FIELD).0;
        let f = turned(FIELD, declination);
        assert!(f[1].abs() < 1e-12 && (f[0] - FIELD[0].hypot(FIELD[1])).abs() < 1e-12);
        // The field a sensor sees at its true attitude is the turned field seen at the reference's attitude.
        for q in tumble(50) {
            let want = frames::expected_sensor_field(true_attitude(q, 33.0), FIELD);
            let got = frames::expected_sensor_field(q, turned(FIELD, 33.0));
            assert!((0..3).all(|k| (want[k] - got[k]).abs() < 1e-9));
        }
    }

    #[test]
    fn every_heading_is_found_within_its_standard_error() {
        let quat = tumble(6000);
        for (seed, heading_deg) in [0.0, 5.0, -10.0, 30.0, 90.0, 179.0].into_iter().enumerate() {
            let raw = readings(&quat, heading_deg, 0.3, seed as u64);
            let est = estimate(&raw, &quat, FIELD, None).unwrap();
            let off = (est.heading_deg - heading_deg + 540.0).rem_euclid(360.0) - 180.0;
            assert!(off.abs() < 4.0 * est.se_deg, "{heading_deg}: {est:?}");
            assert!(est.se_deg < 0.05, "{est:?}");
            assert!((est.rms_ut / 0.3 - 1.0).abs() < 0.1, "{est:?}");
            assert_eq!(est.material(0.3), heading_deg != 0.0, "{est:?}");
            assert!(
                heading_deg == 0.0 || est.explained_share(0.3) > 0.95,
                "{est:?}"
            );
            for j in 0..3 {
                assert!((est.b_ut[j] - B[j]).abs() < 0.1, "{est:?}");
                for k in 0..3 {
                    assert!((est.a[j][k] - A[j][k]).abs() < 0.005, "{est:?}");
                }
            }
        }
    }

    #[test]
    fn a_turn_about_the_vertical_alone_does_not_determine_it() {
        // The sensor level on a turntable: the turn of the reference is a turn of A.
        let quat: Vec<[f64; 4]> = (0..3000)
            .map(|i| {
                let (s, c) = (i as f64 * 0.004).sin_cos();
                [c, 0.0, 0.0, s]
            })
            .collect();
        let raw = readings(&quat, 10.0, 0.3, 7);
        let est = estimate(&raw, &quat, FIELD, None);
        assert!(
            est.is_none_or(|e| !e.determined() && !e.material(0.3)),
            "{est:?}"
        );
    }

    #[test]
    fn trimming_leaves_a_field_on_the_board_out() {
        let quat = tumble(6000);
        let mut raw = readings(&quat, 30.0, 0.3, 3);
        for m in &mut raw[1000..2200] {
            m[0] += 40.0;
        }
        let est = estimate_trimmed(&raw, &quat, FIELD, None).unwrap();
        assert!((est.heading_deg - 30.0).abs() < 0.1, "{est:?}");
        assert!(est.rms_ut < 0.4, "{est:?}");
    }

    #[test]
    fn a_turn_that_explains_little_of_the_misfit_is_not_the_references() {
        // A significant 2° turn under a misfit five times the noise that no turn explains (a field that changes
        // along the path, the reference's own error).
        let quat = tumble(6000);
        let mut raw = readings(&quat, 2.0, 0.3, 5);
        for (i, m) in raw.iter_mut().enumerate() {
            let t = i as f64 * 0.01;
            m[0] += 1.5 * (0.9 * t).sin();
            m[2] += 1.5 * (0.7 * t + 1.0).cos();
        }
        let est = estimate(&raw, &quat, FIELD, None).unwrap();
        assert!(
            est.heading_deg.abs() > SIGNIFICANT_SE * est.se_deg,
            "{est:?}"
        );
        assert!(est.explained_share(0.3) < EXPLAINED_SHARE, "{est:?}");
        assert!(!est.material(0.3), "{est:?}");
    }
}
