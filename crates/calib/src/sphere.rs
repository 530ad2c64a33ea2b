//! The sphere raw readings lie on, before any calibration: the least-squares sphere `|m|² = 2·c·m + k`, linear in
//! the centre `c` (the hard-iron offset, roughly) and `k`, so its sums can be kept as readings arrive; and which
//! readings are off it (a magnet or iron near the sensor changes the field's magnitude).

use nalgebra::{Matrix3, Matrix4, SymmetricEigen, Vector4};

use crate::coverage::{REFUSE_RATIO, STILL_SPREAD_UT};

/// A reading is off the sphere when its distance from the centre differs from the radius by more than this
/// fraction of it…
pub const OFF_SPHERE: f64 = 0.15;
/// …and by more than this, µT (so noise on a weak field is never a departure).
pub const MIN_OFF_SPHERE_UT: f64 = 5.0;

/// A sphere in raw sensor axes, µT.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// The centre, µT.
    pub centre_ut: [f64; 3],
    /// The radius: the field's magnitude in raw units, µT.
    pub radius_ut: f64,
}

impl Sphere {
    /// The reading relative to the centre: the field's direction (and raw magnitude), µT.
    pub fn relative_ut(&self, m: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| m[k] - self.centre_ut[k])
    }

    /// Distance of a reading from the centre, µT.
    pub fn distance_ut(&self, m: [f64; 3]) -> f64 {
        let d = self.relative_ut(m);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    }

    /// Whether a reading is off the sphere ([`OFF_SPHERE`], [`MIN_OFF_SPHERE_UT`]).
    pub fn departs(&self, m: [f64; 3]) -> bool {
        (self.distance_ut(m) - self.radius_ut).abs()
            > (OFF_SPHERE * self.radius_ut).max(MIN_OFF_SPHERE_UT)
    }
}

/// The sums of the least-squares sphere: `Σ x·xᵀ` and `Σ x·|m|²` with `x = (2m, 1)`.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereSums {
    xtx: Matrix4<f64>,
    xty: Vector4<f64>,
    n: usize,
}

impl Default for SphereSums {
    fn default() -> SphereSums {
        SphereSums {
            xtx: Matrix4::zeros(),
            xty: Vector4::zeros(),
            n: 0,
        }
    }
}

impl SphereSums {
    /// The sums of `readings`.
    pub fn of(readings: impl IntoIterator<Item = [f64; 3]>) -> SphereSums {
        let mut sums = SphereSums::default();
        readings.into_iter().for_each(|m| sums.add(m));
        sums
    }

    /// Adds a raw reading, µT.
    pub fn add(&mut self, m: [f64; 3]) {
        let x = Vector4::new(2.0 * m[0], 2.0 * m[1], 2.0 * m[2], 1.0);
        self.xtx += x * x.transpose();
        self.xty += x * (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        self.n += 1;
    }

    /// Readings added.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether no reading was added.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The least-squares sphere, if the readings determine one: they spread in three dimensions (the weakest
    /// principal spread at least [`REFUSE_RATIO`] of the largest, as the fits require, and the largest at least
    /// 1 µT), and the sphere can hold them (readings on a sphere spread by no more than its radius in any direction:
    /// a short arc fitted by a tiny sphere does not).
    pub fn sphere(&self) -> Option<Sphere> {
        let n = self.n as f64;
        if self.n < 4 {
            return None;
        }
        // Σ x·xᵀ holds Σ 4·m·mᵀ, Σ 2·m and n: the readings' covariance.
        let mean = [0, 1, 2].map(|k| self.xtx[(k, 3)] / (2.0 * n));
        let cov = Matrix3::from_fn(|j, k| self.xtx[(j, k)] / (4.0 * n) - mean[j] * mean[k]);
        let spreads = SymmetricEigen::new(cov)
            .eigenvalues
            .map(|e| e.max(0.0).sqrt());
        let (weakest, largest) = (spreads.min(), spreads.max());
        if !(largest >= STILL_SPREAD_UT && weakest >= REFUSE_RATIO * largest) {
            return None;
        }
        let s = self.xtx.cholesky()?.solve(&self.xty);
        let centre_ut = [s[0], s[1], s[2]];
        let r2 = s[3] + centre_ut.iter().map(|c| c * c).sum::<f64>();
        (r2.is_finite() && r2.sqrt() >= largest && centre_ut.iter().all(|c| c.is_finite())).then(
            || Sphere {
                centre_ut,
                radius_ut: r2.sqrt(),
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fibonacci_sphere(n: usize, radius: f64, centre: [f64; 3]) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let z = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
                let phi = i as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                [
                    centre[0] + radius * r * phi.cos(),
                    centre[1] + radius * r * phi.sin(),
                    centre[2] + radius * z,
                ]
            })
            .collect()
    }

    #[test]
    fn the_sphere_of_a_cap_and_the_readings_off_it() {
        let centre = [30.0, -20.0, 10.0];
        let cap: Vec<[f64; 3]> = fibonacci_sphere(2000, 50.0, centre)
            .into_iter()
            .filter(|p| p[2] - centre[2] > 20.0)
            .collect();
        let s = SphereSums::of(cap.iter().copied()).sphere().unwrap();
        assert!(
            (0..3).all(|k| (s.centre_ut[k] - centre[k]).abs() < 1e-6),
            "{s:?}"
        );
        assert!((s.radius_ut - 50.0).abs() < 1e-6);
        assert!(!s.departs([30.0, -20.0, 10.0 + 57.0]) && s.departs([30.0, -20.0, 10.0 + 58.0]));
        assert!(s.departs([30.0, -20.0, 10.0 + 42.0]));
    }

    #[test]
    fn readings_that_do_not_span_three_dimensions_give_no_sphere() {
        let still = vec![[10.0, 20.0, 30.0]; 100];
        assert_eq!(SphereSums::of(still.iter().copied()).sphere(), None);
        let ring: Vec<[f64; 3]> = (0..360)
            .map(|i| {
                let a = f64::from(i).to_radians();
                [25.0 * a.cos(), 25.0 * a.sin(), 43.0]
            })
            .collect();
        assert_eq!(SphereSums::of(ring).sphere(), None);
        assert_eq!(SphereSums::default().sphere(), None);
    }
}
