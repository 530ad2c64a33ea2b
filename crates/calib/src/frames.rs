//! Frames and small fixed-size linear algebra that must also work without `std`.
//!
//! Conventions: quaternions are `[w, x, y, z]` (scalar first, Hamilton) and rotate sensor-frame vectors into the
//! world NED frame, `v_ned = q · v_sensor · q*`. Matrices are row-major `[[f64; 3]; 3]`.

/// A 3×3 matrix, row-major.
pub type Mat3 = [[f64; 3]; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `m · v`.
pub fn mat_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// `mᵀ · v`.
pub fn mat_t_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
        m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
        m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
    ]
}

/// Dot product.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product `a × b`.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Euclidean norm.
pub fn norm(v: [f64; 3]) -> f64 {
    libm::sqrt(dot(v, v))
}

/// `a + b`.
pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a − b`.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s · v`.
pub fn scale(v: [f64; 3], s: f64) -> [f64; 3] {
    [v[0] * s, v[1] * s, v[2] * s]
}

/// Rotation matrix (sensor → NED) of a unit quaternion `[w, x, y, z]`.
pub fn quat_to_matrix(q: [f64; 4]) -> Mat3 {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The world field as the sensor should see it: `Rᵀ · field_ned` for the attitude `q` (sensor → NED).
pub fn expected_sensor_field(q: [f64; 4], field_ned_ut: [f64; 3]) -> [f64; 3] {
    mat_t_vec(&quat_to_matrix(q), field_ned_ut)
}

/// Declination, inclination (degrees) and magnitude (µT) of a NED field vector.
pub fn field_angles(field_ned_ut: [f64; 3]) -> (f64, f64, f64) {
    let [n, e, d] = field_ned_ut;
    let h = libm::sqrt(n * n + e * e);
    (
        libm::atan2(e, n).to_degrees(),
        libm::atan2(d, h).to_degrees(),
        norm(field_ned_ut),
    )
}

/// The NED field vector of a declination, inclination (degrees) and magnitude (µT).
pub fn field_from_angles(
    declination_deg: f64,
    inclination_deg: f64,
    magnitude_ut: f64,
) -> [f64; 3] {
    let (sd, cd) = (
        libm::sin(declination_deg.to_radians()),
        libm::cos(declination_deg.to_radians()),
    );
    let (si, ci) = (
        libm::sin(inclination_deg.to_radians()),
        libm::cos(inclination_deg.to_radians()),
    );
    [
        magnitude_ut * ci * cd,
        magnitude_ut * ci * sd,
        magnitude_ut * si,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12)
    }

    #[test]
    fn yaw_of_90_degrees_turns_sensor_x_to_east() {
        let h = core::f64::consts::FRAC_1_SQRT_2;
        let q = [h, 0.0, 0.0, h]; // +90° about NED down
        let r = quat_to_matrix(q);
        assert!(close(mat_vec(&r, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]));
        // A field pointing north is seen on the sensor's −Y axis after that yaw.
        assert!(close(
            expected_sensor_field(q, [1.0, 0.0, 0.0]),
            [0.0, -1.0, 0.0]
        ));
    }

    #[test]
    fn field_angles_round_trip() {
        let f = [19.8, 1.2, 45.3];
        let (d, i, m) = field_angles(f);
        assert!(close(field_from_angles(d, i, m), f));
    }
}
