//! The sensor's true calibration: what a perfect fit would find.

use magcal_calib::frames::Mat3;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::RngExt;

/// The true `A` and `b` of `B = A·B̂ + b` (calibrated field in the reference's axes from the raw reading).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorTruth {
    /// `A`, row-major.
    pub a: Mat3,
    /// `b`, µT.
    pub b_ut: [f64; 3],
}

impl SensorTruth {
    /// A perfect sensor: `A = I`, `b = 0`.
    pub const IDEAL: SensorTruth = SensorTruth {
        a: magcal_calib::frames::IDENTITY,
        b_ut: [0.0; 3],
    };

    /// A sensor whose own calibration is `B_s = a·B̂ + b` in its own axes, mounted with its axes rotated from the
    /// reference's by `mount` (a rotation vector, rad, taking sensor axes to reference axes): then `A = M·a`,
    /// `b = M·b_s`.
    pub fn mounted(a: Mat3, b_ut: [f64; 3], mount_rad: [f64; 3]) -> SensorTruth {
        let m = Rotation3::from_scaled_axis(Vector3::from(mount_rad)).into_inner();
        let a = m * Matrix3::from_fn(|j, k| a[j][k]);
        let b = m * Vector3::from(b_ut);
        SensorTruth {
            a: std::array::from_fn(|j| std::array::from_fn(|k| a[(j, k)])),
            b_ut: [b.x, b.y, b.z],
        }
    }

    /// A random sensor: scale errors and soft iron up to `soft` (relative, e.g. 0.2), hard iron up to `hard_ut` per
    /// axis, mounting misalignment up to `mount_deg` about a random axis.
    pub fn random(soft: f64, hard_ut: f64, mount_deg: f64, rng: &mut impl RngExt) -> SensorTruth {
        let mut a = [[0.0; 3]; 3];
        for j in 0..3 {
            for k in 0..3 {
                let base = if j == k { 1.0 } else { 0.0 };
                let spread = if j == k { soft } else { soft / 4.0 };
                a[j][k] = base + rng.random_range(-spread..=spread);
            }
        }
        let b = std::array::from_fn(|_| rng.random_range(-hard_ut..=hard_ut));
        let axis = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize();
        let angle = rng.random_range(0.0..=mount_deg).to_radians();
        let mount = axis * angle;
        SensorTruth::mounted(a, b, [mount.x, mount.y, mount.z])
    }

    /// The sensor run forwards: the raw reading for a calibrated-domain field, `A⁻¹·(B − b)`.
    pub fn forward(&self) -> impl Fn([f64; 3]) -> [f64; 3] + use<> {
        let a = Matrix3::from_fn(|j, k| self.a[j][k]);
        let inv = a.try_inverse().expect("a sensor's A is invertible");
        let b = Vector3::from(self.b_ut);
        move |field_ut| {
            let m = inv * (Vector3::from(field_ut) - b);
            [m.x, m.y, m.z]
        }
    }
}
