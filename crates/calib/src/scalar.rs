//! The classic scalar calibration: find `A` (symmetric) and `b` so that `|A·B̂ + b|` equals the field magnitude at
//! every sample.
//!
//! First an algebraic fit of the general quadric through the readings (the unit-norm coefficient vector minimising
//! the algebraic distance, on centred and scaled data), turned into centre and shape; then Levenberg–Marquardt on the
//! magnitude residual `|A·B̂ + b| − F`. Only the magnitude is constrained, so a rotation of the calibrated field is
//! invisible: see [`ROTATION_NOTE`].

use nalgebra::{Matrix3, SMatrix, SVector, SymmetricEigen, Vector3};

use crate::FitError;
use crate::coverage::Coverage;
use crate::frames::Mat3;
use crate::model::Model;

/// What the scalar method cannot see, in words for reports.
pub const ROTATION_NOTE: &str = "the scalar method constrains only |B|, and a rotation of the calibrated field leaves \
|B| unchanged: it cannot observe the sensor's misalignment, so A is the symmetric matrix that maps the readings onto a \
sphere and the components are only as well aligned as the sensor is mounted";

/// Parameters: the six entries of the symmetric `A` (xx, yy, zz, xy, xz, yz) and `b` (x, y, z).
const P: usize = 9;
const MAX_ITERATIONS: usize = 100;

/// Options of the scalar fit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScalarOptions {
    /// The field magnitude, µT. Without it, the calibrated sphere keeps the volume of the raw ellipsoid.
    pub field_ut: Option<f64>,
    /// Skip the coverage check.
    pub skip_coverage_check: bool,
}

/// The result of a scalar fit.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalarFit {
    /// `A`, symmetric, row-major.
    pub a: Mat3,
    /// `b`, µT.
    pub b_ut: [f64; 3],
    /// Standard error of each entry of `A`.
    pub a_se: Mat3,
    /// Standard error of each entry of `b`, µT.
    pub b_se_ut: [f64; 3],
    /// The magnitude the fit aimed at, µT.
    pub field_ut: f64,
    /// Whether that magnitude was given (otherwise it is the raw ellipsoid's mean radius).
    pub field_given: bool,
    /// RMS of `|A·B̂ + b| − F`, µT.
    pub residual_rms_ut: f64,
    /// Levenberg–Marquardt iterations.
    pub iterations: usize,
    /// Samples used.
    pub n: usize,
    /// Spread of the readings.
    pub coverage: Coverage,
}

impl ScalarFit {
    /// The fitted linear model.
    pub fn model(&self) -> Model {
        Model::linear(self.a, self.b_ut)
    }

    /// The raw ellipsoid's semi-axes, largest first, µT: the field magnitude over the eigenvalues of `A`.
    pub fn radii_ut(&self) -> [f64; 3] {
        let a = Matrix3::from_fn(|j, k| self.a[j][k]);
        let mut r: Vec<f64> = SymmetricEigen::new(a)
            .eigenvalues
            .iter()
            .map(|l| self.field_ut / l)
            .collect();
        r.sort_by(|x, y| y.total_cmp(x));
        [r[0], r[1], r[2]]
    }

    /// The ellipsoid's centre in raw units, `−A⁻¹·b` (the hard-iron offset as most tools quote it), µT.
    pub fn centre_ut(&self) -> [f64; 3] {
        centre(&self.a, self.b_ut)
    }
}

/// `−A⁻¹·b`: the raw reading that calibrates to zero.
pub fn centre(a: &Mat3, b_ut: [f64; 3]) -> [f64; 3] {
    let a = Matrix3::from_fn(|j, k| a[j][k]);
    let c = -(a.try_inverse().unwrap_or_else(Matrix3::zeros) * Vector3::from(b_ut));
    [c[0], c[1], c[2]]
}

