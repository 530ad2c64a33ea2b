//! One magnetometer sample from a serial line, whatever protocol carried it.

/// One sample. The magnetic field is always there; the other quantities are `Some` only when the
/// protocol carries them. Within a present quantity a value the device left out (an empty CSV
/// field, `nan`) is NaN, the magcal-recording v1 convention for missing values.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Device time (s), from the native CSV `t` column. MotionCal lines carry no time: the
    /// reception time ([`Received::host_s`](super::port::Received::host_s)) stands in for it.
    pub t_s: Option<f64>,
    /// Magnetic field (µT), sensor axes, uncalibrated.
    pub mag_ut: [f64; 3],
    /// Specific force (g), from MotionCal `Raw:` lines.
    pub accel_g: Option<[f64; 3]>,
    /// Angular rate (rad/s): MotionCal `Raw:` gyro converted from °/s, or CSV `gx,gy,gz`.
    pub gyro_rad_s: Option<[f64; 3]>,
    /// Sensor temperature (°C), CSV `temp`.
    pub temp_c: Option<f64>,
    /// Attitude quaternion `[w, x, y, z]`, CSV `qw,qx,qy,qz` (the recording format's convention:
    /// it rotates sensor axes into world NED).
    pub quat_wxyz: Option<[f64; 4]>,
    /// Values of the CSV `i_<name>` columns, in the order of the stream's
    /// [`input_names`](super::csv_stream::CsvStream::input_names); empty for MotionCal.
    pub inputs: Vec<f64>,
}

impl Sample {
    /// A sample holding only a magnetic field (µT).
    pub fn mag_only(mag_ut: [f64; 3]) -> Self {
        Sample {
            t_s: None,
            mag_ut,
            accel_g: None,
            gyro_rad_s: None,
            temp_c: None,
            quat_wxyz: None,
            inputs: Vec::new(),
        }
    }
}
