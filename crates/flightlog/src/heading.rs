//! The estimator's heading is partly the compass's own: in flight the autopilot fuses the magnetometer, with the
//! calibration it had, into its yaw. A fit against the estimator's attitude would then learn that calibration's
//! heading errors back. What the estimator knows without the compass is its tilt (from gravity), so the calibration
//! is fitted to what the tilt and the World Magnetic Model say whatever the heading: the field's magnitude and its
//! component along the down direction (the dip) — [`fit_magnitude_dip`], with the current's field as a term. The
//! reference's heading is then fitted ([`rehead`]): the estimator's heading error, as a compass deviation curve of
//! its heading, is fitted to where that fit's field points and taken out. Where the flight does not determine a
//! parameter (a level flight says little about the vertical axis' scale), the logged calibration's value stays.

use magcal_calib::frames::{Mat3, dot, mat_t_vec, mat_vec, norm, quat_to_matrix};
use nalgebra::{DMatrix, DVector};

/// A calibration fitted to the magnitude and the dip: the true field in sensor axes is `A·raw + b − Σ kᵢ·Iᵢ`, µT.
#[derive(Debug, Clone, PartialEq)]
pub struct MagnitudeDipFit {
    /// `A`, symmetric.
    pub a: Mat3,
    /// `b`, µT.
    pub b_ut: [f64; 3],
    /// The field each current channel adds per ampere, sensor axes, µT/A.
    pub k_ut_per_a: Vec<[f64; 3]>,
    /// RMS of `|B| − |F|`, µT.
    pub magnitude_rms_ut: f64,
    /// RMS of `B·down − F_down`, µT.
    pub down_rms_ut: f64,
}

impl MagnitudeDipFit {
    /// The true field of row `i`: `A·raw + b − Σ kᵢ·Iᵢ`, µT (a missing current counts as none).
    pub fn field_ut(&self, raw_ut: [f64; 3], currents_a: &[f64]) -> [f64; 3] {
        let mut v = mat_vec(&self.a, raw_ut);
        for k in 0..3 {
            v[k] += self.b_ut[k];
            for (c, i) in self.k_ut_per_a.iter().zip(currents_a) {
                if i.is_finite() {
                    v[k] -= c[k] * i;
                }
            }
        }
        v
    }
}

/// The down direction in sensor axes of an attitude `q` (sensor → NED): it does not depend on the heading.
pub fn down_in_sensor(q: [f64; 4]) -> [f64; 3] {
    mat_t_vec(&quat_to_matrix(q), [0.0, 0.0, 1.0])
}

/// Each parameter's pull towards the start, relative to the weight the rows give it: enough to hold a direction
/// the rows do not determine, too little to move one they do.
const PULL: f64 = 1e-5;

/// Number of parameters: 6 of the symmetric `A`, 3 of `b`, 3 per current channel.
fn parameters(channels: usize) -> usize {
    9 + 3 * channels
}

/// `∂B/∂θ`: the derivative of the field with respect to each parameter, for one row.
fn jacobian(raw: [f64; 3], currents: &[f64]) -> Vec<[f64; 3]> {
    let [x, y, z] = raw;
    let mut d = vec![
        [x, 0.0, 0.0],
        [0.0, y, 0.0],
        [0.0, 0.0, z],
        [y, x, 0.0],
        [z, 0.0, x],
        [0.0, z, y],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    for i in currents {
        let i = if i.is_finite() { *i } else { 0.0 };
        d.extend([[-i, 0.0, 0.0], [0.0, -i, 0.0], [0.0, 0.0, -i]]);
    }
    d
}

fn to_params(a: &Mat3, b: [f64; 3], k: &[[f64; 3]]) -> DVector<f64> {
    let mut p = vec![a[0][0], a[1][1], a[2][2], a[0][1], a[0][2], a[1][2]];
    p.extend(b);
    for c in k {
        p.extend(c);
    }
    DVector::from_vec(p)
}

fn from_params(p: &DVector<f64>, channels: usize) -> MagnitudeDipFit {
    let a = [[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]];
    MagnitudeDipFit {
        a,
        b_ut: [p[6], p[7], p[8]],
        k_ut_per_a: (0..channels)
            .map(|c| [p[9 + 3 * c], p[10 + 3 * c], p[11 + 3 * c]])
            .collect(),
        magnitude_rms_ut: f64::NAN,
        down_rms_ut: f64::NAN,
    }
}

/// Rows of the problem: raw field, down direction, currents.
pub struct Rows<'a> {
    /// Raw field per row, sensor axes, µT.
    pub raw_ut: &'a [[f64; 3]],
    /// Down direction per row, sensor axes ([`down_in_sensor`]).
    pub down: &'a [[f64; 3]],
    /// Currents per row, A, one vector per row (empty without channels).
    pub currents_a: &'a [Vec<f64>],
}

