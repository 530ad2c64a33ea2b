//! From magcal's affine model to the one MotionCal firmware holds.
//!
//! magcal fits `B = A·m + b` (raw `m`, calibrated `B`, µT). MotionCal firmware applies
//! `B' = S·(m − V)` with S symmetric. With `V = −A⁻¹·b` magcal's model reads `B = A·(m − V)`, so
//! the two agree when `S = A`, which needs A symmetric. A scalar (ellipsoid) fit gives a
//! symmetric A; a vector fit against a reference attitude does not in general, because A then
//! also holds the rotation between the magnetometer axes and the reference axes. The polar
//! decomposition `A = R·S` (R orthogonal, S symmetric positive definite) splits that rotation
//! off: sending S gives `B' = Rᵀ·B`, the same magnitude as magcal's calibration, in axes
//! turned by R. That rotation is what the packet cannot carry; [`split_affine`] reports it.

use std::fmt;

/// A 3×3 matrix, row-major.
pub type Matrix3 = [[f64; 3]; 3];

/// MotionCal's `V` and `S` for one magcal calibration, and what was left out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionCalModel {
    /// Hard-iron offset `V = −A⁻¹·b` (µT).
    pub hard_iron_ut: [f64; 3],
    /// Soft-iron matrix S, the symmetric positive-definite polar factor of A.
    pub soft_iron: Matrix3,
    /// The orthogonal factor R of `A = R·S` that the packet cannot carry (identity when A is
    /// symmetric positive definite).
    pub dropped_rotation: Matrix3,
    /// Rotation angle of R (degrees); when R is improper, the angle of `−R`.
    pub dropped_rotation_deg: f64,
    /// Whether `det A < 0`: R then also mirrors the axes (A swaps handedness, e.g. a sign
    /// flip in the axis mapping), which the firmware's S cannot express either.
    pub dropped_reflection: bool,
}

/// Why [`split_affine`] failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AffineError {
    /// A or b holds NaN or an infinity.
    NotFinite,
    /// A is singular (or nearly: relative determinant below 1e-12).
    Singular,
}

impl fmt::Display for AffineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            AffineError::NotFinite => "calibration matrix or offset is not finite",
            AffineError::Singular => "calibration matrix is singular",
        })
    }
}

impl std::error::Error for AffineError {}

fn transpose(m: &Matrix3) -> Matrix3 {
    std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]))
}

fn mul(a: &Matrix3, b: &Matrix3) -> Matrix3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn mul_vec(a: &Matrix3, v: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn det(m: &Matrix3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

fn frobenius(m: &Matrix3) -> f64 {
    m.iter().flatten().map(|v| v * v).sum::<f64>().sqrt()
}

/// Inverse by the adjugate; `None` when the determinant is negligible against the scale of `m`.
fn inverse(m: &Matrix3) -> Option<Matrix3> {
    let d = det(m);
    let scale = frobenius(m);
    // Also refuses a NaN determinant.
    if d.is_nan() || d.abs() <= 1e-12 * scale * scale * scale {
        return None;
    }
    let cof = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    // inverse[i][j] = cofactor(j, i) / det; the cyclic indices carry the signs.
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| cof(j, i) / d)
    }))
}

/// Orthogonal polar factor of a nonsingular matrix by the Newton iteration
/// `X ← (X + X⁻ᵀ)/2`, which converges quadratically from `X = A`.
fn orthogonal_factor(a: &Matrix3) -> Option<Matrix3> {
    let mut x = *a;
    for _ in 0..100 {
        let inv_t = transpose(&inverse(&x)?);
        let next: Matrix3 =
            std::array::from_fn(|i| std::array::from_fn(|j| 0.5 * (x[i][j] + inv_t[i][j])));
        let step: Matrix3 = std::array::from_fn(|i| std::array::from_fn(|j| next[i][j] - x[i][j]));
        x = next;
        if frobenius(&step) < 1e-15 {
            break;
        }
    }
    Some(x)
}