/// Fits a symmetric `A` and `b` to raw readings (µT) so that the calibrated magnitude is constant.
pub fn fit(raw_ut: &[[f64; 3]], opts: &ScalarOptions) -> Result<ScalarFit, FitError> {
    const NEEDED: usize = 20;
    if raw_ut.len() < NEEDED {
        return Err(FitError::TooFewSamples {
            needed: NEEDED,
            got: raw_ut.len(),
        });
    }
    let coverage = Coverage::of(raw_ut);
    if !opts.skip_coverage_check {
        coverage.check()?;
    }
    let n = raw_ut.len();
    let mean = raw_ut
        .iter()
        .fold(Vector3::zeros(), |s, m| s + Vector3::from(*m))
        / n as f64;
    let centred: Vec<Vector3<f64>> = raw_ut.iter().map(|m| Vector3::from(*m) - mean).collect();

    let (shape, centre_c) = algebraic(&centred)?;
    // shape maps (m − centre) onto the unit sphere; its volume-preserving radius is det(shape)^(−1/3).
    let mean_radius = shape.determinant().cbrt().recip();
    let field_ut = opts.field_ut.unwrap_or(mean_radius);
    let a0 = shape * field_ut;
    let b0 = -(a0 * centre_c);
    let mut p = pack(&a0, &b0);

    let mut lambda = 1e-3;
    let (mut jtj, mut jtr, mut rss) = normal_equations(&centred, &p, field_ut);
    let mut iterations = 0;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let mut damped = jtj;
        for k in 0..P {
            damped[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&(-jtr))) else {
            lambda *= 10.0;
            continue;
        };
        let trial = p + step;
        let (t_jtj, t_jtr, t_rss) = normal_equations(&centred, &trial, field_ut);
        if t_rss <= rss {
            let converged = rss - t_rss <= 1e-12 * rss.max(1e-300);
            (p, jtj, jtr, rss) = (trial, t_jtj, t_jtr, t_rss);
            lambda = (lambda / 10.0).max(1e-12);
            if converged {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
        }
    }

    let (a, b_c) = unpack(&p);
    let b = b_c - a * mean; // back from centred readings
    let dof = (n - P) as f64;
    let cov = jtj.try_inverse().ok_or(FitError::Singular(
        "the magnitude residual's normal matrix has no inverse",
    ))? * (rss / dof);
    // Standard errors: A from the first six parameters; b = b_c − A·mean needs the full propagation.
    let mut jac_b = SMatrix::<f64, 3, P>::zeros();
    for j in 0..3 {
        jac_b[(j, 6 + j)] = 1.0;
        for (idx, (r, s)) in SYM.iter().enumerate() {
            if *r == j {
                jac_b[(j, idx)] -= mean[*s];
            }
            if *s == j && r != s {
                jac_b[(j, idx)] -= mean[*r];
            }
        }
    }
    let cov_b = jac_b * cov * jac_b.transpose();
    let mut a_se = [[0.0; 3]; 3];
    for (idx, (r, s)) in SYM.iter().enumerate() {
        a_se[*r][*s] = cov[(idx, idx)].sqrt();
        a_se[*s][*r] = cov[(idx, idx)].sqrt();
    }
    Ok(ScalarFit {
        a: std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)])),
        b_ut: [b[0], b[1], b[2]],
        a_se,
        b_se_ut: std::array::from_fn(|j| cov_b[(j, j)].sqrt()),
        field_ut,
        field_given: opts.field_ut.is_some(),
        residual_rms_ut: (rss / n as f64).sqrt(),
        iterations,
        n,
        coverage,
    })
}

/// Index pairs of the symmetric matrix's parameters.
const SYM: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

fn pack(a: &Matrix3<f64>, b: &Vector3<f64>) -> SVector<f64, P> {
    let mut p = SVector::<f64, P>::zeros();
    for (idx, (r, s)) in SYM.iter().enumerate() {
        p[idx] = (a[(*r, *s)] + a[(*s, *r)]) / 2.0;
    }
    p.fixed_rows_mut::<3>(6).copy_from(b);
    p
}

fn unpack(p: &SVector<f64, P>) -> (Matrix3<f64>, Vector3<f64>) {
    let mut a = Matrix3::zeros();
    for (idx, (r, s)) in SYM.iter().enumerate() {
        a[(*r, *s)] = p[idx];
        a[(*s, *r)] = p[idx];
    }
    (a, p.fixed_rows::<3>(6).into_owned())
}

/// `JᵀJ`, `Jᵀr` and the residual sum of squares of `r_i = |A·m_i + b| − F`.
fn normal_equations(
    centred: &[Vector3<f64>],
    p: &SVector<f64, P>,
    field_ut: f64,
) -> (SMatrix<f64, P, P>, SVector<f64, P>, f64) {
    let (a, b) = unpack(p);
    let mut jtj = SMatrix::<f64, P, P>::zeros();
    let mut jtr = SVector::<f64, P>::zeros();
    let mut rss = 0.0;
    for m in centred {
        let v = a * m + b;
        let norm = v.norm();
        let r = norm - field_ut;
        let u = v / norm;
        let mut j = SVector::<f64, P>::zeros();
        for (idx, (r_, s_)) in SYM.iter().enumerate() {
            j[idx] = if r_ == s_ {
                u[*r_] * m[*s_]
            } else {
                u[*r_] * m[*s_] + u[*s_] * m[*r_]
            };
        }
        j.fixed_rows_mut::<3>(6).copy_from(&u);
        jtj += j * j.transpose();
        jtr += j * r;
        rss += r * r;
    }
    (jtj, jtr, rss)
}