/// Residuals (magnitude, down) and the sum of squares of a fit.
fn residuals(fit: &MagnitudeDipFit, rows: &Rows<'_>, field_ned_ut: [f64; 3]) -> (f64, f64) {
    let (mut sm, mut sd) = (0.0, 0.0);
    for i in 0..rows.raw_ut.len() {
        let b = fit.field_ut(rows.raw_ut[i], &rows.currents_a[i]);
        sm += (norm(b) - norm(field_ned_ut)).powi(2);
        sd += (dot(b, rows.down[i]) - field_ned_ut[2]).powi(2);
    }
    (sm, sd)
}

/// Fits `A` (symmetric), `b` and the currents' fields to the magnitude `|F|` and the down component `F_down` of the
/// world field, from `start` (the logged calibration); a weak pull towards the start ([`PULL`]) keeps what the rows
/// do not determine. `None` with fewer rows than twice the parameters, or if it fails.
pub fn fit_magnitude_dip(
    rows: &Rows<'_>,
    field_ned_ut: [f64; 3],
    start: (Mat3, [f64; 3]),
) -> Option<MagnitudeDipFit> {
    let channels = rows.currents_a.first().map_or(0, Vec::len);
    let np = parameters(channels);
    let n = rows.raw_ut.len();
    if 2 * n < 2 * np {
        return None;
    }
    let p0 = to_params(&start.0, start.1, &vec![[0.0; 3]; channels]);
    let mut p = p0.clone();
    let (f_mag, f_down) = (norm(field_ned_ut), field_ned_ut[2]);
    let mut lambda = 1e-3;
    let cost = |p: &DVector<f64>| {
        let (m, d) = residuals(&from_params(p, channels), rows, field_ned_ut);
        m + d
    };
    let mut current = cost(&p);
    for _ in 0..100 {
        let fit = from_params(&p, channels);
        let mut jtj = DMatrix::<f64>::zeros(np, np);
        let mut jtr = DVector::<f64>::zeros(np);
        for i in 0..n {
            let b = fit.field_ut(rows.raw_ut[i], &rows.currents_a[i]);
            let nb = norm(b);
            let u = [b[0] / nb, b[1] / nb, b[2] / nb];
            let d = jacobian(rows.raw_ut[i], &rows.currents_a[i]);
            for (w, r) in [
                (u, nb - f_mag),
                (rows.down[i], dot(b, rows.down[i]) - f_down),
            ] {
                let row = DVector::from_iterator(np, d.iter().map(|g| dot(w, *g)));
                jtj += &row * row.transpose();
                jtr += &row * r;
            }
        }
        // Each parameter's pull towards the start, relative to what the rows say of it.
        let prior = DVector::from_iterator(np, (0..np).map(|j| PULL * jtj[(j, j)].max(1e-12)));
        let mut improved = false;
        for _ in 0..10 {
            let mut h = jtj.clone();
            for j in 0..np {
                h[(j, j)] += prior[j] + lambda * jtj[(j, j)].max(1e-12);
            }
            let g = &jtr + (&p - &p0).component_mul(&prior);
            let step = h.cholesky()?.solve(&g);
            let trial = &p - &step;
            let c = cost(&trial);
            if c.is_finite() && c < current {
                let small = step.norm() < 1e-9 * (1.0 + p.norm());
                (p, current, lambda) = (trial, c, (lambda * 0.3).max(1e-9));
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let mut fit = from_params(&p, channels);
    let (m, d) = residuals(&fit, rows, field_ned_ut);
    fit.magnitude_rms_ut = (m / n as f64).sqrt();
    fit.down_rms_ut = (d / n as f64).sqrt();
    Some(fit)
}

/// The heading (degrees, 0–360) of the sensor's x axis for an attitude `q` (sensor → NED); of its y axis when x
/// points nearly straight up or down.
pub fn heading_deg(q: [f64; 4]) -> f64 {
    let m = quat_to_matrix(q);
    let (n, e) = (m[0][0], m[1][0]);
    let (n, e) = if n.hypot(e) < 0.2 {
        (m[0][1], m[1][1])
    } else {
        (n, e)
    };
    e.atan2(n).to_degrees().rem_euclid(360.0)
}

/// Regressors of a compass deviation curve at heading `psi` (radians): a constant (misalignment), the first harmonic
/// (hard iron) and the second (soft iron).
fn deviation_terms(psi: f64) -> [f64; 5] {
    [
        1.0,
        psi.cos(),
        psi.sin(),
        (2.0 * psi).cos(),
        (2.0 * psi).sin(),
    ]
}

/// The estimator's heading error, fitted as a compass deviation curve of its heading ([`rehead`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deviation {
    /// The curve's coefficients, radians: constant, cos ψ, sin ψ, cos 2ψ, sin 2ψ.
    pub coef: [f64; 5],
    /// Its χ² against no error (5 degrees of freedom).
    pub chi2: f64,
    /// Whether it was taken out (χ² above [`DEVIATION_CHI2`]).
    pub applied: bool,
    /// Its largest value over the headings, degrees.
    pub max_deg: f64,
}

/// χ² (5 degrees of freedom) above which the estimator's heading error is taken out: 0.1 % by chance.
pub const DEVIATION_CHI2: f64 = 20.5;

/// The attitude's angular rate at each row in world (NED) axes, rad/s, from its neighbours in time (`t_s`, s).
pub fn angular_rate_ned(quat: &[[f64; 4]], t_s: &[f64]) -> Vec<[f64; 3]> {
    let n = quat.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let dt = t_s[b] - t_s[a];
            let [w, x, y, z] = quat[a];
            let d = crate::recording::quat_mul(quat[b], [w, -x, -y, -z]);
            let d = if d[0] < 0.0 { d.map(|v| -v) } else { d };
            let v = [d[1], d[2], d[3]];
            let s = norm(v);
            if dt <= 0.0 || s < 1e-15 {
                return [0.0; 3];
            }
            let angle = 2.0 * s.atan2(d[0]);
            v.map(|c| c / s * angle / dt)
        })
        .collect()
}