/// Splits magcal's `B = A·m + b` into MotionCal's hard-iron offset V and soft-iron matrix S,
/// with the rotation (and reflection) the firmware cannot hold.
pub fn split_affine(a: &Matrix3, b: &[f64; 3]) -> Result<MotionCalModel, AffineError> {
    if !a.iter().flatten().chain(b).all(|v| v.is_finite()) {
        return Err(AffineError::NotFinite);
    }
    let a_inv = inverse(a).ok_or(AffineError::Singular)?;
    let hard_iron_ut = mul_vec(&a_inv, b).map(|v| -v);
    let r = orthogonal_factor(a).ok_or(AffineError::Singular)?;
    let s = mul(&transpose(&r), a);
    let soft_iron = std::array::from_fn(|i| std::array::from_fn(|j| 0.5 * (s[i][j] + s[j][i])));
    let dropped_reflection = det(&r) < 0.0;
    let sign = if dropped_reflection { -1.0 } else { 1.0 };
    let trace = sign * (r[0][0] + r[1][1] + r[2][2]);
    Ok(MotionCalModel {
        hard_iron_ut,
        soft_iron,
        dropped_rotation: r,
        dropped_rotation_deg: ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees(),
        dropped_reflection,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot_z(deg: f64) -> Matrix3 {
        let (s, c) = deg.to_radians().sin_cos();
        [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    }

    fn rot_x(deg: f64) -> Matrix3 {
        let (s, c) = deg.to_radians().sin_cos();
        [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
    }

    fn assert_close(a: &Matrix3, b: &Matrix3, tol: f64) {
        for i in 0..3 {
            for j in 0..3 {
                assert!((a[i][j] - b[i][j]).abs() < tol, "{a:?} vs {b:?}");
            }
        }
    }

    fn norm(v: [f64; 3]) -> f64 {
        v.iter().map(|x| x * x).sum::<f64>().sqrt()
    }

    #[test]
    fn symmetric_a_goes_through_unchanged() {
        let a = [[1.1, 0.02, -0.01], [0.02, 0.95, 0.03], [-0.01, 0.03, 1.02]];
        let b = [5.0, -3.0, 40.0];
        let m = split_affine(&a, &b).unwrap();
        assert_close(&m.soft_iron, &a, 1e-12);
        assert!(m.dropped_rotation_deg < 1e-6);
        assert!(!m.dropped_reflection);
        // A·V + b = 0: the offset is where the calibrated field is zero.
        let at_v = mul_vec(&a, &m.hard_iron_ut);
        assert!((0..3).all(|i| (at_v[i] + b[i]).abs() < 1e-12));
    }

    #[test]
    fn a_vector_fit_rotation_is_split_off_and_reported() {
        let p = [[1.2, 0.05, 0.0], [0.05, 0.9, -0.02], [0.0, -0.02, 1.05]];
        let r = mul(&rot_z(30.0), &rot_x(10.0));
        let a = mul(&r, &p);
        let b = [12.0, -7.5, 3.0];
        let m = split_affine(&a, &b).unwrap();
        assert_close(&m.soft_iron, &p, 1e-12);
        assert_close(&m.dropped_rotation, &r, 1e-12);
        let expected_deg = ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0)
            .acos()
            .to_degrees();
        assert!((m.dropped_rotation_deg - expected_deg).abs() < 1e-9);
        assert!(m.dropped_rotation_deg > 30.0);
        // MotionCal's S·(m − V) has the magnitude of magcal's A·m + b.
        for raw in [[10.0, 20.0, -30.0], [-45.0, 3.0, 8.0]] {
            let magcal = mul_vec(&a, &raw);
            let magcal = [magcal[0] + b[0], magcal[1] + b[1], magcal[2] + b[2]];
            let shifted = std::array::from_fn(|i| raw[i] - m.hard_iron_ut[i]);
            let motioncal = mul_vec(&m.soft_iron, &shifted);
            assert!((norm(magcal) - norm(motioncal)).abs() < 1e-9);
        }
    }

    #[test]
    fn a_reflection_is_reported() {
        let a = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]];
        let m = split_affine(&a, &[0.0; 3]).unwrap();
        assert!(m.dropped_reflection);
        assert_close(
            &m.soft_iron,
            &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            1e-12,
        );
        assert!(
            (m.dropped_rotation_deg - 180.0).abs() < 1e-6,
            "−R is a half turn"
        );
    }

    #[test]
    fn refuses_singular_and_non_finite() {
        let flat = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]];
        assert_eq!(split_affine(&flat, &[0.0; 3]), Err(AffineError::Singular));
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert_eq!(
            split_affine(&id, &[f64::NAN, 0.0, 0.0]),
            Err(AffineError::NotFinite)
        );
    }

    #[test]
    fn inverse_is_an_inverse() {
        let a = mul(
            &rot_z(40.0),
            &[[2.0, 0.3, 0.0], [0.1, 1.0, 0.2], [0.0, 0.5, 3.0]],
        );
        let id = mul(&a, &inverse(&a).unwrap());
        assert_close(
            &id,
            &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            1e-12,
        );
    }
}