/// The algebraic ellipsoid fit on centred readings: returns the symmetric shape `S` with `|S·(m − c)| = 1` on the
/// ellipsoid, and the centre `c`.
fn algebraic(centred: &[Vector3<f64>]) -> Result<(Matrix3<f64>, Vector3<f64>), FitError> {
    let scale =
        (centred.iter().map(|m| m.norm_squared()).sum::<f64>() / centred.len() as f64).sqrt();
    let mut dtd = SMatrix::<f64, 10, 10>::zeros();
    for m in centred {
        let u = m / scale;
        let row = SVector::<f64, 10>::from([
            u.x * u.x,
            u.y * u.y,
            u.z * u.z,
            2.0 * u.x * u.y,
            2.0 * u.x * u.z,
            2.0 * u.y * u.z,
            2.0 * u.x,
            2.0 * u.y,
            2.0 * u.z,
            1.0,
        ]);
        dtd += row * row.transpose();
    }
    let eig = SymmetricEigen::new(dtd);
    let v = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
    let quad = Matrix3::new(v[0], v[3], v[4], v[3], v[1], v[5], v[4], v[5], v[2]);
    let lin = Vector3::new(v[6], v[7], v[8]);
    let inv = quad
        .try_inverse()
        .ok_or(FitError::NotAnEllipsoid("degenerate quadric"))?;
    let c = -(inv * lin);
    let k = c.dot(&(quad * c)) - v[9];
    let w = quad / k;
    let weig = SymmetricEigen::new(w);
    if weig.eigenvalues.iter().any(|l| *l <= 0.0) {
        return Err(FitError::NotAnEllipsoid(
            if weig.eigenvalues.iter().all(|l| *l <= 0.0) {
                "imaginary ellipsoid"
            } else {
                "hyperboloid"
            },
        ));
    }
    let sqrt_w = weig.eigenvectors
        * Matrix3::from_diagonal(&weig.eigenvalues.map(f64::sqrt))
        * weig.eigenvectors.transpose();
    Ok((sqrt_w / scale, c * scale))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal, UnitSphere};

    fn ellipsoid(
        a_true: Matrix3<f64>,
        b_true: Vector3<f64>,
        sigma: f64,
        n: usize,
        seed: u64,
    ) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let inv = a_true.try_inverse().unwrap();
        (0..n)
            .map(|_| {
                let d: [f64; 3] = UnitSphere.sample(&mut rng);
                let m = inv * (Vector3::from(frames::scale(d, 50.0)) - b_true);
                [m.x, m.y, m.z].map(|v| v + noise.sample(&mut rng))
            })
            .collect()
    }

    #[test]
    fn recovers_a_symmetric_distortion() {
        let a_true = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.9, 0.03, -0.02, 0.03, 1.15);
        let b_true = Vector3::new(-30.0, 12.0, 44.0);
        let raw = ellipsoid(a_true, b_true, 0.0, 400, 4);
        let fit = fit(
            &raw,
            &ScalarOptions {
                field_ut: Some(50.0),
                ..Default::default()
            },
        )
        .unwrap();
        for j in 0..3 {
            assert!((fit.b_ut[j] - b_true[j]).abs() < 1e-6, "{:?}", fit.b_ut);
            for k in 0..3 {
                assert!((fit.a[j][k] - a_true[(j, k)]).abs() < 1e-8);
            }
        }
        assert!(fit.residual_rms_ut < 1e-8);
    }

    #[test]
    fn without_a_magnitude_the_sphere_keeps_the_ellipsoids_volume() {
        let a_true = Matrix3::from_diagonal(&Vector3::new(1.2, 1.0, 0.8));
        let raw = ellipsoid(a_true, Vector3::new(5.0, 5.0, 5.0), 0.0, 300, 5);
        let fit = fit(&raw, &ScalarOptions::default()).unwrap();
        // Raw radii 50/1.2, 50, 50/0.8: their geometric mean.
        let want = 50.0 / (1.2f64 * 0.8).cbrt();
        assert!((fit.field_ut - want).abs() < 1e-6, "{}", fit.field_ut);
        let radii = fit.radii_ut();
        for (r, w) in radii.iter().zip([50.0 / 0.8, 50.0, 50.0 / 1.2]) {
            assert!((r - w).abs() < 1e-6, "{radii:?}");
        }
        assert!(!fit.field_given);
    }

    #[test]
    fn points_on_a_hyperboloid_are_not_an_ellipsoid() {
        let raw: Vec<[f64; 3]> = (0..400)
            .map(|i| {
                let (u, v) = ((i % 20) as f64 * 0.3 - 3.0, (i / 20) as f64 * 0.314);
                [
                    10.0 * u.cosh() * v.cos(),
                    10.0 * u.cosh() * v.sin(),
                    10.0 * u.sinh(),
                ]
            })
            .collect();
        assert!(matches!(
            fit(
                &raw,
                &ScalarOptions {
                    field_ut: Some(50.0),
                    skip_coverage_check: true
                }
            ),
            Err(FitError::NotAnEllipsoid(_))
        ));
    }
}