/// Fits the estimator's heading error as a compass deviation curve of its own heading and, if it is there (χ² above
/// [`DEVIATION_CHI2`]), takes it out: each attitude `quat` (sensor → NED) is turned about the vertical by the curve's
/// value at its heading. The curve is fitted (least squares, each row weighted by its horizontal field's share) to
/// the turns that would make the expected field point where the fitted field `field_ut` (sensor axes) points, with
/// the attitude's angular rate `rate_ned` (world axes, rad/s, [`angular_rate_ned`]) as three further terms: a
/// magnetometer sampling late turns its field by the lag times that rate, which is the fit's to find, not the
/// curve's. An estimator that fused a compass with another
/// calibration has exactly such a curve in level flight (the old calibration's hard iron in the first harmonic,
/// its soft iron in the second); a current's field does not follow the heading either. `None` if the curve cannot
/// be fitted (nothing turned).
pub fn rehead(
    quat: &mut [[f64; 4]],
    field_ut: &[[f64; 3]],
    field_ned_ut: [f64; 3],
    rate_ned: &[[f64; 3]],
) -> Option<Deviation> {
    type V8 = nalgebra::SVector<f64, 8>;
    let declination = field_ned_ut[1].atan2(field_ned_ut[0]);
    let terms = |q: [f64; 4], r: [f64; 3]| {
        let [a, b, c, d, e] = deviation_terms(heading_deg(q).to_radians());
        V8::from([a, b, c, d, e, r[0], r[1], r[2]])
    };
    let mut rows = Vec::with_capacity(quat.len());
    for ((q, b), rate) in quat.iter().zip(field_ut).zip(rate_ned) {
        let ned = mat_vec(&quat_to_matrix(*q), *b);
        let horizontal = ned[0].hypot(ned[1]) / norm(*b).max(1e-12);
        if !horizontal.is_finite() || horizontal < 0.1 || !rate.iter().all(|r| r.is_finite()) {
            continue;
        }
        let turn = (declination - ned[1].atan2(ned[0]) + std::f64::consts::PI)
            .rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        rows.push((terms(*q, *rate), turn, horizontal * horizontal));
    }
    let mut ata = nalgebra::SMatrix::<f64, 8, 8>::zeros();
    let mut atb = V8::zeros();
    for (x, turn, w) in &rows {
        ata += x * x.transpose() * *w;
        atb += x * (*turn * *w);
    }
    let inverse = ata.try_inverse()?;
    let c = inverse * atb;
    let ss: f64 = rows
        .iter()
        .map(|(x, turn, w)| w * (turn - x.dot(&c)).powi(2))
        .sum();
    let sigma2 = (ss / (rows.len() as f64 - 8.0).max(1.0)).max(1e-18);
    // χ² of the curve's five coefficients: their covariance is σ²·(XᵀWX)⁻¹'s first block.
    let curve = c.fixed_rows::<5>(0).into_owned();
    let cov = inverse.fixed_view::<5, 5>(0, 0) * sigma2;
    let chi2 = (curve.transpose() * cov.try_inverse()? * curve)[(0, 0)];
    let applied = chi2 > DEVIATION_CHI2;
    let at = |psi: f64| nalgebra::Vector5::from(deviation_terms(psi)).dot(&curve);
    let max_deg = (0..360)
        .map(|d| at(f64::from(d).to_radians()).abs())
        .fold(0.0, f64::max)
        .to_degrees();
    if applied {
        for q in quat.iter_mut() {
            let (s, co) = (0.5 * at(heading_deg(*q).to_radians())).sin_cos();
            *q = crate::recording::quat_mul([co, 0.0, 0.0, s], *q);
        }
    }
    Some(Deviation {
        coef: [c[0], c[1], c[2], c[3], c[4]],
        chi2,
        applied,
        max_deg,
    })
}

