//! PX4's sensor rotations (`CAL_MAGn_ROT`, `SENS_BOARD_ROT`): the enum shared with MAVLink's `MAV_SENSOR_ORIENTATION`,
//! each a roll, pitch and yaw in degrees, turned into the matrix that takes sensor axes into body (FRD) axes the way
//! PX4's `get_rot_matrix` does (`Dcm(Euler(roll, pitch, yaw))`, yaw applied last).

use magcal_calib::frames::Mat3;

/// Roll, pitch and yaw (degrees) of each `Rotation` value, in enum order (`MAV_SENSOR_ORIENTATION` 0–41).
const ROTATIONS_DEG: [(f64, f64, f64); 42] = [
    (0.0, 0.0, 0.0),
    (0.0, 0.0, 45.0),
    (0.0, 0.0, 90.0),
    (0.0, 0.0, 135.0),
    (0.0, 0.0, 180.0),
    (0.0, 0.0, 225.0),
    (0.0, 0.0, 270.0),
    (0.0, 0.0, 315.0),
    (180.0, 0.0, 0.0),
    (180.0, 0.0, 45.0),
    (180.0, 0.0, 90.0),
    (180.0, 0.0, 135.0),
    (0.0, 180.0, 0.0),
    (180.0, 0.0, 225.0),
    (180.0, 0.0, 270.0),
    (180.0, 0.0, 315.0),
    (90.0, 0.0, 0.0),
    (90.0, 0.0, 45.0),
    (90.0, 0.0, 90.0),
    (90.0, 0.0, 135.0),
    (270.0, 0.0, 0.0),
    (270.0, 0.0, 45.0),
    (270.0, 0.0, 90.0),
    (270.0, 0.0, 135.0),
    (0.0, 90.0, 0.0),
    (0.0, 270.0, 0.0),
    (0.0, 180.0, 90.0),
    (0.0, 180.0, 270.0),
    (90.0, 90.0, 0.0),
    (180.0, 90.0, 0.0),
    (270.0, 90.0, 0.0),
    (90.0, 180.0, 0.0),
    (270.0, 180.0, 0.0),
    (90.0, 270.0, 0.0),
    (180.0, 270.0, 0.0),
    (270.0, 270.0, 0.0),
    (90.0, 180.0, 90.0),
    (90.0, 0.0, 270.0),
    (90.0, 68.0, 293.0),
    (0.0, 315.0, 0.0),
    (90.0, 315.0, 0.0),
    (270.0, 0.0, 180.0),
];

/// The matrix taking sensor axes into body axes for PX4 rotation `value`, or `None` for a value PX4 does not
/// define (`-1` marks an internal sensor, which takes the board's rotation instead).
pub fn sensor_to_body(value: i64) -> Option<Mat3> {
    let (roll, pitch, yaw) = *ROTATIONS_DEG.get(usize::try_from(value).ok()?)?;
    Some(euler_321(
        roll.to_radians(),
        pitch.to_radians(),
        yaw.to_radians(),
    ))
}

/// `Rz(yaw)·Ry(pitch)·Rx(roll)`, rounded where a right angle makes an entry exactly 0 or ±1.
fn euler_321(roll: f64, pitch: f64, yaw: f64) -> Mat3 {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    let m = [
        [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
        [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
        [-sp, sr * cp, cr * cp],
    ];
    m.map(|row| row.map(|v| if v.abs() < 1e-12 { 0.0 } else { v }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use magcal_calib::frames::mat_vec;

    #[test]
    fn yaw_90_takes_sensor_x_to_body_y() {
        let m = sensor_to_body(2).unwrap();
        assert_eq!(mat_vec(&m, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]);
    }

    #[test]
    fn roll_180_flips_y_and_z() {
        let m = sensor_to_body(8).unwrap();
        assert_eq!(mat_vec(&m, [1.0, 2.0, 3.0]), [1.0, -2.0, -3.0]);
    }

    #[test]
    fn every_rotation_is_proper_and_unknown_values_are_none() {
        for v in 0..42 {
            let m = sensor_to_body(v).unwrap();
            let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
            assert!((det - 1.0).abs() < 1e-9, "rotation {v}");
        }
        assert!(sensor_to_body(-1).is_none());
        assert!(sensor_to_body(42).is_none());
    }
}