/// How much a flight turned: the span of headings it covered (360° less the largest gap between the sorted
/// headings of the sensor's horizontal x axis), and the largest tilt from the mean down direction, degrees.
pub fn turned(quat: &[[f64; 4]]) -> (f64, f64) {
    let mut headings: Vec<f64> = quat
        .iter()
        .map(|q| {
            let m = quat_to_matrix(*q);
            let (n, e) = (m[0][0], m[1][0]);
            let (n, e) = if n.hypot(e) < 0.2 {
                (m[0][1], m[1][1])
            } else {
                (n, e)
            };
            e.atan2(n).to_degrees().rem_euclid(360.0)
        })
        .collect();
    headings.sort_by(f64::total_cmp);
    let mut gap = headings
        .first()
        .zip(headings.last())
        .map_or(360.0, |(f, l)| 360.0 - (l - f));
    for w in headings.windows(2) {
        gap = gap.max(w[1] - w[0]);
    }
    let downs: Vec<[f64; 3]> = quat.iter().map(|q| down_in_sensor(*q)).collect();
    let mut mean = [0.0; 3];
    for d in &downs {
        for k in 0..3 {
            mean[k] += d[k];
        }
    }
    let nm = norm(mean).max(1e-12);
    let mean = mean.map(|v| v / nm);
    let tilt = downs
        .iter()
        .map(|d| dot(*d, mean).clamp(-1.0, 1.0).acos().to_degrees())
        .fold(0.0, f64::max);
    (360.0 - gap, tilt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::quat_mul;

    /// Attitudes of a flight: all headings, tilts up to 25°.
    fn attitudes(n: usize) -> Vec<[f64; 4]> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                // Three turns at a varying rate (a steady spin would make a lag and a misalignment one).
                let yaw = 2.0 * std::f64::consts::PI * (3.0 * t + 0.3 * (9.0 * t).sin());
                let roll = 0.4 * (7.0 * t).sin();
                let pitch = 0.35 * (5.0 * t).cos();
                let qz = [(0.5 * yaw).cos(), 0.0, 0.0, (0.5 * yaw).sin()];
                let qy = [(0.5 * pitch).cos(), 0.0, (0.5 * pitch).sin(), 0.0];
                let qx = [(0.5 * roll).cos(), (0.5 * roll).sin(), 0.0, 0.0];
                quat_mul(qz, quat_mul(qy, qx))
            })
            .collect()
    }

    #[test]
    fn a_wrong_estimator_heading_does_not_move_the_fit() {
        let field = [21.0, 1.5, 43.0];
        let a_true = [[1.05, 0.02, -0.01], [0.02, 0.97, 0.03], [-0.01, 0.03, 1.01]];
        let a_inv = nalgebra::Matrix3::from_fn(|r, c| a_true[r][c])
            .try_inverse()
            .unwrap();
        let b_true = [4.0, -6.0, 2.5];
        let k_true = [0.05, -0.08, 0.12]; // µT/A
        let q_true = attitudes(600);
        let (mut raw, mut down, mut currents, mut q_est) = (vec![], vec![], vec![], vec![]);
        for (i, q) in q_true.iter().enumerate() {
            let current = 20.0 + 30.0 * ((i as f64) * 0.07).sin().abs();
            let truth = mat_t_vec(&quat_to_matrix(*q), field);
            let cal: Vec<f64> = (0..3)
                .map(|k| truth[k] + k_true[k] * current - b_true[k])
                .collect();
            let r = a_inv * nalgebra::Vector3::new(cal[0], cal[1], cal[2]);
            raw.push([r[0], r[1], r[2]]);
            down.push(down_in_sensor(*q));
            currents.push(vec![current]);
            // The estimator's heading is off as a compass with another calibration would make it: a deviation
            // curve of its heading, up to 9°.
            let psi = heading_deg(*q).to_radians();
            let err = 0.03 + 0.08 * psi.cos() - 0.05 * (2.0 * psi).sin();
            q_est.push(quat_mul(
                [(0.5 * err).cos(), 0.0, 0.0, (0.5 * err).sin()],
                *q,
            ));
        }
        let rows = Rows {
            raw_ut: &raw,
            down: &down,
            currents_a: &currents,
        };
        let fit =
            fit_magnitude_dip(&rows, field, (magcal_calib::frames::IDENTITY, [0.0; 3])).unwrap();
        for k in 0..3 {
            assert!((fit.b_ut[k] - b_true[k]).abs() < 0.05, "{:?}", fit.b_ut);
            assert!(
                (fit.k_ut_per_a[0][k] - k_true[k]).abs() < 0.002,
                "{:?}",
                fit.k_ut_per_a
            );
            for j in 0..3 {
                assert!((fit.a[k][j] - a_true[k][j]).abs() < 2e-3, "{:?}", fit.a);
            }
        }
        assert!(
            fit.magnitude_rms_ut < 0.01 && fit.down_rms_ut < 0.01,
            "{fit:?}"
        );
        // Re-headed, the reference agrees with the true one wherever the estimator's heading was off (to 0.2 µT: the
        // curve is evaluated at the estimator's heading, the error was made at the true one).
        let fields: Vec<[f64; 3]> = (0..raw.len())
            .map(|i| fit.field_ut(raw[i], &currents[i]))
            .collect();
        let t: Vec<f64> = (0..q_est.len()).map(|i| i as f64 * 0.1).collect();
        let rate = angular_rate_ned(&q_est, &t);
        let curve = rehead(&mut q_est, &fields, field, &rate).unwrap();
        assert!(
            curve.applied && (curve.max_deg - 8.0).abs() < 2.0,
            "{curve:?}"
        );
        let c = curve.coef;
        assert!(
            (c[0] + 0.03).abs() < 0.01 && (c[1] + 0.08).abs() < 0.01,
            "{curve:?}"
        );
        // Once taken out, nothing is left to take.
        let again = rehead(&mut q_est.clone(), &fields, field, &rate).unwrap();
        assert!(again.max_deg < 0.5, "{again:?}");
        for (q, t) in q_est.iter().zip(&q_true) {
            let (e, w) = (
                mat_t_vec(&quat_to_matrix(*q), field),
                mat_t_vec(&quat_to_matrix(*t), field),
            );
            assert!(norm(magcal_calib::frames::sub(e, w)) < 0.2, "{e:?} {w:?}");
        }
        let (span, tilt) = turned(&q_true);
        assert!(span > 350.0 && tilt > 20.0, "{span} {tilt}");
    }
}
